//! The renderer's loop: waits until the view or the scene time changed and the slot is
//! empty, plans the frame, submits it to the fair scheduler (never rendering on the async
//! runtime) and puts the encoded result in the slot. Each frame is made by the one frame
//! function, `crate::frame::render`.

use crate::encode::EncodeError;
use crate::frame::{self, FrameRequest, H264Plan, Pass, StreamMeta, VideoState};
use crate::input::Settings;
use crate::metrics as m;
use crate::refine::Refinement;
use crate::scenes::entry::SceneEntry;
use crate::schedule::JobCost;
use crate::session::controller::{plan_frame, Controller, FramePlan, Quality};
use crate::session::flow::{Shared, SlotFrame, FRAME_WINDOW};
use crate::session::stats::SessionStats;
use crate::state::AppState;
use axum::body::Bytes;
use isoray_protocol::Codec;
use isoray_render::View;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The depth channel is this many times smaller than its frame in each direction.
const DEPTH_FACTOR: u32 = 4;

/// Where the renderer stands when it decides what to do next.
struct Moment {
    view_changed: bool,
    time_changed: bool,
    animating: bool,
    /// The still frame is on screen and fully refined.
    shown_still: bool,
    live: bool,
    now: tokio::time::Instant,
    next_tick: tokio::time::Instant,
    last_change: tokio::time::Instant,
    still_delay: Duration,
    clock: f64,
    time_step_fps: f64,
    frame_interval: Duration,
}

/// What the renderer does next.
enum Next {
    Render(Quality),
    /// Wait for a wake-up or this instant.
    Until(tokio::time::Instant),
    /// Wait for a wake-up.
    Wake,
}

impl Moment {
    /// New input renders at once; a new state at most once per tick; once input stops on a
    /// view that does not animate, lossless still frames (refining), then nothing until
    /// something changes.
    fn next(&self) -> Next {
        if self.view_changed || (self.time_changed && self.now >= self.next_tick) {
            Next::Render(Quality::Interactive)
        } else if !self.animating
            && !self.time_changed
            && !self.shown_still
            && self.now >= self.last_change + self.still_delay
        {
            Next::Render(Quality::Still)
        } else if self.time_changed {
            Next::Until(self.next_tick)
        } else if self.animating {
            // The next time step of the live clock.
            let step = 1.0 / self.time_step_fps;
            let next = ((self.clock / step).floor() + 1.0) * step;
            Next::Until(self.now + Duration::from_secs_f64((next - self.clock).max(0.0)))
        } else if !self.shown_still {
            Next::Until(self.last_change + self.still_delay)
        } else if self.live {
            // A live stored scene: look for a pushed step once per frame interval.
            Next::Until(self.now + self.frame_interval)
        } else {
            Next::Wake
        }
    }
}

/// Queues one frame with the fair scheduler; it renders on the render pool when the
/// session's turn comes.
fn submit_frame(
    app: &AppState,
    entry: &Arc<SceneEntry>,
    id: u64,
    settings: &Settings,
    plan: FramePlan,
    video: &mut VideoState,
    refinement: &Arc<Refinement>,
) -> tokio::sync::oneshot::Receiver<(Result<Rendered, EncodeError>, JobCost)> {
    // The H.264 stream travels with its frames; other codecs leave it with the session.
    let video = if plan.codec == Codec::H264 {
        video.take()
    } else {
        None
    };
    let job_entry = Arc::clone(entry);
    let job_app = app.clone();
    let job_settings = settings.clone();
    let job_refinement = Arc::clone(refinement);
    app.scheduler().submit(id, move || {
        render_frame(
            &job_app,
            &job_entry,
            &job_settings,
            &plan,
            video,
            &job_refinement,
        )
    })
}

/// What the slot needs to know about a frame besides the frame.
struct Shown {
    sequence: u64,
    input_at: Option<Instant>,
    fps: f64,
}

