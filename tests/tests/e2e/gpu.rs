//! The server streaming a demo scene with `--backend gpu` (lavapipe in CI: Mesa's software
//! Vulkan driver, which `.ci/run` installs). The GPU must really start and really trace the
//! frames: a server that fell back to the CPU fails the test.

use super::metrics::sample;
use super::stream::reqwest_like_get;
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
    // The device's stages are reported: in the header's fields (upload within the build,
    // readback within the encoding) and in /metrics, by stage.
    for f in [&a, &b] {
        let t = f.header.timings;
        assert!(t.trace_us > 0 && t.encode_us > 0, "{t:?}");
    }
    let text = reqwest_like_get(server.addr, "/metrics").await;
    let frames = sample(&text, "isoray_frames_traced_total", &["on=\"gpu\""]);
    assert!(frames >= Some(2.0), "GPU frames counted: {frames:?}");
    for stage in ["upload", "trace", "readback"] {
        let label = format!("stage=\"{stage}\"");
        let n = sample(&text, "isoray_gpu_stage_seconds_count", &[label.as_str()]);
        assert!(n >= Some(2.0), "GPU {stage} times recorded: {n:?}\n{text}");
    }
    drop(ws);
    server.stop().await;
}

/// Issue 12, Must show 2: the device is lost in the middle of a stream (destroyed, as a
/// driver reset or a removed GPU would leave it); the session keeps receiving frames, now
/// traced on the CPU, and the backend never goes back to the dead device.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_device_lost_mid_stream_leaves_the_session_streaming_from_the_cpu() {
    let server = TestServer::start(&["--backend", "gpu", "--min-scale", "1"]).await;
    let (mut ws, _) = server.connect("blobs").await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 1, "width": 160, "height": 120}),
    )
    .await;
    let before = frame_for_input(&mut ws, 1).await;
    let (on_gpu, _) = gpu_frames(&server);
    assert!(on_gpu >= 1, "the stream starts on the GPU ({on_gpu})");
    match server.state.backend() {
        Backend::Gpu(gpu) => gpu.lose_device(),
        Backend::Cpu(_) => panic!("--backend gpu started the CPU backend"),
    }
    let (gpu_at_loss, cpu_at_loss) = gpu_frames(&server);
    for (k, value) in [0.7, 0.9, 1.1].into_iter().enumerate() {
        let id = 2 + k as u64;
        send_json(
            &mut ws,
            json!({"type": "isovalue", "input_id": id, "value": value}),
        )
        .await;
        let frame = frame_for_input(&mut ws, id).await;
        assert_eq!(frame.image.dimensions(), (160, 120));
        assert!(
            pixel_stddev(&frame.image) > 10.0,
            "frame {id} after the loss shows the blobs"
        );
        assert!(
            mean_abs_diff(&before.image, &frame.image) > 0.5,
            "frame {id} is a new picture (isovalue {value})"
        );
    }
    let (gpu_after, cpu_after) = gpu_frames(&server);
    match server.state.backend() {
        Backend::Gpu(gpu) => assert!(gpu.has_failed(), "the backend noticed the lost device"),
        Backend::Cpu(_) => unreachable!(),
    }
    assert!(
        gpu_after <= gpu_at_loss,
        "no frame traced on the lost device ({gpu_at_loss} -> {gpu_after})"
    );
    assert!(
        cpu_after >= cpu_at_loss + 3,
        "the CPU traced the frames after the loss ({cpu_at_loss} -> {cpu_after})"
    );
    drop(ws);
    server.stop().await;
}
