//! The walking skeleton: inputs go in, frames that answer them come out.

use super::support::*;
use serde_json::json;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn camera_and_isovalue_produce_answering_frames() {
    // Adaptive resolution off: every frame has exactly the requested size.
    let server = TestServer::start(&["--min-scale", "1"]).await;
    let (mut ws, info) = server.connect("blobs").await;
    assert_eq!(info.protocol_version, 1);
    assert_eq!(info.scene.kind, "metaballs");

    // Pin the scene time so that only our inputs change the picture.
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 2.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 200, "height": 150}),
    )
    .await;
    send_json(
        &mut ws,
        json!({"type": "camera", "input_id": 3, "eye": [0.5, 2.0, 7.0], "target": [0, 0, 0], "up": [0, 1, 0]}),
    )
    .await;
    send_json(
        &mut ws,
        json!({"type": "isovalue", "input_id": 4, "value": 0.5}),
    )
    .await;

    let a = frame_for_input(&mut ws, 4).await;
    assert_eq!(
        a.header.input_id, 4,
        "the header echoes the last applied input"
    );
    assert_eq!(
        a.image.dimensions(),
        (200, 150),
        "the JPEG has the requested size"
    );
    assert_eq!((a.header.width, a.header.height), (200, 150));
    assert_eq!(a.header.scene_time, 2.0);
    assert!(a.header.timings.trace_us > 0, "trace time is reported");
    let stddev = pixel_stddev(&a.image);
    assert!(
        stddev > 10.0,
        "the frame shows something, not a flat fill (stddev {stddev:.1})"
    );

    send_json(
        &mut ws,
        json!({"type": "isovalue", "input_id": 5, "value": 0.9}),
    )
    .await;
    let b = frame_for_input(&mut ws, 5).await;
    let diff = mean_abs_diff(&a.image, &b.image);
    // JPEG noise between identical renders is zero (same encoder, same pixels); a different
    // isovalue moves every silhouette, which shows as several grey levels on average.
    assert!(
        diff > 2.0,
        "a second isovalue changes the image (mean abs diff {diff:.2})"
    );

    // Re-sending the first isovalue reproduces the first image exactly: the engine is deterministic.
    send_json(
        &mut ws,
        json!({"type": "isovalue", "input_id": 6, "value": 0.5}),
    )
    .await;
    let c = frame_for_input(&mut ws, 6).await;
    assert_eq!(mean_abs_diff(&a.image, &c.image), 0.0);

    drop(ws);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_scene_animates_and_scene_list_is_served() {
    let server = TestServer::start(&[]).await;
    let body = reqwest_like_get(server.addr, "/api/v1/scenes").await;
    let list: isoray_protocol::SceneList = serde_json::from_str(&body).expect("scene list JSON");
    assert!(list.scenes.iter().any(|s| s.id == "blobs"));

    let (mut ws, _) = server.connect("blobs").await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 1, "width": 96, "height": 64}),
    )
    .await;
    let first = frame_for_input(&mut ws, 1).await;
    let mut later = next_frame(&mut ws).await;
    while later.header.scene_time == first.header.scene_time {
        later = next_frame(&mut ws).await;
    }
    assert!(later.header.sequence > first.header.sequence);
    assert!(
        later.header.scene_time > first.header.scene_time,
        "live time moves forward"
    );
    drop(ws);
    server.stop().await;
}

