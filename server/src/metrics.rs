//! Prometheus metrics at `/metrics`: sessions, frames and bytes by codec, dropped frames,
//! per-stage times, input-to-frame latency, render queue depth and wait, jobs running, depth
//! channel bytes, scene states built, refusals and rejected inputs, root-finder searches that
//! hit their iteration cap.
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
/// Frames waiting for the render pool (the fair scheduler's queue).
pub const RENDER_QUEUE: &str = "isoray_render_queue_depth";
/// Frames being rendered and encoded now.
pub const RENDER_RUNNING: &str = "isoray_render_jobs_running";
/// Time frames waited in the scheduler's queue.
pub const QUEUE_WAIT_SECONDS: &str = "isoray_render_queue_wait_seconds";
/// Frames rendered but never sent, by reason.
pub const FRAMES_DROPPED: &str = "isoray_frames_dropped_total";
/// Bytes of depth channels sent with interactive frames.
pub const DEPTH_BYTES: &str = "isoray_depth_bytes_total";
/// Scene states prepared (state update plus acceleration structure), by demo scene; every
/// stored scene counts under `scene="stored"` (a series per pushed scene would be unbounded).
pub const STATES_BUILT: &str = "isoray_scene_states_built_total";
pub const INPUTS_REJECTED: &str = "isoray_inputs_rejected_total";
/// Ray searches that stopped at their root finder's iteration cap, by kind (issue 13: a capped
/// search is a possible wrong pixel, counted rather than silent). Single-pass frames only.
pub const CAPPED_SEARCHES: &str = "isoray_root_finder_capped_total";
/// Frames traced, by where: `on="gpu"` (the device traced every pass of the frame) or
/// `on="cpu"` (the CPU backend, or a GPU backend's fallback for what the device does not trace).
pub const FRAMES_TRACED: &str = "isoray_frames_traced_total";
/// The device's share of a GPU frame, by stage: `upload` (frame uniform, lighting and, when
/// the state changed, the kind's arrays), `trace` (dispatch to the kernel's end) and
/// `readback` (the image back into host memory). The frame header carries the same times in
/// its build, trace and encode fields.
pub const GPU_STAGE_SECONDS: &str = "isoray_gpu_stage_seconds";
/// Always 1, labelled with the version and the cargo features the binary was built with
/// (Prometheus' `*_build_info` convention): which encoders a process has, and for the tests,
/// that the binary they spawn is the one they were built with.
pub const BUILD_INFO: &str = "isoray_build_info";

/// Whether this build has the `default` feature (a build with `--no-default-features` lacks
/// it even when it names every default feature, and cargo then compiles it apart).
pub fn default_features() -> bool {
    cfg!(feature = "default")
}

/// The cargo features of this build, sorted, comma-separated.
pub fn features() -> String {
    let mut on = Vec::new();
    if cfg!(feature = "gpu") {
        on.push("gpu");
    }
    if cfg!(feature = "h264") {
        on.push("h264");
    }
    if cfg!(feature = "turbojpeg") {
        on.push("turbojpeg");
    }
    on.join(",")
}

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
                Ok(handle) => {
                    register_zeroes();
                    Some(handle)
                }
                Err(e) => {
                    tracing::warn!(error = %e, "metrics disabled: cannot install the recorder");
                    None
                }
            }
        })
        .as_ref()
}

/// Counters and gauges that should read 0 before their first event, so that dashboards and
/// alerts see them from the start.
fn register_zeroes() {
    for reason in ["replaced", "session_end", "error"] {
        metrics::counter!(FRAMES_DROPPED, "reason" => reason).absolute(0);
    }
    metrics::gauge!(RENDER_QUEUE).set(0.0);
    metrics::gauge!(RENDER_RUNNING).set(0.0);
    metrics::counter!(DEPTH_BYTES).absolute(0);
    for on in ["gpu", "cpu"] {
        metrics::counter!(FRAMES_TRACED, "on" => on).absolute(0);
    }
    for kind in ["metaballs", "surfels"] {
        metrics::counter!(CAPPED_SEARCHES, "kind" => kind).absolute(0);
    }
    metrics::gauge!(
        BUILD_INFO,
        "version" => env!("CARGO_PKG_VERSION"),
        "features" => features()
    )
    .set(1.0);
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

/// Counts a traced frame, and the device's stage times when a device traced it.
pub fn traced(device: &isoray_render::DeviceTimes) {
    if device.passes == 0 {
        metrics::counter!(FRAMES_TRACED, "on" => "cpu").increment(1);
        return;
    }
    metrics::counter!(FRAMES_TRACED, "on" => "gpu").increment(1);
    for (stage, us) in [
        ("upload", device.upload_us),
        ("trace", device.trace_us),
        ("readback", device.readback_us),
    ] {
        metrics::histogram!(GPU_STAGE_SECONDS, "stage" => stage).record(us as f64 * 1e-6);
    }
}

pub fn queue_wait(wait: Duration) {
    metrics::histogram!(QUEUE_WAIT_SECONDS).record(wait.as_secs_f64());
}

pub fn input_to_frame(latency: Duration) {
    metrics::histogram!(INPUT_TO_FRAME_SECONDS).record(latency.as_secs_f64());
}

/// Adds a frame's capped root-finder searches (metaballs, surfels).
pub fn capped_searches(metaballs: u64, surfels: u64) {
    if metaballs > 0 {
        metrics::counter!(CAPPED_SEARCHES, "kind" => "metaballs").increment(metaballs);
    }
    if surfels > 0 {
        metrics::counter!(CAPPED_SEARCHES, "kind" => "surfels").increment(surfels);
    }
}
