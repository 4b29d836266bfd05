//! Wire types of isoray's websocket protocol, version 1.
//!
//! This crate is the compatibility promise between the server and its clients, and nothing
//! else: plain data types with serde derives, plus the fixed binary frame header. It has no
//! engine types and no validation beyond what the wire format itself needs (the server checks
//! values such as finiteness and ranges at its boundary). `PROTOCOL.md` beside this crate is
//! the human-readable description; the tests below pin the JSON shapes it documents.

pub mod api;
pub mod api_surfels;
pub mod api_tets;
pub mod effects;
pub mod frame;
pub mod messages;
pub mod version;

pub use frame::{
    Codec, FrameHeader, FrameHeaderError, StageTimings, FLAG_DEPTH, FLAG_FINAL, FLAG_KEYFRAME,
    FLAG_STILL, FRAME_HEADER_LEN, FRAME_MAGIC,
};

pub use messages::*;
pub use version::{InputId, MAX_INPUT_ID, PROTOCOL_VERSION};
