//! A session's websocket: admission and refusal, the reader, the writer and the heartbeat,
//! run together with the renderer (`session::render`) until one ends.

use crate::encode;
use crate::input::{self, Limits, Settings, StreamSettings};
use crate::metrics as m;
use crate::scenes::entry::SceneEntry;
use crate::session::bandwidth::Bandwidth;
use crate::session::flow::{FrameSlot, Shared, FRAME_WINDOW};
use crate::session::render::render_loop;
use crate::session::stats::SessionStats;
use crate::state::{AppState, SessionTicket};
use axum::body::Bytes;
use axum::extract::ws::{CloseFrame, Message, WebSocket};
use futures_util::{SinkExt, StreamExt};
use isoray_protocol::{
    ClientMessage, ErrorMessage, FrameAck, ServerMessage, SessionInfo, PROTOCOL_VERSION,
};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, Notify};
use tracing::Instrument;

/// Error messages queued for a client that is not reading; more are dropped.
const CONTROL_QUEUE: usize = 16;

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
        style: Default::default(),
        stream: StreamSettings::initial(config.max_fps),
    };
    let limits = Limits {
        max_size: config.max_size,
        isovalue_range: entry.isovalue_range(),
        isovalue_slider: demo.isovalue_slider(),
        scalar_field: entry.kind().has_field(),
        scene_surfaces: entry.lighting().isosurfaces.len(),
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
        scalar_field: limits.scalar_field,
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
        Ok(End::TooLarge(reason)) => {
            let _ = sink
                .send(Message::Close(Some(CloseFrame {
                    code: 1009,
                    reason: reason.clone().into(),
                })))
                .await;
            tracing::info!(frames, %reason, "session closed: message too large");
        }
        Err(e) => tracing::info!(frames, error = %e, "session ended by a connection error"),
    }
}

/// `Some(reason)` when `error` is a client message over the size limit (the connection is
/// still good for a close frame); `None` for a broken connection.
fn too_large(error: axum::Error) -> Result<String, axum::Error> {
    let inner = error.into_inner();
    match inner.downcast_ref::<tungstenite::Error>() {
        Some(tungstenite::Error::Capacity(tungstenite::error::CapacityError::MessageTooLong {
            size,
            max_size,
        })) => Ok(format!(
            "message of {size} bytes exceeds the limit of {max_size} bytes"
        )),
        _ => Err(axum::Error::new(inner)),
    }
}

/// Why a session ended.
enum End {
    /// The client closed the socket or it went away.
    ClientGone,
    /// Nothing arrived from the client (not even a pong) for the idle timeout.
    Idle,
    /// The client sent a message over the size limit (the reason says how large).
    TooLarge(String),
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
        let message = match message {
            Ok(message) => message,
            Err(e) => return too_large(e).map(End::TooLarge),
        };
        let result = match message {
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
