//! The server run in-process on an ephemeral loopback port, driven over real sockets.

mod adaptive;
mod bad_input;
mod codecs;
mod faults;
#[cfg(feature = "gpu")]
mod gpu;
mod lifecycle;
mod metrics;
mod paper_scenes;
mod refine;
mod slow_client;
mod stream;
pub mod support;
