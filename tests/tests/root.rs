//! All of isoray's cross-crate and end-to-end tests, in one binary (one link, shared helpers).
//! Each module is named after what it guards.

mod api;
mod deploy;
mod docs;
mod e2e;
mod golden;
mod scene_json;
mod stability;
mod structure;
