//! Faults at the socket: a client that drops its TCP connection while a large frame is being
//! written to it, a websocket message over the server's limit, and a client that floods
//! inputs without reading. None takes down anything but that session: no panic in the
//! server, the session count returns to zero, and another client keeps streaming.

use super::support::*;
use futures_util::{SinkExt, StreamExt};
use serde_json::json;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;

/// Panics raised in server code or its dependencies (not in tests), counted by a hook that
/// chains to the default one. No passing test raises one.
fn server_panics() -> &'static AtomicU64 {
    static COUNT: OnceLock<Arc<AtomicU64>> = OnceLock::new();
    COUNT.get_or_init(|| {
        let count = Arc::new(AtomicU64::new(0));
        let seen = count.clone();
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if info
                .location()
                .is_some_and(|l| l.file().contains("server/src") || l.file().contains(".cargo"))
            {
                seen.fetch_add(1, Ordering::SeqCst);
            }
            previous(info);
        }));
        count
    })
}

/// A websocket opened by hand over a socket with a small receive buffer, so that a large
/// frame cannot fit in the kernel's buffers and the server's write of it stays unfinished.
struct RawWs {
    stream: TcpStream,
}

impl RawWs {
    async fn open(server: &TestServer, path: &str) -> RawWs {
        let socket = tokio::net::TcpSocket::new_v4().expect("socket");
        socket.set_recv_buffer_size(4096).expect("SO_RCVBUF");
        let mut stream = socket.connect(server.addr).await.expect("connect");
        let request = format!(
            "GET {path} HTTP/1.1\r\nHost: {}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
             Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
            server.addr
        );
        stream
            .write_all(request.as_bytes())
            .await
            .expect("upgrade request");
        // Byte by byte up to the blank line, so no websocket byte is read with the head.
        let mut head = Vec::new();
        while !head.ends_with(b"\r\n\r\n") {
            head.push(stream.read_u8().await.expect("upgrade answer"));
        }
        let head = String::from_utf8_lossy(&head);
        assert!(head.starts_with("HTTP/1.1 101"), "{head}");
        RawWs { stream }
    }

    /// A server frame's opcode and payload length (server frames are not masked).
    async fn frame_header(&mut self) -> (u8, u64) {
        let b0 = self.stream.read_u8().await.expect("frame byte 0");
        let b1 = self.stream.read_u8().await.expect("frame byte 1");
        assert_eq!(b1 & 0x80, 0, "server frames are unmasked");
        let len = match b1 & 0x7f {
            126 => u64::from(self.stream.read_u16().await.expect("length")),
            127 => self.stream.read_u64().await.expect("length"),
            n => u64::from(n),
        };
        (b0 & 0x0f, len)
    }

