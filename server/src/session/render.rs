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

/// Input that came less than this many frame intervals ago counts as streaming in.
const INPUT_STREAM_TICKS: f64 = 2.0;

/// Most interactive frames a session may bank while it renders none.
const FRAME_BURST: f64 = 1.5;

/// The session's interactive frame rate as a token bucket: it fills at the session's frame
/// rate up to [`FRAME_BURST`] frames, and each interactive frame takes one. Over any stretch
/// of time a session gets at most its rate (plus the burst), and an input that arrives a
/// little before a strict tick would (the client's input timer and the session's frames do
/// not share a clock) does not wait for it: with a strict tick the frames drift to lag the
/// input by most of an interval and stay there.
#[derive(Clone, Copy, Debug)]
struct FrameBucket {
    frames: f64,
    at: tokio::time::Instant,
}

impl FrameBucket {
    fn new(now: tokio::time::Instant) -> FrameBucket {
        FrameBucket {
            frames: 1.0,
            at: now,
        }
    }

    fn level(&self, now: tokio::time::Instant, fps: f64) -> f64 {
        (self.frames + now.saturating_duration_since(self.at).as_secs_f64() * fps).min(FRAME_BURST)
    }

    /// When the bucket holds a whole frame.
    fn ready_at(&self, now: tokio::time::Instant, fps: f64) -> tokio::time::Instant {
        let level = self.level(now, fps);
        if level >= 1.0 {
            now
        } else {
            now + Duration::from_secs_f64((1.0 - level) / fps)
        }
    }

