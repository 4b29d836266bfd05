//! Connection life: the session limit, clients that vanish or never answer, and shutdown
//! while streaming. After each, the session count returns to zero (no leaked task).

use super::support::*;
use futures_util::StreamExt;
use serde_json::json;
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;

/// Reads until the close frame and returns its code and reason.
async fn close_reason(ws: &mut Ws) -> (u16, String) {
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        match tokio::time::timeout_at(deadline, ws.next())
            .await
            .expect("close within the wait")
        {
            Some(Ok(Message::Close(Some(frame)))) => {
                return (frame.code.into(), frame.reason.to_string())
            }
            Some(Ok(_)) => continue,
            other => panic!("expected a close frame, got {other:?}"),
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_beyond_the_limit_get_a_clear_refusal() {
    let server = TestServer::start(&["--max-sessions", "2"]).await;
    let (a, _) = server.connect("blobs").await;
    let (_b, _) = server.connect("blobs").await;
    let (mut refused, _) =
        tokio_tungstenite::connect_async(server.url("/api/v1/scenes/blobs/stream"))
            .await
            .expect("the upgrade itself succeeds");
    let error = next_error(&mut refused).await;
    assert_eq!(error.code, "server_full");
    assert!(
        error.message.contains("limit of 2 sessions"),
        "{}",
        error.message
    );
    assert_eq!(
        close_reason(&mut refused).await,
        (1013, "server full".to_string())
    );
    assert_eq!(server.state.sessions().count(), 2);

    drop(a);
    wait_for_sessions(&server, 1, WAIT).await;
    let (c, info) = server.connect("blobs").await;
    assert_eq!(
        info.scene.id, "blobs",
        "a place freed by a leaving client is given to the next"
    );
    drop((c, _b, refused));
    assert_no_sessions_left(&server).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_that_vanish_or_never_answer_are_dropped() {
    let server =
        TestServer::start(&["--ping-interval-secs", "1", "--idle-timeout-secs", "2"]).await;

    // Vanishes without a websocket close: the TCP connection just ends.
    let (mut gone, _) = server.connect("blobs").await;
    send_json(
        &mut gone,
        json!({"type": "resize", "input_id": 1, "width": 64, "height": 64}),
    )
    .await;
    frame_for_input(&mut gone, 1).await;
    drop(gone);
    wait_for_sessions(&server, 0, WAIT).await;

    // Never reads, never acknowledges, never answers a ping: silent, like a dead peer. The
    // live scene animates meanwhile, but without acknowledgements the server renders no more
    // than its window of frames, and holds at most one of them.
    let (silent, _) = server.connect("blobs").await;
    let opened = Instant::now();
    let (_, stats) = server
        .state
        .sessions()
        .snapshot()
        .pop()
        .expect("the silent session");
    wait_for_sessions(&server, 0, Duration::from_secs(10)).await;
    let rendered = stats
        .frames_rendered
        .load(std::sync::atomic::Ordering::SeqCst);
    let pending = stats
        .max_pending_frames
        .load(std::sync::atomic::Ordering::SeqCst);
    println!("silent client: {rendered} frames rendered, at most {pending} pending");
    assert!(
        rendered <= isoray_server::session::FRAME_WINDOW + 1,
        "{rendered} frames rendered for a client that never read"
    );
    assert!(
        pending <= 1,
        "{pending} frames held for a client that never read"
    );
    let after = opened.elapsed();
    assert!(
        after >= Duration::from_millis(1900),
        "closed too early ({after:?})"
    );
    println!("silent client dropped after {after:?}");
    drop(silent);

    // A reading client answers pings by itself and stays well past the idle timeout.
    let (mut alive, _) = server.connect("blobs").await;
    let until = Instant::now() + Duration::from_secs(4);
    while Instant::now() < until {
        let _ = tokio::time::timeout(Duration::from_millis(200), alive.next()).await;
    }
    assert_eq!(
        server.state.sessions().count(),
        1,
        "a responsive client is not idle"
    );
    drop(alive);
    assert_no_sessions_left(&server).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_while_streaming_closes_every_session_with_a_reason() {
    let server = TestServer::start(&[]).await;
    let mut clients = Vec::new();
    for _ in 0..3 {
        let (mut ws, _) = server.connect("blobs").await;
        send_json(
            &mut ws,
            json!({"type": "resize", "input_id": 1, "width": 64, "height": 48}),
        )
        .await;
        frame_for_input(&mut ws, 1).await;
        clients.push(ws);
    }
    let state = server.state.clone();
    let stopping = tokio::spawn(server.stop());
    for ws in &mut clients {
        assert_eq!(
            close_reason(ws).await,
            (1001, "server shutting down".to_string())
        );
    }
    tokio::time::timeout(WAIT, stopping)
        .await
        .expect("drains")
        .expect("no panic");
    assert_eq!(state.sessions().count(), 0);
    assert_eq!(state.scheduler().tracked(), (0, 0), "no share or job left");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_test_server_keeps_its_scenes_out_of_the_users_store() {
    // The servers these tests start take a store of their own (the default would be the
    // user's `~/.local/share/isoray`, where a pushed scene would outlive the test); a test
    // that names one keeps it.
    let server = TestServer::start(&[]).await;
    let dir = server.state.config().data_dir.clone().expect("a store");
    assert!(dir.starts_with(std::env::temp_dir()), "{}", dir.display());
    assert_ne!(Some(dir), isoray_server::config::default_data_dir());
    server.stop().await;
    let named = tempfile::tempdir().expect("temp dir");
    let path = named.path().to_str().expect("utf-8 temp path");
    let server = TestServer::start(&["--data-dir", path]).await;
    assert_eq!(
        server.state.config().data_dir.as_deref(),
        Some(named.path())
    );
    server.stop().await;
}
