//! One viewer's websocket session: read inputs, render when something changed, send frames.
//!
//! Three loops run together in the session's task and end together:
//! - the reader applies inputs to the session's [`Settings`], records acknowledgements (and
//!   from them the bandwidth the client receives) and wakes the renderer;
//! - the renderer waits until the view or the scene time changed *and* the frame slot is
//!   empty, plans the frame (size, codec, JPEG quality, depth channel) with the adaptive
//!   [`Controller`], hands it to the fair [`RenderScheduler`](crate::schedule) (never rendering
//!   on the async runtime), and puts the encoded result in the slot;
//! - the writer takes frames from the slot and error messages from a small queue and sends
//!   them, with a ping every `--ping-interval-secs`.
//!
//! Interactive and still frames: while inputs arrive or the scene animates, frames are
//! *interactive*: JPEG (or, once motion is sustained and the client decodes it, H.264) at a
//! resolution and quality the controller picks to hold the session's frame rate within its
//! share of the pool and its measured bandwidth. When input stops on a still scene, one
//! full-size lossless PNG *still* frame follows, then nothing until something changes. A
//! hidden client (`stream` message with `visible: false`) gets nothing and costs nothing.
//!
//! Flow control: the slot holds at most one frame, and the renderer starts a frame only while
//! fewer than [`FRAME_WINDOW`] sent frames await the client's `ack`. A client that stops
//! reading stops acknowledging, so the renderer stops: it costs one frame of memory and no
//! CPU, and no backlog builds up in socket buffers. When it reads and acknowledges again, the
//! next frame rendered shows the newest state.

use crate::encode::{self, EncodeError};
use crate::input::{self, Limits, Settings, StreamSettings};
use crate::metrics as m;
use crate::scenes::{micros, SceneEntry};
use crate::schedule::JobCost;
use crate::state::{AppState, SessionTicket};
use axum::body::Bytes;
use axum::extract::ws::{CloseFrame, Message, WebSocket};
use futures_util::{SinkExt, StreamExt};
use isoray_protocol::{
    ClientMessage, Codec, ErrorMessage, FrameAck, FrameHeader, ServerMessage, SessionInfo,
    StageTimings, FLAG_DEPTH, FLAG_KEYFRAME, FLAG_STILL, PROTOCOL_VERSION,
};
use isoray_render::{Framebuffer, View};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, Notify};
use tracing::Instrument;

/// Frames sent ahead of the client's acknowledgements: one on screen, one on the wire.
pub const FRAME_WINDOW: u64 = 2;

/// Error messages queued for a client that is not reading; more are dropped.
const CONTROL_QUEUE: usize = 16;

/// Share of a session's frame interval (divided among the sessions competing for the pool)
/// that tracing and encoding an interactive frame may take. Below 1 so that an input waits
/// for less than a frame interval behind the frame already in progress.
const FRAME_BUDGET_SHARE: f64 = 0.6;

/// Share of the measured bandwidth interactive frames may use.
const BANDWIDTH_SHARE: f64 = 0.8;

/// Lowest JPEG quality the controller goes to before it lowers the resolution for bandwidth.
const MIN_JPEG_QUALITY: u8 = 30;

/// Consecutive interactive frames after which motion counts as sustained and a client that
/// decodes H.264 gets it.
const H264_AFTER_FRAMES: u32 = 12;

/// H.264 bits per pixel and frame when bandwidth is plentiful.
const H264_BITS_PER_PIXEL: f64 = 0.12;

/// Lowest H.264 bit rate: small frames need more bits per pixel than large ones.
const H264_MIN_BITRATE_BPS: f64 = 400_000.0;

/// An H.264 stream keeps its size until the controller's size differs by more than this
/// fraction (a new size costs a keyframe).
const H264_RESIZE_HYSTERESIS: f64 = 0.15;

/// The depth channel is this many times smaller than its frame in each direction.
const DEPTH_FACTOR: u32 = 4;

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

