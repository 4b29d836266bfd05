//! A session's counters, shared with the session table (`state.rs`) for `/metrics` and tests.

use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize};

/// Counters of one session, readable while it runs (tests, metrics).
#[derive(Debug, Default)]
pub struct SessionStats {
    pub frames_rendered: AtomicU64,
    pub frames_sent: AtomicU64,
    /// Frames rendered but never sent (the session ended with one pending, or it failed).
    pub frames_dropped: AtomicU64,
    pub inputs_applied: AtomicU64,
    pub inputs_rejected: AtomicU64,
    /// Highest frame sequence sent, and highest acknowledged by the client.
    pub last_sent_sequence: AtomicU64,
    pub last_acked_sequence: AtomicU64,
    /// Frames rendered but not yet handed to the socket, now and at most.
    pub pending_frames: AtomicUsize,
    pub max_pending_frames: AtomicUsize,
    /// Resolution scale of interactive frames, in thousandths (1000 = full size).
    pub scale_permille: AtomicU32,
    /// JPEG quality the controller chose last.
    pub jpeg_quality: AtomicU32,
    /// The last clear estimate of the bandwidth to the client, bytes per second (0: none yet;
    /// see `Bandwidth`).
    pub bandwidth_bytes_per_s: AtomicU64,
}
