//! Helpers: start a server on 127.0.0.1:0, open a websocket, read frames and messages.

use futures_util::{SinkExt, StreamExt};
use isoray_protocol::{
    Codec, ErrorMessage, FrameHeader, ServerMessage, SessionInfo, FRAME_HEADER_LEN,
};
use isoray_server::{AppState, Config};
use std::net::SocketAddr;
use std::time::Duration;
use tokio::net::TcpStream;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

pub type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// How long any single wait in a test may take before the test fails.
pub const WAIT: Duration = Duration::from_secs(20);

pub struct TestServer {
    pub addr: SocketAddr,
    pub state: AppState,
    shutdown: Option<oneshot::Sender<()>>,
    handle: Option<JoinHandle<std::io::Result<()>>>,
    /// The server's scene store, unless `args` named one: a test never opens the user's own
    /// (`~/.local/share/isoray`, the default), nor another test's.
    _store: Option<tempfile::TempDir>,
}

impl TestServer {
    /// A server with default settings plus `args` (flags as on the command line).
    pub async fn start(args: &[&str]) -> TestServer {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind loopback");
        TestServer::start_on(listener, args)
    }

    /// A server on a listener the test made (for example with small socket buffers, which
    /// accepted connections inherit).
    pub fn start_on(listener: tokio::net::TcpListener, args: &[&str]) -> TestServer {
        let mut argv = vec!["isoray", "--listen", "127.0.0.1:0"];
        argv.extend_from_slice(args);
        let names_store = args
            .iter()
            .any(|a| matches!(*a, "--data-dir" | "--demos-only"));
        let store = (!names_store).then(|| tempfile::tempdir().expect("temp dir"));
        if let Some(dir) = &store {
            argv.extend(["--data-dir", dir.path().to_str().expect("utf-8 temp path")]);
        }
        let config = <Config as clap::Parser>::parse_from(argv);
        let state = AppState::new(config).expect("valid test config");
        let addr = listener.local_addr().expect("local addr");
        let (tx, rx) = oneshot::channel::<()>();
        let handle = tokio::spawn(isoray_server::serve(listener, state.clone(), async move {
            let _ = rx.await;
        }));
        TestServer {
            addr,
            state,
            shutdown: Some(tx),
            handle: Some(handle),
            _store: store,
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("ws://{}{}", self.addr, path)
    }

    /// Opens a stream of `scene` and returns the socket and the server's `info`.
    pub async fn connect(&self, scene: &str) -> (Ws, SessionInfo) {
        let (mut ws, _) =
            tokio_tungstenite::connect_async(self.url(&format!("/api/v1/scenes/{scene}/stream")))
                .await
                .expect("websocket connects");
        let info = match next_text(&mut ws).await {
            ServerMessage::Info(info) => info,
            other => panic!("expected info first, got {other:?}"),
        };
        (ws, info)
    }

    /// Stops the server and waits for it to drain.
    pub async fn stop(mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        if let Some(handle) = self.handle.take() {
            tokio::time::timeout(WAIT, handle)
                .await
                .expect("server drains in time")
                .expect("server task did not panic")
                .expect("server ran without I/O error");
        }
    }
}

pub async fn send_json(ws: &mut Ws, value: serde_json::Value) {
    ws.send(Message::Text(value.to_string().into()))
        .await
        .expect("send");
}

pub async fn send_text(ws: &mut Ws, text: &str) {
    ws.send(Message::Text(text.to_string().into()))
        .await
        .expect("send");
}

/// The next text message, skipping frames.
pub async fn next_text(ws: &mut Ws) -> ServerMessage {
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let msg = tokio::time::timeout_at(deadline, ws.next())
            .await
            .expect("a message within the wait")
            .expect("stream open")
            .expect("no websocket error");
        if let Message::Text(text) = msg {
            return serde_json::from_str(text.as_str()).expect("server text is a ServerMessage");
        }
    }
}

