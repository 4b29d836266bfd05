//! One viewer's websocket session: read inputs, render when something changed, send frames.
//!
//! Three loops run together in the session's task and end together:
//! - the reader applies inputs to the session's [`Settings`] and wakes the renderer;
//! - the renderer waits until the view or the scene time changed *and* the frame slot is
//!   empty, hands the frame to the render pool (never rendering on the async runtime), and
//!   puts the encoded result in the slot;
//! - the writer takes frames from the slot and error messages from a small queue and sends
//!   them.
//!
//! Adaptive resolution: while the view moves, frames are rendered at a scale chosen so that
//! tracing plus encoding fits [`FRAME_BUDGET_SHARE`] of the frame interval, measured from the
//! previous frame (so a busy pool lowers every session's scale alike); the still frame is
//! always full size.
//!
//! Flow control: the slot holds at most one frame, and the renderer starts a frame only while
//! fewer than [`FRAME_WINDOW`] sent frames await the client's `ack`. A client that stops
//! reading stops acknowledging, so the renderer stops: it costs one frame of memory and no
//! CPU, and no backlog builds up in socket buffers. When it reads and acknowledges again, the
//! next frame rendered shows the newest state.

use crate::input::{self, Limits, Settings};
use crate::metrics as m;
use crate::scenes::{micros, SceneEntry};
use crate::state::{AppState, SessionTicket};
use axum::body::Bytes;
use axum::extract::ws::{CloseFrame, Message, WebSocket};
use futures_util::{SinkExt, StreamExt};
use isoray_protocol::{
    ClientMessage, Codec, ErrorMessage, FrameAck, FrameHeader, ServerMessage, SessionInfo,
    StageTimings, FLAG_STILL, PROTOCOL_VERSION,
};
use isoray_render::View;
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, oneshot, Notify};
use tracing::Instrument;

/// Frames sent ahead of the client's acknowledgements: one on screen, one on the wire.
pub const FRAME_WINDOW: u64 = 2;

/// Error messages queued for a client that is not reading; more are dropped.
const CONTROL_QUEUE: usize = 16;

/// Counters of one session, readable while it runs (tests, metrics).
#[derive(Debug, Default)]
pub struct SessionStats {
    pub frames_rendered: AtomicU64,
    pub frames_sent: AtomicU64,
    pub inputs_applied: AtomicU64,
    pub inputs_rejected: AtomicU64,
    /// Highest frame sequence sent, and highest acknowledged by the client.
    pub last_sent_sequence: AtomicU64,
    pub last_acked_sequence: AtomicU64,
    /// Frames rendered but not yet handed to the socket, now and at most.
    pub pending_frames: AtomicUsize,
    /// Resolution scale of interactive frames, in thousandths (1000 = full size).
    pub scale_permille: AtomicU32,
    pub max_pending_frames: AtomicUsize,
}

/// A rendered frame waiting for the writer.
struct SlotFrame {
    sequence: u64,
    bytes: Bytes,
    codec: &'static str,
    /// When the input this frame first shows arrived, for the latency histogram.
    input_at: Option<Instant>,
}

/// The one-frame mailbox between renderer and writer.
#[derive(Default)]
struct FrameSlot {
    frame: Mutex<Option<SlotFrame>>,
    ready: Notify,
}

impl FrameSlot {
    fn lock(&self) -> std::sync::MutexGuard<'_, Option<SlotFrame>> {
        // Only plain values live here; a panic elsewhere cannot leave them inconsistent.
        self.frame.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn is_empty(&self) -> bool {
        self.lock().is_none()
    }

    fn put(&self, frame: SlotFrame, stats: &SessionStats) {
        let replaced = self.lock().replace(frame).is_some();
        if !replaced {
            let now = stats.pending_frames.fetch_add(1, Ordering::SeqCst) + 1;
            stats.max_pending_frames.fetch_max(now, Ordering::SeqCst);
        }
        self.ready.notify_one();
    }

    fn take(&self, stats: &SessionStats) -> Option<SlotFrame> {
        let frame = self.lock().take();
        if frame.is_some() {
            stats.pending_frames.fetch_sub(1, Ordering::SeqCst);
        }
        frame
    }
}