/// A rendered frame waiting for the writer.
struct SlotFrame {
    sequence: u64,
    bytes: Bytes,
    codec: Codec,
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
        if replaced {
            stats.frames_dropped.fetch_add(1, Ordering::Relaxed);
            metrics::counter!(m::FRAMES_DROPPED, "reason" => "replaced").increment(1);
        } else {
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

/// Estimates the bandwidth to the client from acknowledgements.
///
/// Each acknowledged frame gives a service time: from when the link could start on it (its
/// send, or the previous acknowledgement if it was sent before that) to its own
/// acknowledgement. A link of `B` bytes per second with a fixed latency `L` (round trip plus
/// the client's decoding before it acknowledges) serves a frame of `b` bytes in `L + b / B`,
/// so the estimate is the slope of a least-squares line through the (bytes, service time)
/// samples of the last two seconds, frames differ in size enough for that (the camera
/// moves, the controller changes quality). Only a clear fit counts (correlation at least
/// [`BANDWIDTH_MIN_CORRELATION`], positive slope): when service time does not grow with
/// frame size, the client is limited by latency or by its own pace, smaller frames would not
/// help, and bandwidth limits nothing. A clear fit holds for two windows, since frames of a
/// settled controller are too alike in size for a new one.
#[derive(Default)]
struct Bandwidth {
    in_flight: VecDeque<(u64, usize, Instant)>,
    last_ack_at: Option<Instant>,
    /// (acknowledged at, bytes, service seconds)
    samples: VecDeque<(Instant, f64, f64)>,
    /// The last clear fit and when it was made: it holds while frames are too alike in size
    /// for a new one (as they are once the controller has settled).
    last_clear: Option<(Instant, f64)>,
}

/// How long a bandwidth sample counts.
const BANDWIDTH_WINDOW: Duration = Duration::from_secs(2);

/// Samples needed before the estimate limits anything.
const BANDWIDTH_MIN_SAMPLES: usize = 6;

/// Correlation of service time with frame size below which size is not what limits.
const BANDWIDTH_MIN_CORRELATION: f64 = 0.7;

impl Bandwidth {
    fn sent(&mut self, sequence: u64, bytes: usize, at: Instant) {
        // Bounded: the renderer keeps at most FRAME_WINDOW frames unacknowledged.
        if self.in_flight.len() >= 64 {
            self.in_flight.pop_front();
        }
        self.in_flight.push_back((sequence, bytes, at));
    }

    fn acked(&mut self, sequence: u64, at: Instant) {
        let mut delivered = 0usize;
        let mut first_sent = None;
        while let Some(&(seq, bytes, sent)) = self.in_flight.front() {
            if seq > sequence {
                break;
            }
            self.in_flight.pop_front();
            delivered += bytes;
            first_sent.get_or_insert(sent);
        }
        let Some(first_sent) = first_sent else {
            return;
        };
        let start = self.last_ack_at.map_or(first_sent, |a| a.max(first_sent));
        self.last_ack_at = Some(at);
        self.samples
            .push_back((at, delivered as f64, (at - start).as_secs_f64()));
        while self
            .samples
            .front()
            .is_some_and(|(t, _, _)| at - *t > BANDWIDTH_WINDOW)
        {
            self.samples.pop_front();
        }
        if let Some(fit) = self.fit() {
            self.last_clear = Some((at, fit));
        }
    }

    /// Bytes per second: the last clear fit of the last two bandwidth windows.
    fn estimate(&self) -> Option<f64> {
        let (at, fit) = self.last_clear?;
        let newest = self.samples.back().map_or(at, |s| s.0);
        (newest - at <= 2 * BANDWIDTH_WINDOW).then_some(fit)
    }

    /// The slope fit of the current samples, when it is clear.
    fn fit(&self) -> Option<f64> {
        let n = self.samples.len();
        if n < BANDWIDTH_MIN_SAMPLES {
            return None;
        }
        let mean_b = self.samples.iter().map(|s| s.1).sum::<f64>() / n as f64;
        let mean_s = self.samples.iter().map(|s| s.2).sum::<f64>() / n as f64;
        let (mut var_b, mut var_s, mut cov) = (0.0, 0.0, 0.0);
        for &(_, b, s) in &self.samples {
            var_b += (b - mean_b) * (b - mean_b);
            var_s += (s - mean_s) * (s - mean_s);
            cov += (b - mean_b) * (s - mean_s);
        }
        if var_b <= 0.0 || var_s <= 0.0 || cov <= 0.0 {
            return None;
        }
        let correlation = cov / (var_b * var_s).sqrt();
        (correlation >= BANDWIDTH_MIN_CORRELATION).then(|| var_b / cov)
    }
}

/// What the session shares between its loops.
struct Shared {
    settings: Mutex<Settings>,
    /// Wakes the renderer: an input applied, an ack received, the slot emptied.
    wake: Notify,
    slot: FrameSlot,
    bandwidth: Mutex<Bandwidth>,
}

impl Shared {
    fn settings(&self) -> std::sync::MutexGuard<'_, Settings> {
        self.settings.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn bandwidth(&self) -> std::sync::MutexGuard<'_, Bandwidth> {
        self.bandwidth.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Runs a session until the client leaves, the connection fails or the server shuts down.
pub async fn run(socket: WebSocket, app: AppState, entry: Arc<SceneEntry>, ticket: SessionTicket) {
    let span = tracing::info_span!("session", id = ticket.id, scene = entry.id());
    run_registered(socket, &app, entry, ticket.id, &ticket.stats)
        .instrument(span)
        .await;
    app.scheduler().forget(ticket.id);
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
    id: u64,
    stats: &SessionStats,
) {
    tracing::info!("session opened");

    let config = app.config();
    let demo = entry.demo();
    let camera = demo.default_camera();
    let offered = encode::offered_codecs();
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
        stream: StreamSettings::initial(config.max_fps),
    };
    let limits = Limits {
        max_size: config.max_size,
        isovalue_range: entry.isovalue_range(),
        effects: crate::effects::EffectLimits::from_config(config),
        codecs: offered.clone(),
        max_fps: config.max_fps,
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
        codecs: offered.iter().map(|c| c.name().to_string()).collect(),
        max_fps: config.max_fps,
    });

    let shared = Shared {
        settings: Mutex::new(settings),
        wake: Notify::new(),
        slot: FrameSlot::default(),
        bandwidth: Mutex::new(Bandwidth::default()),
    };
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
            r = read_loop(stream, &shared, &limits, &control_tx, stats, timing.idle_after) => r,
            r = write_loop(&mut sink, control_rx, &shared, stats, timing.ping_every) => r.map(|()| End::ClientGone),
            () = render_loop(app, &entry, id, &shared, stats) => Ok(End::ClientGone),
            _ = async { shutdown.wait_for(|down| *down).await.map(|_| ()) } => Ok(End::Shutdown),
        }
    }
    .await;

    if shared.slot.take(stats).is_some() {
        stats.frames_dropped.fetch_add(1, Ordering::Relaxed);
        metrics::counter!(m::FRAMES_DROPPED, "reason" => "session_end").increment(1);
    }
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
    shared: &Shared,
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
                ClientMessage::Ack(FrameAck { sequence }) => acknowledge(sequence, shared, stats),
                msg => {
                    let mut s = shared.settings();
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
                shared.wake.notify_one();
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
fn acknowledge(sequence: u64, shared: &Shared, stats: &SessionStats) -> Result<(), ErrorMessage> {
    let sent = stats.last_sent_sequence.load(Ordering::SeqCst);
    if sequence > sent {
        return Err(ErrorMessage {
            code: "invalid_value".into(),
            message: format!("ack of frame {sequence}, but the last frame sent is {sent}"),
            input_id: None,
        });
    }
    let before = stats
        .last_acked_sequence
        .fetch_max(sequence, Ordering::SeqCst);
    if sequence > before {
        let mut bandwidth = shared.bandwidth();
        bandwidth.acked(sequence, Instant::now());
        // The last clear estimate stays visible while none is clear.
        if let Some(estimate) = bandwidth.estimate() {
            stats
                .bandwidth_bytes_per_s
                .store(estimate as u64, Ordering::Relaxed);
        }
    }
    Ok(())
}

async fn write_loop(
    sink: &mut futures_util::stream::SplitSink<WebSocket, Message>,
    mut control: mpsc::Receiver<Message>,
    shared: &Shared,
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
            () = shared.slot.ready.notified() => {
                if let Some(frame) = shared.slot.take(stats) {
                    shared.wake.notify_one();
                    stats.last_sent_sequence.store(frame.sequence, Ordering::SeqCst);
                    let len = frame.bytes.len();
                    shared.bandwidth().sent(frame.sequence, len, Instant::now());
                    sink.send(Message::Binary(frame.bytes)).await?;
                    stats.frames_sent.fetch_add(1, Ordering::Relaxed);
                    metrics::counter!(m::FRAMES_SENT, "codec" => frame.codec.name()).increment(1);
                    metrics::counter!(m::FRAME_BYTES, "codec" => frame.codec.name())
                        .increment(len as u64);
                    if let Some(input_at) = frame.input_at {
                        m::input_to_frame(input_at.elapsed());
                    }
                }
            }
        }
    }
}

