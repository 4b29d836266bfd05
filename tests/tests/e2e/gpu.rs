//! The server streaming a demo scene with `--backend gpu` (lavapipe in CI: Mesa's software
//! Vulkan driver, which `.ci/run` installs). The GPU must really start and really trace the
//! frames: a server that fell back to the CPU fails the test.

use super::support::*;
use isoray_render::backend::dispatch::Backend;
use serde_json::json;

/// Frames the GPU and the CPU traced so far; panics unless the server runs the GPU backend.
fn gpu_frames(server: &TestServer) -> (u64, u64) {
    match server.state.backend() {
        Backend::Gpu(gpu) => gpu.frames(),
        Backend::Cpu(_) => panic!("--backend gpu started the CPU backend (no Vulkan device?)"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_streams_a_demo_traced_on_the_gpu() {
    let server = TestServer::start(&["--backend", "gpu", "--min-scale", "1"]).await;
    assert_eq!(server.state.backend().name(), "gpu");
    let (mut ws, info) = server.connect("blobs").await;
    assert_eq!(info.scene.kind, "metaballs");
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 2.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 160, "height": 120}),
    )
    .await;
    let a = frame_for_input(&mut ws, 2).await;
    assert_eq!(a.image.dimensions(), (160, 120));
    let stddev = pixel_stddev(&a.image);
    assert!(
        stddev > 10.0,
        "the frame shows the blobs (stddev {stddev:.1})"
    );
    send_json(
        &mut ws,
        json!({"type": "isovalue", "input_id": 3, "value": 0.9}),
    )
    .await;
    let b = frame_for_input(&mut ws, 3).await;
    assert!(
        mean_abs_diff(&a.image, &b.image) > 1.0,
        "a new isovalue changes the picture"
    );
    let (on_gpu, _) = gpu_frames(&server);
    assert!(on_gpu >= 2, "the GPU traced the streamed frames ({on_gpu})");
    drop(ws);
    server.stop().await;
}
