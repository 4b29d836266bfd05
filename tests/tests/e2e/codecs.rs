//! Codec negotiation: the client lists what it decodes, the server picks per frame (JPEG while
//! the view starts moving, H.264 once motion is sustained, PNG for the still frame) and falls
//! back cleanly; the depth channel rides with interactive frames when asked for.

use super::support::*;
use isoray_protocol::{Codec, FLAG_DEPTH, FLAG_KEYFRAME, FLAG_STILL};
use isoray_render::scenes::DemoScene;
use isoray_render::{Camera, CpuBackend, Framebuffer, View};
use serde_json::json;
use std::collections::HashMap;
use std::sync::Arc;

/// The orbit camera of input `id`.
fn orbit(id: u64) -> Camera {
    let angle = id as f32 * 0.04;
    Camera {
        eye: glam::Vec3::new(7.5 * angle.sin(), 1.5, 7.5 * angle.cos()),
        target: glam::Vec3::ZERO,
        up: glam::Vec3::Y,
        fov_y_deg: 45.0,
    }
}

async fn send_camera(ws: &mut Ws, id: u64, camera: Camera) {
    send_json(
        ws,
        json!({"type": "camera", "input_id": id, "eye": camera.eye.to_array(),
               "target": camera.target.to_array(), "up": camera.up.to_array(),
               "fov_y_deg": camera.fov_y_deg}),
    )
    .await;
}

fn reference(camera: Camera, width: u32, height: u32, time: f64) -> Framebuffer {
    let scene = Arc::new(DemoScene::Blobs.state_at(time)).prepare();
    let view = View {
        width,
        height,
        camera,
        isovalue: 0.5,
    };
    CpuBackend::new(1).expect("pool").render(&scene, &view)
}