/// How a frame is made: fast while the view changes, lossless once it settles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Quality {
    /// JPEG or H.264 at the controller's size and quality.
    Interactive,
    /// PNG at full size, bit-exact to the renderer's output, flagged `FLAG_STILL`.
    Still,
}

/// The adaptive controller of one session: picks the size and JPEG quality of interactive
/// frames from what the previous frames cost and the bandwidth the client receives.
///
/// - Time: a frame may take `FRAME_BUDGET_SHARE / (fps × sessions competing)` of pool time.
///   The controller learns the pool time per pixel from every interactive frame and picks the
///   scale whose pixel count fits, moving halfway there each frame (steady under noise, quick
///   to follow a change in load).
/// - Bandwidth: a frame may take `BANDWIDTH_SHARE × bandwidth / fps` bytes. Over it, JPEG
///   quality drops in steps of 10 down to [`MIN_JPEG_QUALITY`], then the scale drops too; well
///   under it, quality climbs back in steps of 5 up to `--jpeg-quality`.
#[derive(Debug)]
pub struct Controller {
    scale: f64,
    quality: u8,
    max_quality: u8,
    min_scale: f64,
    /// Pool seconds per pixel of recent interactive frames.
    pool_s_per_pixel: Option<f64>,
    /// Scale the bandwidth allows (1 when it does not limit).
    bandwidth_scale: f64,
    /// Consecutive interactive frames since the last still frame.
    motion_frames: u32,
}