/// A minimal HTTP/1.1 GET over a raw socket: enough for JSON endpoints in tests.
pub async fn reqwest_like_get(addr: std::net::SocketAddr, path: &str) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut stream = tokio::net::TcpStream::connect(addr).await.expect("connect");
    let request = format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
    stream.write_all(request.as_bytes()).await.expect("write");
    let mut response = String::new();
    stream.read_to_string(&mut response).await.expect("read");
    assert!(response.starts_with("HTTP/1.1 200"), "{response}");
    let body = response.split("\r\n\r\n").nth(1).expect("body").to_string();
    body
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn still_view_gets_its_antialiased_lossless_frames_then_silence() {
    use isoray_protocol::{Codec, FLAG_FINAL, FLAG_STILL};
    use isoray_render::scenes::DemoScene;
    use isoray_render::{Accumulator, Camera, CpuBackend, Effects, View};
    use std::sync::Arc;

    let server = TestServer::start(&["--still-after-ms", "100"]).await;
    let (mut ws, _) = server.connect("blobs").await;
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 4.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 120, "height": 90}),
    )
    .await;
    send_json(
        &mut ws,
        json!({"type": "camera", "input_id": 3, "eye": [1.0, 1.0, 8.0], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 40}),
    )
    .await;
    send_json(
        &mut ws,
        json!({"type": "isovalue", "input_id": 4, "value": 0.6}),
    )
    .await;

    let mut frame = frame_for_input(&mut ws, 4).await;
    while frame.header.flags & FLAG_STILL == 0 {
        assert_eq!(
            frame.header.codec,
            Codec::Jpeg,
            "interactive frames are JPEG"
        );
        frame = next_frame(&mut ws).await;
    }
    assert_eq!(
        frame.header.codec,
        Codec::Png,
        "the still frame is lossless"
    );
    assert_eq!(frame.header.input_id, 4);
    assert_eq!(frame.header.flags & FLAG_FINAL, 0, "more passes follow");

    // The same view rendered directly by the engine: the still frame must match it bit for bit.
    let demo = DemoScene::Blobs;
    let scene = Arc::new(demo.state_at(4.0)).prepare();
    let view = View {
        width: 120,
        height: 90,
        camera: Camera {
            eye: glam::Vec3::new(1.0, 1.0, 8.0),
            target: glam::Vec3::ZERO,
            up: glam::Vec3::Y,
            fov_y_deg: 40.0,
        },
        isovalue: 0.6,
    };
    let backend = CpuBackend::new(1).expect("pool");
    let reference = backend.render(&scene, &view);
    assert_eq!(
        frame.image.as_raw(),
        &reference.rgb,
        "the first still frame is bit-exact"
    );

    // The PNG itself is lossless: decoded by the `png` crate (not the one the server encodes
    // with) it gives the same bytes.
    let (payload, depth) = frame.payload();
    assert!(depth.is_none(), "no depth channel unless asked for");
    let mut reader = png::Decoder::new(std::io::Cursor::new(payload))
        .read_info()
        .expect("a PNG");
    let mut decoded = vec![0; reader.output_buffer_size().expect("size")];
    let info = reader.next_frame(&mut decoded).expect("PNG decodes");
    assert_eq!((info.width, info.height), (120, 90));
    assert_eq!(&decoded[..info.buffer_size()], &reference.rgb[..]);

    // Then one lossless frame per antialiasing position (`--antialias-passes`, default 8),
    // the last the engine's mean of those passes, bit for bit.
    let mut accumulator = Accumulator::new(64);
    accumulator.antialias = 8;
    let mut antialiased = backend.refine(&scene, &view, &Effects::OFF, &mut accumulator);
    for pass in 2..=8 {
        antialiased = backend.refine(&scene, &view, &Effects::OFF, &mut accumulator);
        frame = next_frame(&mut ws).await;
        assert!(
            frame.header.flags & FLAG_STILL != 0,
            "pass {pass} is a still frame"
        );
        assert_eq!(frame.header.codec, Codec::Png, "pass {pass} is lossless");
        // Only the pass that ends the refinement says so.
        assert_eq!(
            frame.header.flags & FLAG_FINAL != 0,
            pass == 8,
            "pass {pass}: the final flag"
        );
    }
    assert!(accumulator.converged());
    assert_ne!(
        antialiased.rgb, reference.rgb,
        "the passes smooth the edges"
    );
    assert_eq!(
        frame.image.as_raw(),
        &antialiased.rgb,
        "the last still frame is the mean of the eight positions"
    );

    // Nothing changes, so nothing more is sent, and nothing is rendered either.
    let (_, stats) = server
        .state
        .sessions()
        .snapshot()
        .pop()
        .expect("the session");
    let rendered = stats
        .frames_rendered
        .load(std::sync::atomic::Ordering::SeqCst);
    let quiet =
        tokio::time::timeout(std::time::Duration::from_millis(1500), next_frame(&mut ws)).await;
    assert!(quiet.is_err(), "a frame arrived although nothing changed");
    assert_eq!(
        stats
            .frames_rendered
            .load(std::sync::atomic::Ordering::SeqCst),
        rendered,
        "a still view costs no rendering"
    );
    drop(ws);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn moving_views_trade_resolution_for_frame_rate_and_settle_at_full_size() {
    use isoray_protocol::FLAG_STILL;
    // A 240 fps target leaves about 3 ms per frame: far less than a 480×360 frame takes here,
    // so the controller must lower the resolution while the camera moves.
    let server = TestServer::start(&["--max-fps", "240", "--still-after-ms", "300"]).await;
    let (mut ws, _) = server.connect("blobs").await;
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 2.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 480, "height": 360}),
    )
    .await;
    let mut sizes = Vec::new();
    for id in 3..23u64 {
        let angle = id as f64 * 0.05;
        send_json(
            &mut ws,
            json!({"type": "camera", "input_id": id, "eye": [7.5 * angle.sin(), 1.5, 7.5 * angle.cos()], "target": [0, 0, 0], "up": [0, 1, 0]}),
        )
        .await;
        let frame = frame_for_input(&mut ws, id).await;
        sizes.push((frame.header.width, frame.header.height));
        assert_eq!(
            frame.image.dimensions(),
            (frame.header.width, frame.header.height)
        );
    }
    let (w, h) = *sizes.last().expect("frames");
    println!("interactive sizes while moving: {sizes:?}");
    assert!(
        w < 480 && h < 360,
        "the controller lowered the resolution: {sizes:?}"
    );
    assert!(
        (w as f64 / h as f64 - 480.0 / 360.0).abs() < 0.05,
        "aspect ratio kept"
    );
    let mut frame = next_frame(&mut ws).await;
    while frame.header.flags & FLAG_STILL == 0 {
        frame = next_frame(&mut ws).await;
    }
    assert_eq!(
        (frame.header.width, frame.header.height),
        (480, 360),
        "the still frame is full size"
    );
    drop(ws);
    server.stop().await;
}