    fn take(&mut self, now: tokio::time::Instant, fps: f64) {
        self.frames = self.level(now, fps) - 1.0;
        self.at = now;
    }
}

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
    /// New input or a new state renders once the session's [`FrameBucket`] holds a frame
    /// (at once unless frames came faster than the session's rate), and while input streams
    /// in (the last came less than [`INPUT_STREAM_TICKS`] intervals ago) a new state alone
    /// renders nothing: the next input's frame shows it. So a viewer that moves the camera of
    /// an animated scene gets the frame rate it asked for, not input's plus the animation's,
    /// and its input does not wait behind a frame of the animation. Once input stops on a
    /// view that does not animate: lossless still frames (refining), then nothing until
    /// something changes.
    fn next(&self) -> Next {
        let due = self.now >= self.next_tick;
        let input_until = self.last_change + self.frame_interval.mul_f64(INPUT_STREAM_TICKS);
        let streaming = self.now < input_until;
        if due && (self.view_changed || (self.time_changed && !streaming)) {
            Next::Render(Quality::Interactive)
        } else if self.view_changed {
            Next::Until(self.next_tick)
        } else if self.time_changed && streaming {
            Next::Until(input_until.max(self.next_tick))
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

/// What the slot needs to know about a frame besides the frame, and the scene it showed.
struct Shown<'a> {
    sequence: u64,
    input_at: Option<Instant>,
    fps: f64,
    entry: &'a SceneEntry,
}

impl<'a> Shown<'a> {
    fn new(sequence: u64, input_at: Option<Instant>, fps: f64, entry: &'a SceneEntry) -> Self {
        Shown {
            sequence,
            input_at,
            fps,
            entry,
        }
    }
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
        if let Some(per_pixel) = controller.pool_s_per_pixel {
            shown.entry.note_pixel_cost(per_pixel);
        }
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
    let mut controller = Controller::new(config.jpeg_quality, config.min_scale, config.pool_share)
        .starting_from(entry.pixel_cost());
    let mut video: VideoState = None;
    // What the last frame showed: settings version, state key, and whether it was the still.
    let mut last: Option<(u64, u128, Quality)> = None;
    let mut last_change = tokio::time::Instant::now();
    let mut bucket = FrameBucket::new(tokio::time::Instant::now());
    let mut sequence = 0u64;
    let mut seen: Option<f64> = None;
    // Effects hook: a still view keeps refining (one pass per still frame) until converged.
    let refinement = Arc::new(Refinement::new(
        config.max_refine_passes,
        config.antialias_passes,
    ));
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
            next_tick: bucket.ready_at(now, fps),
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
            bucket.take(now, fps);
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
                let shown = Shown::new(sequence, input_at, fps, entry);
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
    let key = (
        settings.version,
        plan.time.to_bits(),
        plan.size.0,
        plan.size.1,
    );
    let pass = match plan.quality {
        Quality::Interactive => Pass::Single,
        Quality::Still => Pass::Refine(refinement, key),
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
        last: plan.quality == Quality::Still && refinement.converged(key),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A 30 fps session whose next frame is due at `tick`, last input at `input`.
    fn moment(
        now: tokio::time::Instant,
        tick: tokio::time::Instant,
        input: tokio::time::Instant,
    ) -> Moment {
        Moment {
            view_changed: false,
            time_changed: false,
            animating: true,
            shown_still: false,
            live: true,
            now,
            next_tick: tick,
            last_change: input,
            still_delay: Duration::from_millis(250),
            clock: 10.0,
            time_step_fps: 30.0,
            frame_interval: Duration::from_secs_f64(1.0 / 30.0),
        }
    }

    fn waits_until(next: Next) -> Option<tokio::time::Instant> {
        match next {
            Next::Until(at) => Some(at),
            Next::Render(_) | Next::Wake => None,
        }
    }

    #[test]
    fn input_and_new_states_share_the_sessions_frame_rate() {
        let interval = Duration::from_secs_f64(1.0 / 30.0);
        let t0 = tokio::time::Instant::now();
        let tick = t0 + interval;
        let soon = t0 + Duration::from_millis(10);
        // Input before the frame is due waits for it, with or without a new state.
        for time_changed in [false, true] {
            let early = Moment {
                view_changed: true,
                time_changed,
                ..moment(soon, tick, soon)
            };
            assert_eq!(waits_until(early.next()), Some(tick));
            let due = Moment {
                view_changed: true,
                time_changed,
                ..moment(tick, tick, tick)
            };
            assert!(matches!(due.next(), Next::Render(Quality::Interactive)));
        }
        // A new state alone while input streams (the last 10 ms ago) waits for the next
        // input, or renders once input has stopped for 2 intervals.
        let quiet = t0 + interval.mul_f64(2.0);
        for now in [soon, tick] {
            let state = Moment {
                time_changed: true,
                ..moment(now, t0, t0)
            };
            assert_eq!(waits_until(state.next()), Some(quiet));
        }
        let stopped = Moment {
            time_changed: true,
            ..moment(quiet, t0, t0)
        };
        assert!(matches!(stopped.next(), Next::Render(Quality::Interactive)));
        // Without input, a new state renders when due.
        let animation = Moment {
            time_changed: true,
            ..moment(tick, tick, t0 - Duration::from_secs(1))
        };
        assert!(matches!(
            animation.next(),
            Next::Render(Quality::Interactive)
        ));
    }

    #[test]
    fn the_frame_bucket_holds_the_rate_and_lets_early_input_through() {
        let fps = 30.0;
        let interval = Duration::from_secs_f64(1.0 / fps);
        let t0 = tokio::time::Instant::now();
        let mut bucket = FrameBucket::new(t0);
        // Frames as fast as they are allowed, for 3 s: about 90 of them, never more than the
        // rate plus the burst.
        let mut now = t0;
        let mut frames = 0;
        while now < t0 + Duration::from_secs(3) {
            now = bucket.ready_at(now, fps);
            bucket.take(now, fps);
            frames += 1;
        }
        assert!(
            (90..=92).contains(&frames),
            "{frames} frames in 3 s at 30 fps"
        );
        // Input every 34 ms (a client timer a little off 30 Hz, a frame each) never waits,
        // and neither does one that comes 5 ms early after a steady run.
        let mut bucket = FrameBucket::new(t0);
        let mut at = t0;
        for _ in 0..60 {
            assert_eq!(bucket.ready_at(at, fps), at);
            bucket.take(at, fps);
            at += Duration::from_millis(34);
        }
        let early = at - Duration::from_millis(5);
        assert_eq!(bucket.ready_at(early, fps), early);
        // After a frame, one right behind it waits for most of an interval.
        bucket.take(early, fps);
        let next = bucket.ready_at(early, fps);
        assert!(next > early + interval.mul_f64(0.5), "{:?}", next - early);
    }
}