/// The next error message, skipping frames.
pub async fn next_error(ws: &mut Ws) -> ErrorMessage {
    match next_text(ws).await {
        ServerMessage::Error(e) => e,
        other => panic!("expected an error, got {other:?}"),
    }
}

/// A decoded frame.
pub struct Frame {
    pub header: FrameHeader,
    /// The picture; empty (0×0) for H.264 frames, which need the stream's earlier frames
    /// (see `raw`).
    pub image: image::RgbImage,
    /// The whole message, header included.
    pub raw: Vec<u8>,
}

impl Frame {
    /// The image payload and the depth block, as the header splits them.
    pub fn payload(&self) -> (&[u8], Option<&[u8]>) {
        self.header
            .split_payload(&self.raw)
            .expect("payload length fits the message")
    }
}

/// The next binary frame, decoded and acknowledged; text messages in between are skipped.
pub async fn next_frame(ws: &mut Ws) -> Frame {
    let frame = next_frame_unacked(ws).await;
    send_json(
        ws,
        serde_json::json!({"type": "ack", "sequence": frame.header.sequence}),
    )
    .await;
    frame
}

/// The next binary frame, without acknowledging it.
pub async fn next_frame_unacked(ws: &mut Ws) -> Frame {
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let msg = tokio::time::timeout_at(deadline, ws.next())
            .await
            .expect("a frame within the wait")
            .expect("stream open")
            .expect("no websocket error");
        if let Message::Binary(bytes) = msg {
            return decode_frame(&bytes);
        }
    }
}

pub fn decode_frame(bytes: &[u8]) -> Frame {
    let header = FrameHeader::decode(bytes).expect("valid frame header");
    let (payload, _) = header.split_payload(bytes).expect("payload length fits");
    assert!(
        bytes.len() > FRAME_HEADER_LEN,
        "a frame has a payload after its header"
    );
    let image = match header.codec {
        Codec::H264 => image::RgbImage::new(0, 0),
        Codec::Jpeg | Codec::Png => image::load_from_memory(payload)
            .expect("payload decodes")
            .to_rgb8(),
    };
    Frame {
        header,
        image,
        raw: bytes.to_vec(),
    }
}

/// Reads frames until one answers `input_id` (or a later input).
pub async fn frame_for_input(ws: &mut Ws, input_id: u64) -> Frame {
    loop {
        let frame = next_frame(ws).await;
        if frame.header.input_id >= input_id {
            return frame;
        }
    }
}

/// Waits until the server has `n` open sessions.
pub async fn wait_for_sessions(server: &TestServer, n: usize, within: Duration) {
    let start = std::time::Instant::now();
    while server.state.sessions().count() != n {
        assert!(
            start.elapsed() < within,
            "expected {n} sessions within {within:?}, have {}",
            server.state.sessions().count()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Asserts that no session is left anywhere: not in the session table, and not in the render
/// scheduler (no share kept, no job waiting). Call once every client is gone.
pub async fn assert_no_sessions_left(server: &TestServer) {
    wait_for_sessions(server, 0, WAIT).await;
    let start = std::time::Instant::now();
    while server.state.scheduler().tracked() != (0, 0) {
        assert!(
            start.elapsed() < WAIT,
            "the scheduler still tracks {:?} (sessions, waiting jobs)",
            server.state.scheduler().tracked()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Mean absolute difference per channel, 0–255.
pub fn mean_abs_diff(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let sum: u64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| x.abs_diff(*y) as u64)
        .sum();
    sum as f64 / a.as_raw().len() as f64
}

/// Standard deviation of the luma-ish channel sum, to tell a picture from a flat fill.
pub fn pixel_stddev(img: &image::RgbImage) -> f64 {
    let values: Vec<f64> = img
        .pixels()
        .map(|p| p.0.iter().map(|&c| c as f64).sum::<f64>() / 3.0)
        .collect();
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt()
}