    /// Sends a masked text frame, as a client must.
    async fn send_text(&mut self, text: &str) {
        let payload = text.as_bytes();
        assert!(payload.len() < 126);
        let mask = [0x12u8, 0x34, 0x56, 0x78];
        let mut frame = vec![0x81, 0x80 | payload.len() as u8];
        frame.extend_from_slice(&mask);
        frame.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
        self.stream.write_all(&frame).await.expect("send");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_drops_tcp_mid_frame_costs_only_its_session() {
    let panics = server_panics().load(Ordering::SeqCst);
    // A small send buffer (accepted sockets inherit it, and it stops the kernel growing it):
    // a frame of hundreds of KB cannot leave the server's hands at once.
    let socket = tokio::net::TcpSocket::new_v4().expect("socket");
    socket.set_send_buffer_size(16 * 1024).expect("SO_SNDBUF");
    socket
        .bind("127.0.0.1:0".parse().expect("addr"))
        .expect("bind");
    let server = TestServer::start_on(socket.listen(64).expect("listen"), &["--max-size", "2048"]);
    let (mut other, _) = server.connect("blobs").await;
    send_json(
        &mut other,
        json!({"type": "resize", "input_id": 1, "width": 48, "height": 32}),
    )
    .await;
    frame_for_input(&mut other, 1).await;

    let mut raw = RawWs::open(&server, "/api/v1/scenes/blobs/stream").await;
    let (opcode, len) = raw.frame_header().await;
    assert_eq!(opcode, 1, "info first");
    let mut info = vec![0u8; len as usize];
    raw.stream.read_exact(&mut info).await.expect("info");
    // A still scene: after the resize, a full-size lossless PNG still frame follows (1600×1200,
    // about 200 KB: far more than the socket buffers hold).
    raw.send_text(r#"{"type":"time","input_id":1,"time":1.0}"#)
        .await;
    raw.send_text(r#"{"type":"resize","input_id":2,"width":1600,"height":1200}"#)
        .await;
    let (_, stats) = server
        .state
        .sessions()
        .snapshot()
        .into_iter()
        .max_by_key(|(id, _)| *id)
        .expect("the raw session");
    // Read and acknowledge smaller frames until a large one starts; read a little of it.
    let mut whole_frames = 0;
    let len = tokio::time::timeout(WAIT, async {
        loop {
            let (opcode, len) = raw.frame_header().await;
            if opcode == 2 && len > 1 << 17 {
                return len;
            }
            let mut payload = vec![0u8; len as usize];
            raw.stream.read_exact(&mut payload).await.expect("payload");
            if opcode == 2 {
                whole_frames += 1;
                let sequence = decode_frame(&payload).header.sequence;
                raw.send_text(&format!(r#"{{"type":"ack","sequence":{sequence}}}"#))
                    .await;
            }
        }
    })
    .await
    .expect("a frame over 128 KiB");
    let mut part = vec![0u8; 16 * 1024];
    raw.stream
        .read_exact(&mut part)
        .await
        .expect("part of the frame");
    println!("dropping the connection after 16 KiB of a {len}-byte frame");
    // RST, not FIN: the connection is gone at once, as when a machine drops off the network.
    // (Deprecated because a linger time blocks the dropping thread; a zero one does not.)
    #[allow(deprecated)]
    raw.stream
        .set_linger(Some(std::time::Duration::ZERO))
        .expect("linger 0");
    drop(raw);
    wait_for_sessions(&server, 1, WAIT).await;
    assert_eq!(
        stats.frames_sent.load(Ordering::SeqCst),
        whole_frames,
        "the server's write of the large frame never finished: the drop came mid-frame"
    );

    // The other client still streams.
    send_json(
        &mut other,
        json!({"type": "isovalue", "input_id": 2, "value": 0.55}),
    )
    .await;
    frame_for_input(&mut other, 2).await;
    drop(other);
    assert_no_sessions_left(&server).await;
    server.stop().await;
    assert_eq!(
        server_panics().load(Ordering::SeqCst),
        panics,
        "a panic in server code"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_oversized_message_closes_its_session_with_a_reason() {
    let panics = server_panics().load(Ordering::SeqCst);
    let server = TestServer::start(&[]).await;
    let (mut other, _) = server.connect("blobs").await;
    let (mut big, _) = server.connect("blobs").await;
    // Valid JSON, 64 KiB + 1 bytes: over the limit by one byte.
    let limit = 64 * 1024;
    let prefix = r#"{"type":"isovalue","input_id":1,"value":0.5,"pad":""#;
    let text = format!("{prefix}{}\"}}", "x".repeat(limit + 1 - prefix.len() - 2));
    assert_eq!(text.len(), limit + 1);
    big.send(Message::Text(text.into())).await.expect("send");
    let deadline = tokio::time::Instant::now() + WAIT;
    let close = loop {
        match tokio::time::timeout_at(deadline, big.next())
            .await
            .expect("the server closes the session")
        {
            Some(Ok(Message::Close(frame))) => break frame,
            Some(Ok(_)) => continue,
            other => panic!("a close frame with a reason, got {other:?}"),
        }
    };
    let close = close.expect("a close frame with a code");
    assert_eq!(u16::from(close.code), 1009, "1009: message too big");
    assert!(
        close.reason.contains("65537") && close.reason.contains("65536"),
        "the reason names the size and the limit: {:?}",
        close.reason
    );
    wait_for_sessions(&server, 1, WAIT).await;
    // One byte less is read (and refused as an unknown field, not as too large).
    let (mut at_limit, _) = server.connect("blobs").await;
    let text = format!("{prefix}{}\"}}", "x".repeat(limit - prefix.len() - 2));
    at_limit
        .send(Message::Text(text.into()))
        .await
        .expect("send");
    let error = next_error(&mut at_limit).await;
    assert_eq!(error.code, "invalid_message", "{error:?}");
    send_json(
        &mut other,
        json!({"type": "isovalue", "input_id": 5, "value": 0.55}),
    )
    .await;
    frame_for_input(&mut other, 5).await;
    drop((other, at_limit, big));
    assert_no_sessions_left(&server).await;
    server.stop().await;
    assert_eq!(server_panics().load(Ordering::SeqCst), panics);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_flooding_inputs_without_reading_holds_bounded_state() {
    const VALID: u64 = 20_000;
    const INVALID: u64 = 2_000;
    let server = TestServer::start(&[]).await;
    let (mut flood, _) = server.connect("blobs").await;
    let (_, stats) = server
        .state
        .sessions()
        .snapshot()
        .pop()
        .expect("the flooding session");
    let flooding = tokio::spawn(async move {
        for i in 0..VALID + INVALID {
            let text = if i % 11 == 10 {
                json!({"type": "isovalue", "input_id": i + 1, "value": "high"}).to_string()
            } else if i % 2 == 0 {
                json!({"type": "isovalue", "input_id": i + 1, "value": 0.4 + (i % 100) as f64 * 1e-3})
                    .to_string()
            } else {
                let a = i as f64 * 0.01;
                json!({"type": "camera", "input_id": i + 1, "eye": [3.0 * a.cos(), 1.0, 3.0 * a.sin()],
                       "target": [0, 0, 0], "up": [0, 1, 0]})
                .to_string()
            };
            flood.send(Message::Text(text.into())).await.expect("send");
        }
        flood
    });
    // Another client is served while the flood goes on.
    let (mut other, _) = server.connect("blobs").await;
    send_json(
        &mut other,
        json!({"type": "resize", "input_id": 1, "width": 48, "height": 32}),
    )
    .await;
    frame_for_input(&mut other, 1).await;
    let flood = tokio::time::timeout(WAIT * 3, flooding)
        .await
        .expect("the server reads the flood")
        .expect("no panic");
    // Every message was read and applied or refused: the server never stopped reading.
    let start = std::time::Instant::now();
    let total = VALID + INVALID;
    let invalid = (0..total).filter(|i| i % 11 == 10).count() as u64;
    loop {
        let applied = stats.inputs_applied.load(Ordering::SeqCst);
        let rejected = stats.inputs_rejected.load(Ordering::SeqCst);
        if applied + rejected == total {
            assert_eq!(rejected, invalid);
            break;
        }
        assert!(
            start.elapsed() < WAIT,
            "{applied} + {rejected} of {total} inputs read"
        );
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    // The session renders (the bound below is not met by rendering nothing)...
    while stats.frames_rendered.load(Ordering::SeqCst) == 0 {
        assert!(
            start.elapsed() < WAIT,
            "the flooding session rendered no frame"
        );
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    // ...and the live scene animates for another second of scene time, which would be about
    // 30 more frames if the window did not hold them back...
    let until = server.state.scenes().live_time() + 1.0;
    while server.state.scenes().live_time() < until {
        assert!(start.elapsed() < WAIT * 2, "the live scene's time advances");
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    // ...but without acknowledgements, at most a window of frames for 22,000 inputs,
    // and at most one held: inputs replace the settings, nothing queues per input.
    let rendered = stats.frames_rendered.load(Ordering::SeqCst);
    let pending = stats.max_pending_frames.load(Ordering::SeqCst);
    println!("flood of {total} inputs: {rendered} frames rendered, at most {pending} pending");
    assert!(
        rendered <= isoray_server::session::FRAME_WINDOW + 1,
        "{rendered} frames rendered"
    );
    assert!(pending <= 1, "{pending} frames held");
    send_json(
        &mut other,
        json!({"type": "isovalue", "input_id": 2, "value": 0.55}),
    )
    .await;
    frame_for_input(&mut other, 2).await;
    drop((flood, other));
    assert_no_sessions_left(&server).await;
    server.stop().await;
}
