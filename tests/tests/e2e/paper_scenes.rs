//! Every scene of the Fitted BVH paper's Table 1 streams live: its ball count is announced,
//! frames keep coming with the scene time moving forward, and their headers carry the time it
//! took to build each state's acceleration structure and to trace the frame.

use super::support::*;
use isoray_render::scenes::DemoScene;
use serde_json::json;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_paper_scene_streams_animated_with_build_and_trace_timings() {
    // Full-size frames only, so every frame has the size asked for.
    let server = TestServer::start(&["--min-scale", "1"]).await;
    for demo in DemoScene::PAPER {
        let (mut ws, info) = server.connect(demo.id()).await;
        assert_eq!(info.scene.primitives, demo.ball_count() as u64);
        assert!(info.scene.animated);
        send_json(
            &mut ws,
            json!({"type": "resize", "input_id": 1, "width": 32, "height": 24}),
        )
        .await;
        let mut frames = vec![frame_for_input(&mut ws, 1).await];
        // Three states in a row, each newer than the last.
        while frames.len() < 3 {
            let frame = next_frame(&mut ws).await;
            let last = frames
                .last()
                .map_or(f64::NEG_INFINITY, |f| f.header.scene_time);
            if frame.header.scene_time > last {
                frames.push(frame);
            }
        }
        for f in &frames {
            assert_eq!(f.image.dimensions(), (32, 24), "{}", demo.id());
            assert!(f.header.timings.trace_us > 0, "{}: trace time", demo.id());
        }
        // Each state is built once and its first frame reports the build (later frames of the
        // same state, and other viewers of it, report zero).
        assert!(
            frames.iter().all(|f| f.header.timings.build_us > 0),
            "{}: build times {:?}",
            demo.id(),
            frames
                .iter()
                .map(|f| f.header.timings.build_us)
                .collect::<Vec<_>>()
        );
        drop(ws);
    }
    server.stop().await;
}