/// Tells the controller what the frame cost and puts it in the slot for the writer.
fn show(
    rendered: Rendered,
    cost: JobCost,
    plan: &FramePlan,
    shown: &Shown,
    controller: &mut Controller,
    shared: &Shared,
    stats: &SessionStats,
) {
    stats.frames_rendered.fetch_add(1, Ordering::Relaxed);
    let pixels = plan.size.0 as u64 * plan.size.1 as u64;
    if plan.quality == Quality::Interactive {
        controller.motion_frames = controller.motion_frames.saturating_add(1);
        controller.observe(
            pixels,
            cost,
            rendered.bytes.len(),
            rendered.codec,
            shared.bandwidth().estimate(),
            shown.fps,
        );
    } else {
        controller.motion_frames = 0;
    }
    m::queue_wait(cost.queued);
    shared.slot.put(
        SlotFrame {
            sequence: shown.sequence,
            bytes: rendered.bytes,
            codec: rendered.codec,
            input_at: shown.input_at,
        },
        stats,
    );
}

/// What a render job hands back.
struct Rendered {
    bytes: Bytes,
    codec: Codec,
    video: VideoState,
    /// Time of the state shown (a live demo's may differ from the plan's time).
    state_time: Option<f64>,
}

pub async fn render_loop(
    app: &AppState,
    entry: &Arc<SceneEntry>,
    id: u64,
    shared: &Shared,
    stats: &SessionStats,
) {
    let config = app.config();
    // Scene time steps: every session of a scene sees the same grid, so they share states.
    let time_step_fps = config.max_fps;
    let still_delay = Duration::from_millis(config.still_after_ms);
    let mut controller = Controller::new(config.jpeg_quality, config.min_scale);
    let mut video: VideoState = None;
    // What the last frame showed: settings version, state key, and whether it was the still.
    let mut last: Option<(u64, u128, Quality)> = None;
    let mut last_change = tokio::time::Instant::now();
    let mut next_tick = tokio::time::Instant::now();
    let mut sequence = 0u64;
    let mut seen: Option<f64> = None;
    // Effects hook: a still view keeps refining (one pass per still frame) until converged.
    let refinement = Arc::new(Refinement::new(config.max_refine_passes));
    loop {
        // Flow control: one frame in the slot at most, and a window of unacknowledged ones.
        let acked = stats.last_acked_sequence.load(Ordering::SeqCst);
        if !shared.slot.is_empty() || sequence + 1 > acked + FRAME_WINDOW {
            shared.wake.notified().await;
            continue;
        }
        let current = shared.settings().clone();
        if !current.stream.visible {
            // A hidden page costs nothing; the next input (`visible: true`) wakes us.
            shared.wake.notified().await;
            continue;
        }
        let fps = current.stream.fps;
        let frame_interval = Duration::from_secs_f64(1.0 / fps);
        let live = current.pinned_time.is_none();
        let clock = app.scenes().live_time();
        let time = current
            .pinned_time
            .unwrap_or_else(|| (clock * time_step_fps).floor() / time_step_fps);
        // A demo followed live changes with the clock; any other view only when its state does
        // (a pinned time, a stored scene's newest step).
        let animating = live && entry.animates();
        let state_key = entry.state_key(time, live);
        let now = tokio::time::Instant::now();
        let view_changed = last.map(|(v, _, _)| v) != Some(current.version);
        let time_changed = last.map(|(_, k, _)| k) != Some(state_key);
        let refine_key = (
            current.version,
            time.to_bits(),
            current.width,
            current.height,
        );
        let shown_still =
            last.is_some_and(|(_, _, q)| q == Quality::Still) && refinement.converged(refine_key);
        if view_changed {
            last_change = now;
        }
        // What to do next: see `Moment::next`.
        let moment = Moment {
            view_changed,
            time_changed,
            animating,
            shown_still,
            live,
            now,
            next_tick,
            last_change,
            still_delay,
            clock,
            time_step_fps,
            frame_interval,
        };
        let quality = match moment.next() {
            Next::Render(quality) => quality,
            Next::Until(deadline) => {
                tokio::select! {
                    () = shared.wake.notified() => {}
                    () = tokio::time::sleep_until(deadline) => {}
                }
                continue;
            }
            Next::Wake => {
                shared.wake.notified().await;
                continue;
            }
        };
        if quality == Quality::Interactive {
            next_tick = now + frame_interval;
        }
        sequence += 1;
        last = Some((current.version, state_key, quality));

        let input_at = current.last_input_at.filter(|_| view_changed);
        let plan = plan_frame(
            &mut controller,
            &current,
            quality,
            sequence,
            time,
            app.scheduler().active_sessions(),
            shared.bandwidth().estimate(),
            video_size(&video),
        );
        stats.scale_permille.store(
            (controller.scale * 1000.0).round() as u32,
            Ordering::Relaxed,
        );
        stats
            .jpeg_quality
            .store(plan.jpeg_quality as u32, Ordering::Relaxed);
        let job_plan = FramePlan { seen, ..plan };
        let result =
            submit_frame(app, entry, id, &current, job_plan, &mut video, &refinement).await;
        match result {
            Ok((Ok(mut rendered), cost)) => {
                if rendered.video.is_some() {
                    video = rendered.video.take();
                }
                if rendered.state_time.is_some() {
                    seen = rendered.state_time;
                }
                let shown = Shown {
                    sequence,
                    input_at,
                    fps,
                };
                show(
                    rendered,
                    cost,
                    &plan,
                    &shown,
                    &mut controller,
                    shared,
                    stats,
                );
            }
            Ok((Err(e), _)) => {
                stats.frames_dropped.fetch_add(1, Ordering::Relaxed);
                metrics::counter!(m::FRAMES_DROPPED, "reason" => "error").increment(1);
                // The sequence number was not used: the next frame takes it.
                sequence -= 1;
                tracing::warn!(error = %e, "frame failed; the session waits for the next change");
                shared.wake.notified().await;
            }
            Err(_) => return, // the pool dropped the job: the server is going down
        }
    }
}

