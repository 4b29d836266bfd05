//! Progressive refinement over a real socket: a resting view with soft shadows gets a run of
//! lossless frames, each one more accumulated pass, until the engine says it converged; then
//! the session renders nothing at all until something changes, and a change starts over.

use super::support::*;
use isoray_protocol::FLAG_STILL;
use serde_json::json;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Reads (and acknowledges) frames until none arrives for `quiet`; returns how many came.
async fn frames_until_quiet(ws: &mut Ws, quiet: Duration) -> Vec<Frame> {
    let mut frames = Vec::new();
    while let Ok(frame) = tokio::time::timeout(quiet, next_frame(ws)).await {
        frames.push(frame);
    }
    frames
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refinement_accumulates_then_stops_rendering_until_something_changes() {
    let server = TestServer::start(&["--still-after-ms", "50", "--max-refine-passes", "6"]).await;
    let (mut ws, info) = server.connect("glass").await;
    assert!(
        info.effects.available.iter().any(|e| e == "soft_shadows"),
        "the glass scene has an area light: {:?}",
        info.effects.available
    );
    assert_eq!(info.effects.max_passes, 6);
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 2.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 48, "height": 36}),
    )
    .await;
    // Soft shadows only: reflections and refraction off keep the debug build quick.
    send_json(
        &mut ws,
        json!({"type": "effects", "input_id": 3, "effects": {
            "shadows": true, "soft_shadows": true, "reflections": false,
            "refraction": false, "transparency": false, "light_samples": 2}}),
    )
    .await;
    frame_for_input(&mut ws, 3).await;
    let frames = frames_until_quiet(&mut ws, Duration::from_millis(1500)).await;
    let stills: Vec<_> = frames
        .iter()
        .filter(|f| f.header.flags & FLAG_STILL != 0)
        .collect();
    assert!(
        (2..=6).contains(&stills.len()),
        "one still frame per refinement pass, up to --max-refine-passes: {}",
        stills.len()
    );
    assert!(
        stills.windows(2).any(|w| w[0].image != w[1].image),
        "successive passes refine the image"
    );

    // Converged: nothing is rendered while nothing changes.
    let (_, stats) = server
        .state
        .sessions()
        .snapshot()
        .pop()
        .expect("one session");
    let rendered = stats.frames_rendered.load(Ordering::SeqCst);
    tokio::time::sleep(Duration::from_millis(1500)).await;
    assert_eq!(
        stats.frames_rendered.load(Ordering::SeqCst),
        rendered,
        "the session rendered although nothing changed"
    );

    // Any change starts the accumulation over.
    send_json(
        &mut ws,
        json!({"type": "effects", "input_id": 4, "effects": {"light_samples": 3}}),
    )
    .await;
    frame_for_input(&mut ws, 4).await;
    let again = frames_until_quiet(&mut ws, Duration::from_millis(1500)).await;
    let stills = again
        .iter()
        .filter(|f| f.header.flags & FLAG_STILL != 0)
        .count();
    assert!(
        (2..=6).contains(&stills),
        "a change restarts refinement: {stills}"
    );
    drop(ws);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn effects_input_is_validated_and_unusable_effects_are_accepted() {
    let server = TestServer::start(&["--max-ray-depth", "4"]).await;
    let (mut ws, info) = server.connect("blobs").await;
    assert_eq!(info.effects.max_depth, 4);
    assert!(!info.effects.available.iter().any(|e| e == "reflections"));
    send_json(
        &mut ws,
        json!({"type": "effects", "input_id": 5, "effects": {"depth": 5}}),
    )
    .await;
    let e = next_error(&mut ws).await;
    assert_eq!(e.code, "invalid_value");
    assert!(e.message.contains("depth"), "{}", e.message);
    send_json(
        &mut ws,
        json!({"type": "effects", "input_id": 6, "effects": {"mirror": true}}),
    )
    .await;
    let e = next_error(&mut ws).await;
    assert_eq!(e.code, "invalid_message");
    assert!(e.message.contains("mirror"), "{}", e.message);
    send_json(
        &mut ws,
        json!({"type": "effects", "input_id": 7, "effects": {"reflections": true, "depth": 4}}),
    )
    .await;
    let frame = frame_for_input(&mut ws, 7).await;
    assert_eq!(frame.header.input_id, 7);
    drop(ws);
    server.stop().await;
}
