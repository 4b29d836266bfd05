//! REST API v1 for simulation codes, scripts and notebooks: create scenes, push time steps
//! (JSON, `.npy` or raw), list and fetch them, delete, send a tet mesh, and render one image
//! or a histogram. One file per group of routes; `routes` puts them together with the
//! OpenAPI document.
//!
//! Architecture invariant: handlers do I/O only. Parsing and writing steps run on blocking
//! threads (`spawn_blocking`); rendering, encoding and histograms run on the job pool
//! (`crate::jobs`) or the render pool; all report back through channels. The HTTP layer
//! maps the domain's errors (`kinds`, `store`) to the one `crate::error::AppError`.

pub mod access;
pub mod auth;
pub mod client;
mod contract;
mod histogram;
pub mod origin;
mod peers;
mod push;
mod render;
pub mod request;
pub mod routes;
mod scenes;
mod steps;
pub mod strict_json;
mod tets;

pub use routes::{openapi, router};