impl Controller {
    pub fn new(max_quality: u8, min_scale: f64) -> Controller {
        Controller {
            scale: 1.0,
            quality: max_quality,
            max_quality,
            min_scale,
            pool_s_per_pixel: None,
            bandwidth_scale: 1.0,
            motion_frames: 0,
        }
    }

    /// The scale for the next interactive frame at `fps` with `sessions` competing.
    fn plan_scale(&mut self, full: (u32, u32), fps: f64, sessions: usize) -> f64 {
        if let Some(per_pixel) = self.pool_s_per_pixel {
            let budget_s = FRAME_BUDGET_SHARE / (fps * sessions.max(1) as f64);
            let full_pixels = full.0 as f64 * full.1 as f64;
            let wanted = (budget_s / (per_pixel * full_pixels)).sqrt();
            self.scale = 0.5 * self.scale + 0.5 * wanted;
        }
        self.scale = self
            .scale
            .min(self.bandwidth_scale)
            .clamp(self.min_scale, 1.0);
        self.scale
    }

    /// Learns from an interactive frame of `pixels` that cost `cost` and weighed `bytes`.
    fn observe(
        &mut self,
        pixels: u64,
        cost: JobCost,
        bytes: usize,
        codec: Codec,
        bandwidth: Option<f64>,
        fps: f64,
    ) {
        let per_pixel = cost.pool_s / pixels.max(1) as f64;
        self.pool_s_per_pixel = Some(match self.pool_s_per_pixel {
            Some(old) => 0.5 * old + 0.5 * per_pixel,
            None => per_pixel,
        });
        let Some(bandwidth) = bandwidth else {
            return;
        };
        let budget = BANDWIDTH_SHARE * bandwidth / fps;
        let bytes = bytes as f64;
        if bytes > budget {
            if codec == Codec::Jpeg && self.quality > MIN_JPEG_QUALITY {
                self.quality = self.quality.saturating_sub(10).max(MIN_JPEG_QUALITY);
            } else {
                self.bandwidth_scale = (self.scale * (budget / bytes).sqrt()).max(self.min_scale);
            }
        } else if bytes < 0.5 * budget {
            if self.bandwidth_scale < 1.0 {
                self.bandwidth_scale = (self.bandwidth_scale * 1.1).min(1.0);
            } else if codec == Codec::Jpeg {
                self.quality = (self.quality + 5).min(self.max_quality);
            }
        }
    }