/// Runs a session until the client leaves, the connection fails or the server shuts down.
pub async fn run(socket: WebSocket, app: AppState, entry: Arc<SceneEntry>, ticket: SessionTicket) {
    let span = tracing::info_span!("session", id = ticket.id, scene = entry.id());
    run_registered(socket, &app, entry, &ticket.stats)
        .instrument(span)
        .await;
}

/// Tells a client the server is full, then closes (code 1013, "try again later").
pub async fn refuse(mut socket: WebSocket, limit: usize) {
    let error = ServerMessage::Error(ErrorMessage {
        code: "server_full".into(),
        message: format!("the server is at its limit of {limit} sessions; try again later"),
        input_id: None,
    });
    let _ = socket.send(Message::Text(to_json(&error).into())).await;
    let close = CloseFrame {
        code: 1013,
        reason: "server full".into(),
    };
    let _ = socket.send(Message::Close(Some(close))).await;
}

async fn run_registered(
    socket: WebSocket,
    app: &AppState,
    entry: Arc<SceneEntry>,
    stats: &SessionStats,
) {
    tracing::info!("session opened");

    let config = app.config();
    let demo = entry.demo();
    let camera = demo.default_camera();
    let settings = Settings {
        camera,
        isovalue: demo.default_isovalue(),
        width: config.default_width,
        height: config.default_height,
        pinned_time: None,
        last_input_id: 0,
        version: 0,
        last_input_at: None,
        effects: crate::effects::clamp(
            &entry.lighting().effects,
            &crate::effects::EffectLimits::from_config(config),
        ),
    };
    let limits = Limits {
        max_size: config.max_size,
        isovalue_range: entry.isovalue_range(),
        effects: crate::effects::EffectLimits::from_config(config),
    };
    let slider = demo.isovalue_slider();
    let info = ServerMessage::Info(SessionInfo {
        protocol_version: PROTOCOL_VERSION,
        scene: entry.summary(),
        max_width: config.max_size,
        max_height: config.max_size,
        width: settings.width,
        height: settings.height,
        isovalue: settings.isovalue as f64,
        isovalue_range: [
            limits.isovalue_range.0 as f64,
            limits.isovalue_range.1 as f64,
        ],
        isovalue_slider: [slider.0 as f64, slider.1 as f64],
        frame_window: FRAME_WINDOW as u32,
        camera: isoray_protocol::CameraPose {
            eye: camera.eye.as_dvec3().to_array(),
            target: camera.target.as_dvec3().to_array(),
            up: camera.up.as_dvec3().to_array(),
            fov_y_deg: camera.fov_y_deg as f64,
        },
        effects: crate::effects::info(
            entry.lighting(),
            entry.effect_primitives(),
            &settings.effects,
            &limits.effects,
        ),
    });

    let settings = Arc::new(Mutex::new(settings));
    // Wakes the renderer: an input applied, an ack received, the slot emptied.
    let wake = Arc::new(Notify::new());
    let slot = Arc::new(FrameSlot::default());
    let (control_tx, control_rx) = mpsc::channel::<Message>(CONTROL_QUEUE);
    let (mut sink, stream) = socket.split();

    let mut shutdown = app.shutdown_signal();
    let timing = Heartbeat {
        ping_every: Duration::from_secs(app.config().ping_interval_secs),
        idle_after: Duration::from_secs(app.config().idle_timeout_secs),
    };
    let outcome = async {
        sink.send(Message::Text(to_json(&info).into())).await?;
        tokio::select! {
            r = read_loop(stream, &settings, &wake, &limits, &control_tx, stats, timing.idle_after) => r,
            r = write_loop(&mut sink, control_rx, &slot, &wake, stats, timing.ping_every) => r.map(|()| End::ClientGone),
            () = render_loop(app, &entry, &settings, &wake, &slot, stats) => Ok(End::ClientGone),
            _ = async { shutdown.wait_for(|down| *down).await.map(|_| ()) } => Ok(End::Shutdown),
        }
    }
    .await;

    let frames = stats.frames_sent.load(Ordering::Relaxed);
    let close = |reason: String| {
        Message::Close(Some(CloseFrame {
            code: 1001,
            reason: reason.into(),
        }))
    };
    match outcome {
        Ok(End::ClientGone) => tracing::info!(frames, "session closed by the client"),
        Ok(End::Shutdown) => {
            let _ = sink.send(close("server shutting down".into())).await;
            tracing::info!(frames, "session closed: server shutting down");
        }
        Ok(End::Idle) => {
            let secs = timing.idle_after.as_secs();
            let _ = sink
                .send(close(format!("no message from the client for {secs} s")))
                .await;
            tracing::info!(frames, "session closed: client idle");
        }
        Err(e) => tracing::info!(frames, error = %e, "session ended by a connection error"),
    }
}

