//! Prometheus metrics at `/metrics`: sessions, frames, bytes, per-stage times, input-to-frame
//! latency, render queue depth, refusals and rejected inputs.
//!
//! One process-wide recorder (the `metrics` facade is global); servers started in one process,
//! as the tests do, share it.

use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};
use std::sync::OnceLock;
use std::time::Duration;

pub const SESSIONS: &str = "isoray_sessions";
pub const SESSIONS_REFUSED: &str = "isoray_sessions_refused_total";
pub const FRAMES_SENT: &str = "isoray_frames_sent_total";
pub const FRAME_BYTES: &str = "isoray_frame_bytes_total";
pub const STAGE_SECONDS: &str = "isoray_stage_seconds";
pub const INPUT_TO_FRAME_SECONDS: &str = "isoray_input_to_frame_seconds";
pub const RENDER_QUEUE: &str = "isoray_render_queue_depth";
pub const INPUTS_REJECTED: &str = "isoray_inputs_rejected_total";

/// Bucket bounds, seconds: 0.5 ms to 2.5 s, about ×2 apart.
const SECONDS_BUCKETS: [f64; 13] = [
    0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.04, 0.07, 0.1, 0.2, 0.5, 1.0, 2.5,
];

static HANDLE: OnceLock<Option<PrometheusHandle>> = OnceLock::new();

/// Installs the recorder on first use; `None` if another recorder was installed first.
pub fn handle() -> Option<&'static PrometheusHandle> {
    HANDLE
        .get_or_init(|| {
            let builder = PrometheusBuilder::new()
                .set_buckets_for_metric(Matcher::Suffix("_seconds".into()), &SECONDS_BUCKETS);
            match builder.and_then(|b| b.install_recorder()) {
                Ok(handle) => Some(handle),
                Err(e) => {
                    tracing::warn!(error = %e, "metrics disabled: cannot install the recorder");
                    None
                }
            }
        })
        .as_ref()
}

/// The text exposition of every metric.
pub fn render() -> String {
    match handle() {
        Some(h) => {
            h.run_upkeep();
            h.render()
        }
        None => String::new(),
    }
}

pub fn stage(stage: &'static str, micros: u32) {
    metrics::histogram!(STAGE_SECONDS, "stage" => stage).record(micros as f64 * 1e-6);
}

pub fn input_to_frame(latency: Duration) {
    metrics::histogram!(INPUT_TO_FRAME_SECONDS).record(latency.as_secs_f64());
}