#[cfg(feature = "h264")]
fn video_size(video: &VideoState) -> Option<((u32, u32), u32)> {
    video.as_ref().map(|v| (v.size(), v.bitrate_bps()))
}

#[cfg(not(feature = "h264"))]
fn video_size(_: &VideoState) -> Option<((u32, u32), u32)> {
    None
}

/// Prepares one frame's state and makes the frame with the one frame function. Runs on the
/// render pool.
fn render_frame(
    app: &AppState,
    entry: &SceneEntry,
    settings: &Settings,
    plan: &FramePlan,
    video: VideoState,
    refinement: &Refinement,
) -> Result<Rendered, EncodeError> {
    let state = entry.prepared_at(plan.time, settings.pinned_time.is_none(), plan.seen);
    let pass = match plan.quality {
        Quality::Interactive => Pass::Single,
        Quality::Still => Pass::Refine(
            refinement,
            (
                settings.version,
                plan.time.to_bits(),
                plan.size.0,
                plan.size.1,
            ),
        ),
    };
    let request = FrameRequest {
        view: View {
            width: plan.size.0,
            height: plan.size.1,
            camera: settings.camera,
            isovalue: settings.isovalue,
        },
        effects: &settings.effects,
        style: Some(&settings.style),
        pass,
        codec: plan.codec,
        jpeg_quality: plan.jpeg_quality,
        h264: H264Plan {
            bitrate_bps: plan.h264_bitrate_bps,
            restart: plan.h264_restart,
            fps: plan.fps,
        },
        depth_factor: plan.depth.then_some(DEPTH_FACTOR),
    };
    let mut frame = frame::render(app.backend(), &state, &request, video)?;
    let video = frame.video.take();
    let meta = StreamMeta {
        sequence: plan.sequence,
        input_id: settings.last_input_id,
        still: plan.quality == Quality::Still,
        codec: plan.codec,
        jpeg_quality: plan.jpeg_quality,
        time: plan.time,
    };
    Ok(Rendered {
        bytes: frame::stream_message(frame, &state, &meta)?,
        codec: plan.codec,
        video,
        state_time: state.step_time,
    })
}