/// Why a session ended.
enum End {
    /// The client closed the socket or it went away.
    ClientGone,
    /// Nothing arrived from the client (not even a pong) for the idle timeout.
    Idle,
    Shutdown,
}

#[derive(Clone, Copy)]
struct Heartbeat {
    ping_every: Duration,
    idle_after: Duration,
}

fn to_json(msg: &ServerMessage) -> String {
    // Serializing these plain structs cannot fail: no maps with non-string keys, no floats
    // that serde_json refuses (NaN serializes as null).
    serde_json::to_string(msg).unwrap_or_else(|_| String::from(r#"{"type":"error"}"#))
}

async fn read_loop(
    mut stream: futures_util::stream::SplitStream<WebSocket>,
    settings: &Mutex<Settings>,
    wake: &Notify,
    limits: &Limits,
    control: &mpsc::Sender<Message>,
    stats: &SessionStats,
    idle_after: Duration,
) -> Result<End, axum::Error> {
    loop {
        // Browsers answer pings with pongs by themselves, so a live client is never idle.
        let Ok(message) = tokio::time::timeout(idle_after, stream.next()).await else {
            return Ok(End::Idle);
        };
        let Some(message) = message else {
            return Ok(End::ClientGone);
        };
        let result = match message? {
            Message::Text(text) => input::parse(text.as_str()).and_then(|msg| match msg {
                ClientMessage::Ack(FrameAck { sequence }) => acknowledge(sequence, stats),
                msg => {
                    let mut s = settings.lock().unwrap_or_else(|e| e.into_inner());
                    let applied = input::apply(&msg, &mut s, limits);
                    if applied.is_ok() {
                        s.last_input_at = Some(Instant::now());
                    }
                    applied
                }
            }),
            Message::Binary(_) => Err(ErrorMessage {
                code: "unsupported".into(),
                message: "binary messages are not part of protocol v1; send JSON text".into(),
                input_id: None,
            }),
            Message::Close(_) => return Ok(End::ClientGone),
            Message::Ping(_) | Message::Pong(_) => continue,
        };
        match result {
            Ok(()) => {
                stats.inputs_applied.fetch_add(1, Ordering::Relaxed);
                wake.notify_one();
            }
            Err(error) => {
                stats.inputs_rejected.fetch_add(1, Ordering::Relaxed);
                metrics::counter!(m::INPUTS_REJECTED).increment(1);
                tracing::debug!(code = %error.code, message = %error.message, "input rejected");
                // A client that floods bad input without reading loses the surplus errors.
                let _ =
                    control.try_send(Message::Text(to_json(&ServerMessage::Error(error)).into()));
            }
        }
    }
}

/// Records the client's acknowledgement of every frame up to `sequence`.
fn acknowledge(sequence: u64, stats: &SessionStats) -> Result<(), ErrorMessage> {
    let sent = stats.last_sent_sequence.load(Ordering::SeqCst);
    if sequence > sent {
        return Err(ErrorMessage {
            code: "invalid_value".into(),
            message: format!("ack of frame {sequence}, but the last frame sent is {sent}"),
            input_id: None,
        });
    }
    stats
        .last_acked_sequence
        .fetch_max(sequence, Ordering::SeqCst);
    Ok(())
}

async fn write_loop(
    sink: &mut futures_util::stream::SplitSink<WebSocket, Message>,
    mut control: mpsc::Receiver<Message>,
    slot: &FrameSlot,
    wake: &Notify,
    stats: &SessionStats,
    ping_every: Duration,
) -> Result<(), axum::Error> {
    let mut ping = tokio::time::interval_at(tokio::time::Instant::now() + ping_every, ping_every);
    loop {
        tokio::select! {
            biased;
            _ = ping.tick() => sink.send(Message::Ping(Bytes::from_static(b"isoray"))).await?,
            message = control.recv() => match message {
                Some(message) => sink.send(message).await?,
                None => return Ok(()),
            },
            () = slot.ready.notified() => {
                if let Some(frame) = slot.take(stats) {
                    wake.notify_one();
                    stats.last_sent_sequence.store(frame.sequence, Ordering::SeqCst);
                    let len = frame.bytes.len() as u64;
                    sink.send(Message::Binary(frame.bytes)).await?;
                    stats.frames_sent.fetch_add(1, Ordering::Relaxed);
                    metrics::counter!(m::FRAMES_SENT, "codec" => frame.codec).increment(1);
                    metrics::counter!(m::FRAME_BYTES).increment(len);
                    if let Some(input_at) = frame.input_at {
                        m::input_to_frame(input_at.elapsed());
                    }
                }
            }
        }
    }
}

async fn render_loop(
    app: &AppState,
    entry: &Arc<SceneEntry>,
    settings: &Mutex<Settings>,
    wake: &Notify,
    slot: &FrameSlot,
    stats: &SessionStats,
) {
    let fps = app.config().max_fps;
    let frame_interval = Duration::from_secs_f64(1.0 / fps);
    let still_delay = Duration::from_millis(app.config().still_after_ms);
    // Interactive frames aim to be traced and encoded within this share of a frame interval.
    let budget_us = frame_interval.as_secs_f64() * 1e6 * FRAME_BUDGET_SHARE;
    let mut scale = 1.0f64;
    // What the last frame showed: settings version, scene time, and whether it was the still.
    let mut last: Option<(u64, f64, Quality)> = None;
    let mut last_change = tokio::time::Instant::now();
    let mut next_tick = tokio::time::Instant::now();
    let mut sequence = 0u64;
    // Effects hook: a still view keeps refining (one pass per still frame) until converged.
    let refinement = Arc::new(crate::refine::Refinement::new(
        app.config().max_refine_passes,
    ));
    loop {
        // Flow control: one frame in the slot at most, and a window of unacknowledged ones.
        let acked = stats.last_acked_sequence.load(Ordering::SeqCst);
        if !slot.is_empty() || sequence + 1 > acked + FRAME_WINDOW {
            wake.notified().await;
            continue;
        }
        let current = settings.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let time = current
            .pinned_time
            .unwrap_or_else(|| (app.scenes().live_time() * fps).floor() / fps);
        let now = tokio::time::Instant::now();
        let view_changed = last.map(|(v, _, _)| v) != Some(current.version);
        let time_changed = last.map(|(_, t, _)| t) != Some(time);
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
        // New input renders at once; animation alone at most once per tick; once input stops
        // on a still scene, one lossless still frame, then nothing until something changes.
        let quality = if view_changed || (time_changed && now >= next_tick) {
            Quality::Interactive
        } else if !time_changed && !shown_still && now >= last_change + still_delay {
            Quality::Still
        } else {
            let deadline = if time_changed {
                next_tick
            } else if !shown_still {
                last_change + still_delay
            } else {
                wake.notified().await;
                continue;
            };
            tokio::select! {
                () = wake.notified() => {}
                () = tokio::time::sleep_until(deadline) => {}
            }
            continue;
        };
        if quality == Quality::Interactive {
            next_tick = now + frame_interval;
        }
        sequence += 1;
        last = Some((current.version, time, quality));

        let input_at = if view_changed {
            current.last_input_at
        } else {
            None
        };
        let codec = match quality {
            Quality::Interactive => "jpeg",
            Quality::Still => "png",
        };
        let full = (current.width, current.height);
        let (width, height) = match quality {
            Quality::Interactive => scaled_size(full.0, full.1, scale),
            Quality::Still => full,
        };
        let (tx, rx) = oneshot::channel();
        let job_entry = Arc::clone(entry);
        let job_app = app.clone();
        let job_refinement = Arc::clone(&refinement);
        metrics::gauge!(m::RENDER_QUEUE).increment(1.0);
        app.backend().spawn(move || {
            let frame = render_frame(
                &job_app,
                &job_entry,
                &current,
                time,
                sequence,
                quality,
                (width, height),
                &job_refinement,
            );
            metrics::gauge!(m::RENDER_QUEUE).decrement(1.0);
            let _ = tx.send(frame);
        });
        match rx.await {
            Ok(Ok((bytes, timings))) => {
                stats.frames_rendered.fetch_add(1, Ordering::Relaxed);
                if quality == Quality::Interactive {
                    let spent_us = (timings.trace_us + timings.encode_us).max(1) as f64;
                    let per_pixel_us = spent_us / (width as f64 * height as f64);
                    let full_pixels = full.0 as f64 * full.1 as f64;
                    let wanted = (budget_us / per_pixel_us / full_pixels).sqrt();
                    let min = app.config().min_scale;
                    // Halfway towards the measured scale: steady under noise, quick to follow.
                    scale = (0.5 * scale + 0.5 * wanted).clamp(min, 1.0);
                    stats
                        .scale_permille
                        .store((scale * 1000.0).round() as u32, Ordering::Relaxed);
                }
                let frame = SlotFrame {
                    sequence,
                    bytes,
                    codec,
                    input_at,
                };
                slot.put(frame, stats);
            }
            Ok(Err(e)) => {
                tracing::warn!(error = %e, "frame failed; the session waits for the next change");
                wake.notified().await;
            }
            Err(_) => return, // the pool dropped the job: the server is going down
        }
    }
}

/// Share of the frame interval an interactive frame may spend tracing and encoding.
const FRAME_BUDGET_SHARE: f64 = 0.7;

/// The requested size scaled by `scale`, keeping the aspect ratio, never below 8 pixels.
fn scaled_size(width: u32, height: u32, scale: f64) -> (u32, u32) {
    if scale >= 1.0 {
        return (width, height);
    }
    let s = |v: u32| ((v as f64 * scale).round() as u32).clamp(8.min(v), v);
    (s(width), s(height))
}

/// How a frame is made: fast while the view changes, lossless once it settles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Quality {
    /// JPEG at the configured quality.
    Interactive,
    /// PNG, bit-exact to the renderer's output, flagged `FLAG_STILL`.
    Still,
}

/// Prepares, traces and encodes one frame. Runs on the render pool.
#[allow(clippy::too_many_arguments)]
fn render_frame(
    app: &AppState,
    entry: &SceneEntry,
    settings: &Settings,
    time: f64,
    sequence: u64,
    quality: Quality,
    (width, height): (u32, u32),
    refinement: &crate::refine::Refinement,
) -> Result<(Bytes, StageTimings), crate::encode::EncodeError> {
    let state = entry.prepared_at(time, settings.pinned_time.is_none());
    let view = View {
        width,
        height,
        camera: settings.camera,
        isovalue: settings.isovalue,
    };
    let t0 = Instant::now();
    // Effects hook: interactive frames trace one pass of the session's effects; a still frame
    // adds a refinement pass.
    let fb = match quality {
        Quality::Interactive => {
            app.backend()
                .render_effects(&state.prepared, &view, &settings.effects)
                .0
        }
        Quality::Still => {
            let key = (settings.version, time.to_bits(), width, height);
            refinement.next_pass(
                app.backend(),
                &state.prepared,
                &view,
                &settings.effects,
                key,
            )
        }
    };
    let t1 = Instant::now();
    let (codec, flags, payload) = match quality {
        Quality::Interactive => (
            Codec::Jpeg,
            0,
            crate::encode::jpeg(&fb, app.config().jpeg_quality)?,
        ),
        Quality::Still => (Codec::Png, FLAG_STILL, crate::encode::png(&fb)?),
    };
    let header = FrameHeader {
        version: PROTOCOL_VERSION,
        sequence,
        input_id: settings.last_input_id,
        width: fb.width,
        height: fb.height,
        codec,
        flags,
        timings: StageTimings {
            update_us: state.update_us,
            build_us: state.build_us,
            trace_us: micros(t1 - t0),
            encode_us: micros(t1.elapsed()),
        },
        // A stored scene's frame shows its step's time, a live demo's the state it shows.
        scene_time: state.step_time.unwrap_or(time),
    };
    m::stage("update", header.timings.update_us);
    m::stage("build", header.timings.build_us);
    m::stage("trace", header.timings.trace_us);
    m::stage("encode", header.timings.encode_us);
    let mut bytes = Vec::with_capacity(isoray_protocol::FRAME_HEADER_LEN + payload.len());
    bytes.extend_from_slice(&header.encode());
    bytes.extend_from_slice(&payload);
    Ok((Bytes::from(bytes), header.timings))
}
