//! The render backends behind one closed enum ([`dispatch::Backend`]); the seam is the pass
//! ([`accumulator::TracePasses`]).

pub mod accumulator;
pub mod cpu;
pub mod dispatch;
#[cfg(feature = "gpu")]
pub mod gpu;

pub use accumulator::{
    Accumulator, DeviceTimes, FrameRays, Pass, DEFAULT_MAX_PASSES, DEFAULT_THRESHOLD,
};
pub use cpu::{CpuBackend, PoolError, MAX_THREADS};
pub use dispatch::Backend;
#[cfg(test)]
mod antialias_tests;
#[cfg(test)]
mod surface_tests;