    /// The codec of the next frame.
    fn codec(&self, quality: Quality, stream: &StreamSettings) -> Codec {
        match quality {
            Quality::Still if stream.accepts(Codec::Png) => Codec::Png,
            Quality::Still => Codec::Jpeg,
            Quality::Interactive => {
                let sustained = self.motion_frames >= H264_AFTER_FRAMES;
                if stream.accepts(Codec::H264) && (sustained || !stream.accepts(Codec::Jpeg)) {
                    Codec::H264
                } else if stream.accepts(Codec::Jpeg) {
                    Codec::Jpeg
                } else {
                    Codec::Png
                }
            }
        }
    }
}

/// The H.264 stream of a session, moved into each H.264 job and back.
#[cfg(feature = "h264")]
type VideoState = Option<encode::H264Stream>;
#[cfg(not(feature = "h264"))]
type VideoState = Option<std::convert::Infallible>;

/// Everything a render job needs, decided on the async side.
#[derive(Clone, Copy, Debug)]
struct FramePlan {
    sequence: u64,
    quality: Quality,
    codec: Codec,
    size: (u32, u32),
    jpeg_quality: u8,
    depth: bool,
    time: f64,
    fps: f64,
    /// Bit rate for a new H.264 stream.
    h264_bitrate_bps: u32,
    /// Start the H.264 stream over with a keyframe.
    h264_restart: bool,
    /// Time of the live state this session showed last: a live view takes a newer built
    /// state without waiting for the one in flight.
    seen: Option<f64>,
}

/// What a render job hands back.
struct Rendered {
    bytes: Bytes,
    codec: Codec,
    video: VideoState,
    /// Time of the state shown (a live demo's may differ from the plan's time).
    state_time: Option<f64>,
}

