//! What a session's three loops share: the frame slot (at most one frame waiting to be
//! sent), the window of unacknowledged frames, the settings and the bandwidth estimate.

use crate::input::Settings;
use crate::metrics as m;
use crate::session::bandwidth::Bandwidth;
use crate::session::stats::SessionStats;
use axum::body::Bytes;
use isoray_protocol::Codec;
use std::sync::atomic::Ordering;
use std::sync::Mutex;
use std::time::Instant;
use tokio::sync::Notify;

/// Frames sent ahead of the client's acknowledgements: one on screen, one on the wire.
pub const FRAME_WINDOW: u64 = 2;

/// A rendered frame waiting for the writer.
pub struct SlotFrame {
    pub sequence: u64,
    pub bytes: Bytes,
    pub codec: Codec,
    /// When the input this frame first shows arrived, for the latency histogram.
    pub input_at: Option<Instant>,
}

/// The one-frame mailbox between renderer and writer.
#[derive(Default)]
pub struct FrameSlot {
    pub frame: Mutex<Option<SlotFrame>>,
    pub ready: Notify,
}

impl FrameSlot {
    pub fn lock(&self) -> std::sync::MutexGuard<'_, Option<SlotFrame>> {
        // Only plain values live here; a panic elsewhere cannot leave them inconsistent.
        self.frame.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn is_empty(&self) -> bool {
        self.lock().is_none()
    }

    pub fn put(&self, frame: SlotFrame, stats: &SessionStats) {
        let replaced = self.lock().replace(frame).is_some();
        if replaced {
            stats.frames_dropped.fetch_add(1, Ordering::Relaxed);
            metrics::counter!(m::FRAMES_DROPPED, "reason" => "replaced").increment(1);
        } else {
            let now = stats.pending_frames.fetch_add(1, Ordering::SeqCst) + 1;
            stats.max_pending_frames.fetch_max(now, Ordering::SeqCst);
        }
        self.ready.notify_one();
    }

    pub fn take(&self, stats: &SessionStats) -> Option<SlotFrame> {
        let frame = self.lock().take();
        if frame.is_some() {
            stats.pending_frames.fetch_sub(1, Ordering::SeqCst);
        }
        frame
    }
}

/// What the session shares between its loops.
pub struct Shared {
    pub settings: Mutex<Settings>,
    /// Wakes the renderer: an input applied, an ack received, the slot emptied.
    pub wake: Notify,
    pub slot: FrameSlot,
    pub bandwidth: Mutex<Bandwidth>,
}

impl Shared {
    pub fn settings(&self) -> std::sync::MutexGuard<'_, Settings> {
        self.settings.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn bandwidth(&self) -> std::sync::MutexGuard<'_, Bandwidth> {
        self.bandwidth.lock().unwrap_or_else(|e| e.into_inner())
    }
}
