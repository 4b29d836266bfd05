//! The wgpu compute backend (feature `gpu`): the shared data layout (`layout`), the WGSL
//! kernels (`common.wgsl` with the integrator, one part per kind joined at the seam of
//! `kind`; `shader` checks them), what a frame uploads (`upload`, and per kind `metaballs`,
//! `tets`, `surfels`), the device (`device`), the reused buffers of a frame (`buffers`) and
//! the backend with its CPU fallback (`backend`).

pub mod backend;
pub mod buffers;
pub mod device;
pub mod kind;
#[cfg(test)]
mod lavapipe_tests;
pub mod layout;
pub mod metaballs;
#[cfg(test)]
mod naga_checks;
pub mod retrace;
pub mod shader;
pub mod surfels;
pub mod tets;
pub mod tets_layout;
pub mod upload;

#[cfg(test)]
mod agreement_tests;
#[cfg(test)]
mod backend_tests;
#[cfg(test)]
mod finder_tests;

pub use backend::GpuBackend;
pub use device::{AdapterChoice, GpuError};