async fn render_loop(
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
    let refinement = Arc::new(crate::refine::Refinement::new(config.max_refine_passes));
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
        // New input renders at once; a new state at most once per tick; once input stops on a
        // view that does not animate, lossless still frames (refining), then nothing until
        // something changes.
        let quality = if view_changed || (time_changed && now >= next_tick) {
            Quality::Interactive
        } else if !animating && !time_changed && !shown_still && now >= last_change + still_delay {
            Quality::Still
        } else {
            let deadline = if time_changed {
                next_tick
            } else if animating {
                // The next time step of the live clock.
                let step = 1.0 / time_step_fps;
                let next = ((clock / step).floor() + 1.0) * step;
                now + Duration::from_secs_f64((next - clock).max(0.0))
            } else if !shown_still {
                last_change + still_delay
            } else if live {
                // A live stored scene: look for a pushed step once per frame interval.
                now + frame_interval
            } else {
                shared.wake.notified().await;
                continue;
            };
            tokio::select! {
                () = shared.wake.notified() => {}
                () = tokio::time::sleep_until(deadline) => {}
            }
            continue;
        };
        if quality == Quality::Interactive {
            next_tick = now + frame_interval;
        }
        sequence += 1;
        last = Some((current.version, state_key, quality));

        let input_at = if view_changed {
            current.last_input_at
        } else {
            None
        };
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
        let job_video = if plan.codec == Codec::H264 {
            video.take()
        } else {
            None
        };
        let job_entry = Arc::clone(entry);
        let job_app = app.clone();
        let job_settings = current.clone();
        let job_plan = FramePlan { seen, ..plan };
        let job_refinement = Arc::clone(&refinement);
        let result = app
            .scheduler()
            .submit(id, move || {
                render_frame(
                    &job_app,
                    &job_entry,
                    &job_settings,
                    &job_plan,
                    job_video,
                    &job_refinement,
                )
            })
            .await;
        match result {
            Ok((Ok(rendered), cost)) => {
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
                        fps,
                    );
                } else {
                    controller.motion_frames = 0;
                }
                if rendered.video.is_some() {
                    video = rendered.video;
                }
                if rendered.state_time.is_some() {
                    seen = rendered.state_time;
                }
                m::queue_wait(cost.queued);
                shared.slot.put(
                    SlotFrame {
                        sequence,
                        bytes: rendered.bytes,
                        codec: rendered.codec,
                        input_at,
                    },
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

/// Decides size, codec, quality and depth of the next frame.
#[allow(clippy::too_many_arguments)]
fn plan_frame(
    controller: &mut Controller,
    settings: &Settings,
    quality: Quality,
    sequence: u64,
    time: f64,
    sessions: usize,
    bandwidth: Option<f64>,
    video: Option<((u32, u32), u32)>,
) -> FramePlan {
    let full = (settings.width, settings.height);
    let fps = settings.stream.fps;
    let codec = controller.codec(quality, &settings.stream);
    let mut plan = FramePlan {
        sequence,
        quality,
        codec,
        size: full,
        jpeg_quality: match (quality, codec) {
            (Quality::Still, _) => 100,
            (Quality::Interactive, _) => controller.quality,
        },
        depth: settings.stream.depth && quality == Quality::Interactive,
        time,
        fps,
        h264_bitrate_bps: 0,
        h264_restart: false,
        seen: None,
    };
    if quality == Quality::Still {
        return plan;
    }
    let scale = controller.plan_scale(full, fps, sessions);
    plan.size = scaled_size(full.0, full.1, scale);
    if codec == Codec::H264 {
        // Even sizes, at least 16 px; keep the stream's size unless the controller's moved far.
        let even = |v: u32| (v & !1).max(16);
        let wanted = (even(plan.size.0), even(plan.size.1));
        let pixels = wanted.0 as f64 * wanted.1 as f64;
        let ceiling = pixels * fps * H264_BITS_PER_PIXEL;
        let bitrate = bandwidth.map_or(ceiling, |b| ceiling.min(BANDWIDTH_SHARE * b * 8.0));
        plan.h264_bitrate_bps = bitrate.clamp(H264_MIN_BITRATE_BPS, 50_000_000.0) as u32;
        plan.size = wanted;
        match video {
            Some((size, current_bps)) => {
                let drift = (wanted.0 as f64 / size.0 as f64 - 1.0).abs();
                let rate_drift = plan.h264_bitrate_bps as f64 / current_bps.max(1) as f64;
                if drift <= H264_RESIZE_HYSTERESIS && (0.5..=2.0).contains(&rate_drift) {
                    plan.size = size;
                    plan.h264_bitrate_bps = current_bps;
                    // Each run of sustained motion starts with a keyframe: the client's
                    // decoder may have been reset since the last run.
                    plan.h264_restart = controller.motion_frames == H264_AFTER_FRAMES;
                } else {
                    plan.h264_restart = true;
                }
            }
            None => plan.h264_restart = true,
        }
    }
    plan
}

/// The requested size scaled by `scale`, keeping the aspect ratio, never below 8 pixels.
fn scaled_size(width: u32, height: u32, scale: f64) -> (u32, u32) {
    if scale >= 1.0 {
        return (width, height);
    }
    let s = |v: u32| ((v as f64 * scale).round() as u32).clamp(8.min(v), v);
    (s(width), s(height))
}

/// Prepares, traces and encodes one frame. Runs on the render pool.
fn render_frame(
    app: &AppState,
    entry: &SceneEntry,
    settings: &Settings,
    plan: &FramePlan,
    video: VideoState,
    refinement: &crate::refine::Refinement,
) -> Result<Rendered, EncodeError> {
    let state = entry.prepared_at(plan.time, settings.pinned_time.is_none(), plan.seen);
    let view = View {
        width: plan.size.0,
        height: plan.size.1,
        camera: settings.camera,
        isovalue: settings.isovalue,
    };
    let t0 = Instant::now();
    // Effects hook: interactive frames trace one pass of the session's effects; a still frame
    // adds a refinement pass.
    let fb = match plan.quality {
        Quality::Interactive => {
            app.backend()
                .render_effects(&state.prepared, &view, &settings.effects)
                .0
        }
        Quality::Still => {
            let key = (
                settings.version,
                plan.time.to_bits(),
                plan.size.0,
                plan.size.1,
            );
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
    let mut flags = if plan.quality == Quality::Still {
        FLAG_STILL
    } else {
        0
    };
    let (payload, video, keyframe) = encode_image(&fb, plan, video)?;
    if keyframe {
        flags |= FLAG_KEYFRAME;
    }
    let depth = if plan.depth {
        flags |= FLAG_DEPTH;
        Some(encode::depth_block(&fb, &settings.camera, DEPTH_FACTOR)?)
    } else {
        None
    };
    let payload_len = u32::try_from(payload.len())
        .map_err(|_| EncodeError::from_message("frame payload over 4 GiB"))?;
    let header = FrameHeader {
        version: PROTOCOL_VERSION,
        sequence: plan.sequence,
        input_id: settings.last_input_id,
        width: fb.width,
        height: fb.height,
        codec: plan.codec,
        flags,
        quality: if plan.codec == Codec::Jpeg {
            plan.jpeg_quality
        } else {
            0
        },
        payload_len,
        timings: StageTimings {
            update_us: state.update_us,
            build_us: state.build_us,
            trace_us: micros(t1 - t0),
            encode_us: micros(t1.elapsed()),
        },
        // A stored scene's frame shows its step's time, a live demo's the state it shows.
        scene_time: state.step_time.unwrap_or(plan.time),
    };
    m::stage("update", header.timings.update_us);
    m::stage("build", header.timings.build_us);
    m::stage("trace", header.timings.trace_us);
    m::stage("encode", header.timings.encode_us);
    let depth_len = depth.as_ref().map_or(0, Vec::len);
    let mut bytes =
        Vec::with_capacity(isoray_protocol::FRAME_HEADER_LEN + payload.len() + depth_len);
    bytes.extend_from_slice(&header.encode());
    bytes.extend_from_slice(&payload);
    if let Some(depth) = depth {
        metrics::counter!(m::DEPTH_BYTES).increment(depth.len() as u64);
        bytes.extend_from_slice(&depth);
    }
    Ok(Rendered {
        bytes: Bytes::from(bytes),
        codec: plan.codec,
        video,
        state_time: state.step_time,
    })
}

/// The frame's image in the plan's codec: (payload, the H.264 stream to keep, keyframe).
fn encode_image(
    fb: &Framebuffer,
    plan: &FramePlan,
    video: VideoState,
) -> Result<(Vec<u8>, VideoState, bool), EncodeError> {
    match plan.codec {
        Codec::Jpeg => Ok((encode::jpeg(fb, plan.jpeg_quality)?, video, false)),
        Codec::Png => Ok((encode::png(fb)?, video, false)),
        Codec::H264 => encode_h264(fb, plan, video),
    }
}

#[cfg(feature = "h264")]
fn encode_h264(
    fb: &Framebuffer,
    plan: &FramePlan,
    video: VideoState,
) -> Result<(Vec<u8>, VideoState, bool), EncodeError> {
    let mut stream = match video {
        Some(stream) if stream.size() == (fb.width, fb.height) && !plan.h264_restart => stream,
        Some(mut stream)
            if stream.size() == (fb.width, fb.height)
                && stream.bitrate_bps() == plan.h264_bitrate_bps =>
        {
            stream.force_keyframe();
            stream
        }
        _ => encode::H264Stream::new(fb.width, fb.height, plan.h264_bitrate_bps, plan.fps as f32)?,
    };
    let frame = stream.encode(&fb.rgb)?;
    Ok((frame.bytes, Some(stream), frame.keyframe))
}

#[cfg(not(feature = "h264"))]
fn encode_h264(
    _: &Framebuffer,
    _: &FramePlan,
    _: VideoState,
) -> Result<(Vec<u8>, VideoState, bool), EncodeError> {
    Err(EncodeError::from_message("this build has no H.264 encoder"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bandwidth_is_the_slope_of_service_time_over_frame_size() {
        let mut bw = Bandwidth::default();
        let t0 = Instant::now();
        // A 1 MB/s link with 30 ms of latency; frames of 10 to 60 kB, one at a time.
        let mut at = t0;
        for i in 0..10u64 {
            let bytes = 10_000 + (i as usize % 6) * 10_000;
            bw.sent(i + 1, bytes, at);
            at += Duration::from_secs_f64(0.030 + bytes as f64 / 1.0e6);
            bw.acked(i + 1, at);
            at += Duration::from_millis(5);
        }
        let e = bw.estimate().expect("a clear fit");
        assert!((e / 1.0e6 - 1.0).abs() < 0.01, "{e}");

        // A client whose acknowledgements take 40 ms whatever the size: not a bandwidth limit.
        let mut bw = Bandwidth::default();
        let mut at = t0;
        for i in 0..10u64 {
            let bytes = 10_000 + (i as usize % 6) * 10_000;
            bw.sent(i + 1, bytes, at);
            at += Duration::from_millis(40 + (i % 3));
            bw.acked(i + 1, at);
        }
        assert_eq!(bw.estimate(), None);
        // Two seconds later the old samples are gone.
        bw.sent(11, 1_000, at + Duration::from_secs(3));
        bw.acked(11, at + Duration::from_secs(3));
        assert_eq!(bw.samples.len(), 1);
        assert_eq!(bw.fit(), None);
        assert_eq!(bw.in_flight.len(), 0);
    }

    #[test]
    fn controller_lowers_quality_then_scale_when_bandwidth_is_short() {
        let mut c = Controller::new(80, 0.25);
        let cost = JobCost {
            pool_s: 0.001,
            ..JobCost::default()
        };
        // 40 kB frames on a 300 kB/s link at 30 fps: 8 kB per frame allowed.
        for _ in 0..5 {
            c.observe(100_000, cost, 40_000, Codec::Jpeg, Some(300_000.0), 30.0);
        }
        assert_eq!(c.quality, MIN_JPEG_QUALITY);
        c.observe(100_000, cost, 40_000, Codec::Jpeg, Some(300_000.0), 30.0);
        let scale = c.plan_scale((1000, 1000), 30.0, 1);
        assert!(scale < 0.5, "scale follows the byte budget: {scale}");
        // Plenty of bandwidth again: the scale recovers before the quality does.
        for _ in 0..40 {
            c.observe(100_000, cost, 1_000, Codec::Jpeg, Some(1.0e9), 30.0);
        }
        assert_eq!(c.bandwidth_scale, 1.0);
        assert_eq!(c.quality, 80);
    }

    #[test]
    fn controller_scale_fits_the_pools_share_of_the_frame_interval() {
        let mut c = Controller::new(80, 0.01);
        // 1 µs of pool time per pixel; a million-pixel frame at 30 fps alone: 20 ms → 0.14.
        let cost = JobCost {
            pool_s: 0.1,
            ..JobCost::default()
        };
        c.observe(100_000, cost, 1, Codec::Jpeg, None, 30.0);
        let mut alone = 0.0;
        for _ in 0..20 {
            alone = c.plan_scale((1000, 1000), 30.0, 1);
        }
        assert!((alone - 0.1414).abs() < 0.01, "{alone}");
        let mut shared = 0.0;
        for _ in 0..20 {
            shared = c.plan_scale((1000, 1000), 30.0, 4);
        }
        assert!(
            (shared - alone / 2.0).abs() < 0.01,
            "four sessions: half the scale"
        );
    }

    #[test]
    fn codec_follows_the_clients_list_and_sustained_motion() {
        let mut c = Controller::new(80, 0.25);
        let all = StreamSettings::new(&Codec::ALL, 30.0);
        assert_eq!(c.codec(Quality::Still, &all), Codec::Png);
        assert_eq!(c.codec(Quality::Interactive, &all), Codec::Jpeg);
        c.motion_frames = H264_AFTER_FRAMES;
        assert_eq!(c.codec(Quality::Interactive, &all), Codec::H264);
        let images = StreamSettings::new(&[Codec::Jpeg, Codec::Png], 30.0);
        assert_eq!(c.codec(Quality::Interactive, &images), Codec::Jpeg);
        let jpeg_only = StreamSettings::new(&[Codec::Jpeg], 30.0);
        assert_eq!(c.codec(Quality::Still, &jpeg_only), Codec::Jpeg);
    }
}
