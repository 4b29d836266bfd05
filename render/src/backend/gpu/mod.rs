//! The wgpu compute backend (feature `gpu`): the shared data layout (`layout`), the WGSL
//! kernel (`shader`, `metaballs.wgsl`), what a frame uploads (`upload`), the device
//! (`device`), the reused buffers of a frame (`buffers`) and the backend with its CPU
//! fallback (`backend`).

pub mod backend;
pub mod buffers;
pub mod device;
pub mod layout;
pub mod shader;
pub mod upload;

#[cfg(test)]
mod agreement_tests;

pub use backend::GpuBackend;
pub use device::{AdapterChoice, GpuError};