fn psnr(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    let sse: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum();
    10.0 * (255.0f64.powi(2) / (sse / a.len() as f64).max(1e-12)).log10()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sustained_motion_switches_to_h264_that_decodes_to_the_rendered_view() {
    // Full size while moving, so every frame can be compared with a direct render; a long
    // still delay, so that a slow debug render between two inputs never counts as a rest.
    let server = TestServer::start(&["--min-scale", "1", "--still-after-ms", "5000"]).await;
    let (mut ws, info) = server.connect("blobs").await;
    assert!(
        info.codecs.iter().any(|c| c == "h264"),
        "this build offers H.264: {:?}",
        info.codecs
    );
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 2.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 160, "height": 120}),
    )
    .await;
    send_json(
        &mut ws,
        json!({"type": "stream", "input_id": 3, "codecs": ["h264", "jpeg", "png"]}),
    )
    .await;
    frame_for_input(&mut ws, 3).await;

    let mut decoder = openh264::decoder::Decoder::new().expect("decoder");
    let mut cameras = HashMap::new();
    let mut codecs = Vec::new();
    let mut first_h264_keyframe = None;
    let mut worst_psnr = f64::INFINITY;
    for id in 10..40u64 {
        cameras.insert(id, orbit(id));
        send_camera(&mut ws, id, orbit(id)).await;
        // Every frame is read and, if H.264, decoded in order: each predicts from the last.
        loop {
            let frame = next_frame(&mut ws).await;
            codecs.push(frame.header.codec);
            if frame.header.codec == Codec::H264 {
                let (payload, _) = frame.payload();
                if first_h264_keyframe.is_none() {
                    first_h264_keyframe = Some(frame.header.flags & FLAG_KEYFRAME != 0);
                    // An IDR access unit starts with its SPS (NAL type 7).
                    assert_eq!(&payload[..4], &[0, 0, 0, 1], "Annex B start code");
                    assert_eq!(payload[4] & 0x1F, 7, "the keyframe carries its SPS first");
                }
                let (w, h) = (frame.header.width as usize, frame.header.height as usize);
                let yuv = decoder
                    .decode(payload)
                    .expect("OpenH264 decodes the frame")
                    .expect("one picture per access unit");
                let mut rgb = vec![0u8; w * h * 3];
                yuv.write_rgb8(&mut rgb);
                let camera = cameras[&frame.header.input_id];
                let expected = reference(camera, w as u32, h as u32, 2.0);
                let p = psnr(&expected.rgb, &rgb);
                worst_psnr = worst_psnr.min(p);
            }
            if frame.header.input_id >= id {
                break;
            }
        }
    }
    println!("codecs while moving: {codecs:?}; worst H.264 PSNR {worst_psnr:.1} dB");
    assert_eq!(codecs[0], Codec::Jpeg, "motion starts with JPEG frames");
    let h264 = codecs.iter().filter(|c| **c == Codec::H264).count();
    assert!(h264 >= 10, "sustained motion streams H.264 ({h264} frames)");
    let first = codecs
        .iter()
        .position(|c| *c == Codec::H264)
        .expect("an H.264 frame");
    assert!(
        codecs[first..].iter().all(|c| *c == Codec::H264),
        "once in H.264, motion stays in H.264: {codecs:?}"
    );
    assert_eq!(
        first_h264_keyframe,
        Some(true),
        "the stream starts with a keyframe"
    );
    // Measured around 36–40 dB for these 160×120 frames; 30 dB leaves room for encoder
    // changes while still failing on a wrong camera or a broken colour conversion (< 15 dB).
    assert!(worst_psnr > 30.0, "H.264 PSNR {worst_psnr:.1} dB");

    // When the camera rests, the still frame is PNG, whatever the interactive codec was.
    let mut frame = tokio::time::timeout(WAIT, next_frame(&mut ws))
        .await
        .expect("the still frame");
    while frame.header.flags & FLAG_STILL == 0 {
        frame = next_frame(&mut ws).await;
    }
    assert_eq!(frame.header.codec, Codec::Png);
    drop(ws);
    assert_no_sessions_left(&server).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_falls_back_to_what_the_client_decodes() {
    let server = TestServer::start(&["--still-after-ms", "100"]).await;
    let (mut ws, _) = server.connect("blobs").await;
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 1.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 64, "height": 48}),
    )
    .await;
    // Codecs the server does not know are skipped, not refused.
    send_json(
        &mut ws,
        json!({"type": "stream", "input_id": 3, "codecs": ["av1", "jpeg"]}),
    )
    .await;
    let mut codecs = Vec::new();
    for id in 10..30u64 {
        send_camera(&mut ws, id, orbit(id)).await;
        codecs.push(frame_for_input(&mut ws, id).await.header.codec);
    }
    assert!(
        codecs.iter().all(|c| *c == Codec::Jpeg),
        "a JPEG-only client gets JPEG even in sustained motion: {codecs:?}"
    );
    // Without PNG, the still frame is the best JPEG.
    let mut frame = next_frame(&mut ws).await;
    while frame.header.flags & FLAG_STILL == 0 {
        frame = next_frame(&mut ws).await;
    }
    assert_eq!(frame.header.codec, Codec::Jpeg);
    assert_eq!(frame.header.quality, 100);

    // A list without any image codec is refused with the reason, and changes nothing.
    send_json(
        &mut ws,
        json!({"type": "stream", "input_id": 40, "codecs": ["h264", "vp9"]}),
    )
    .await;
    let error = next_error(&mut ws).await;
    assert_eq!(error.code, "invalid_value");
    assert_eq!(error.input_id, Some(40));
    assert!(
        error.message.contains("stream.codecs") && error.message.contains("jpeg"),
        "{}",
        error.message
    );
    send_camera(&mut ws, 41, orbit(41)).await;
    assert_eq!(frame_for_input(&mut ws, 41).await.header.codec, Codec::Jpeg);
    drop(ws);
    assert_no_sessions_left(&server).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn interactive_frames_carry_the_depth_channel_when_asked() {
    let server = TestServer::start(&["--min-scale", "1", "--still-after-ms", "150"]).await;
    let (mut ws, _) = server.connect("blobs").await;
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 3.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 130, "height": 98}),
    )
    .await;
    send_json(
        &mut ws,
        json!({"type": "stream", "input_id": 3, "depth": true}),
    )
    .await;
    let camera = orbit(7);
    send_camera(&mut ws, 4, camera).await;
    let frame = frame_for_input(&mut ws, 4).await;
    assert_eq!(frame.header.codec, Codec::Jpeg);
    assert_ne!(frame.header.flags & FLAG_DEPTH, 0, "the depth flag is set");
    let (image, depth) = frame.payload();
    assert_eq!(
        &image[..2],
        &[0xFF, 0xD8],
        "the image payload is the JPEG alone"
    );
    let depth = depth.expect("a depth block after the image");

    // Layout: u16 width, u16 height, f32 near, camera (eye, target, up, fov) as f32, PNG.
    let u16_at = |i: usize| u16::from_le_bytes([depth[i], depth[i + 1]]);
    let f32_at =
        |i: usize| f32::from_le_bytes([depth[i], depth[i + 1], depth[i + 2], depth[i + 3]]);
    let (w, h) = (u16_at(0) as u32, u16_at(2) as u32);
    assert_eq!((w, h), (33, 25), "a quarter of 130×98, rounded up");
    let near = f32_at(4);
    let eye = [f32_at(8), f32_at(12), f32_at(16)];
    assert_eq!(
        eye,
        camera.eye.to_array(),
        "the camera the frame was traced with"
    );
    assert_eq!(f32_at(44), camera.fov_y_deg);
    let mut reader = png::Decoder::new(std::io::Cursor::new(&depth[48..]))
        .read_info()
        .expect("depth PNG");
    let mut texels = vec![0; reader.output_buffer_size().expect("size")];
    reader.next_frame(&mut texels).expect("decodes");

    // Each texel holds near / (nearest depth of its 4×4 block), 16 bits, 0 for a miss.
    let fb = reference(camera, 130, 98, 3.0);
    let mut hits = 0;
    for ty in 0..h {
        for tx in 0..w {
            let mut nearest = f32::INFINITY;
            for y in ty * 4..((ty + 1) * 4).min(98) {
                for x in tx * 4..((tx + 1) * 4).min(130) {
                    nearest = nearest.min(fb.depth[(y * 130 + x) as usize]);
                }
            }
            let i = ((ty * w + tx) * 3) as usize;
            let q = u16::from_be_bytes([texels[i], texels[i + 1]]);
            if nearest.is_finite() {
                hits += 1;
                let expected = (near / nearest * 65535.0).round() as i32;
                assert!(
                    (q as i32 - expected).abs() <= 1,
                    "texel ({tx}, {ty}): {q} vs {expected}"
                );
            } else {
                assert_eq!(q, 0, "texel ({tx}, {ty}) is background");
            }
        }
    }
    assert!(hits > 50, "the view shows the blobs ({hits} texels hit)");

    // The still frame needs no reprojection: no depth block.
    let mut still = next_frame(&mut ws).await;
    while still.header.flags & FLAG_STILL == 0 {
        still = next_frame(&mut ws).await;
    }
    assert_eq!(still.header.flags & FLAG_DEPTH, 0);
    assert!(still.payload().1.is_none());
    drop(ws);
    server.stop().await;
}
