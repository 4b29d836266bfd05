//! A client that stops reading costs the server at most one pending frame, and gets the
//! newest state when it reads again. Frames are acknowledged as the browser does; a client
//! that stops reading also stops acknowledging.

use super::support::*;
use isoray_server::session::FRAME_WINDOW;
use serde_json::json;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stalled_reader_holds_one_pending_frame_and_then_sees_the_newest() {
    let server = TestServer::start(&["--max-fps", "30"]).await;
    let (mut ws, _) = server.connect("blobs").await;
    // Large frames fill the socket buffers quickly once the client stops reading.
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 1, "width": 640, "height": 480}),
    )
    .await;
    frame_for_input(&mut ws, 1).await;
    for _ in 0..3 {
        next_frame(&mut ws).await;
    }
    let (_, stats) = server
        .state
        .sessions()
        .snapshot()
        .pop()
        .expect("one session");

    // Stop reading for five seconds while the scene animates.
    let pause = Duration::from_secs(5);
    let rendered_at_pause = stats.frames_rendered.load(Ordering::SeqCst);
    tokio::time::sleep(pause / 2).await;
    let rendered_mid = stats.frames_rendered.load(Ordering::SeqCst);
    tokio::time::sleep(pause / 2).await;
    let rendered_end = stats.frames_rendered.load(Ordering::SeqCst);
    let max_pending = stats.max_pending_frames.load(Ordering::SeqCst);
    println!(
        "frames rendered: {rendered_at_pause} at pause, {rendered_mid} midway, {rendered_end} at the end; \
         max pending {max_pending}"
    );
    assert!(
        max_pending <= 1,
        "the server held {max_pending} pending frames"
    );
    assert!(
        rendered_end <= rendered_at_pause + FRAME_WINDOW,
        "the server kept rendering for a client that does not read"
    );

    // Read again: the frames in flight arrive, then one of the current scene time.
    let resume_time = server.state.scenes().live_time();
    let resumed = Instant::now();
    let mut stale = 0;
    loop {
        let frame = next_frame(&mut ws).await;
        if frame.header.scene_time >= resume_time - 0.1 {
            break;
        }
        stale += 1;
        assert!(
            resumed.elapsed() < Duration::from_secs(5),
            "no fresh frame after resuming"
        );
    }
    println!(
        "{stale} stale frames were in flight; fresh frame after {:?}",
        resumed.elapsed()
    );
    assert!(
        stale as u64 <= FRAME_WINDOW + 1,
        "{stale} stale frames: the server queued frames for the slow client"
    );
    assert!(stats.max_pending_frames.load(Ordering::SeqCst) <= 1);
    drop(ws);
    assert_no_sessions_left(&server).await;
    server.stop().await;
}
