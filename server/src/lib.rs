//! The isoray server: axum on tokio for I/O, a rayon pool for rendering and encoding.
//!
//! Entry points: [`app`] builds the router over an [`AppState`] (tests drive it in-process);
//! [`serve`] runs it on a listener until a shutdown future completes, then closes every
//! session with a reason and drains. The `isoray` binary (`main.rs`) parses flags and calls
//! [`serve`].
//!
//! This file only declares modules and re-exports for other crates; inside the crate every
//! path names the defining module (see ARCHITECTURE.md for the module map and its layers).

pub mod api;
pub mod body;
pub mod clients;
pub mod config;
pub mod effects;
pub mod encode;
pub mod error;
pub mod frame;
pub mod input;
pub mod jobs;
pub mod kinds;
pub mod metrics;
pub mod npy;
pub mod placement;
pub mod random;
pub mod refine;
pub mod scenes;
pub mod schedule;
pub mod serve;
pub mod session;
pub mod state;
pub mod store;
pub mod style;
mod web;

pub use config::Config;
pub use serve::{app, serve};
pub use state::AppState;
