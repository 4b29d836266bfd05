//! Averaged passes through the render endpoint and `isoray render`: `"passes": 8` is the
//! engine's mean of eight passes from eight sub-pixel positions (antialiased), byte for byte
//! on the server and offline; one pass is the plain image; a count out of range is a 400
//! naming the field and the limit.

use super::tets::post_json;
use super::*;
use isoray_render::scenes::DemoScene;
use isoray_render::{Accumulator, CpuBackend, Effects};
use std::sync::Arc;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn averaged_passes_are_the_engines_antialiased_mean() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--max-refine-passes", "16"]).await;
    let base = server.base.clone();
    let offline = dir.path().join("eight.png");
    call(move || {
        let render = |extra: &str| {
            let body = format!(r#"{{"time":1,"width":80,"height":60{extra}}}"#);
            post_json(&base, "/api/v1/scenes/blobs/render", &body)
        };
        let plain = render("");
        assert_eq!(plain.status, 200, "{}", plain.text());
        assert_eq!(
            render(r#","passes":1"#).body,
            plain.body,
            "one pass: the plain image"
        );
        let eight = render(r#","passes":8"#);
        assert_eq!(eight.status, 200, "{}", eight.text());
        assert_ne!(eight.body, plain.body, "eight positions smooth the edges");

        // The engine's own accumulation of the same view.
        let demo = DemoScene::Blobs;
        let scene = Arc::new(demo.state_at(1.0)).prepare();
        let view = demo.default_view(80, 60);
        let backend = CpuBackend::new(2).expect("pool");
        let mut accumulator = Accumulator::fixed_passes(8);
        let mean = backend.refine_until_converged(&scene, &view, &Effects::OFF, &mut accumulator);
        assert_eq!(accumulator.passes(), 8);
        let served = image::load_from_memory(&eight.body).expect("PNG").to_rgb8();
        assert_eq!(
            served.as_raw(),
            &mean.rgb,
            "the served image is the engine's mean"
        );

        // Offline, the same bytes.
        let out = Command::new(isoray_binary())
            .args(["render", "--demo", "blobs", "--time", "1", "--width", "80"])
            .args(["--height", "60", "--passes", "8", "-o"])
            .arg(&offline)
            .output()
            .expect("isoray runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(std::fs::read(&offline).expect("written"), eight.body);

        for (extra, says) in [
            (r#","passes":0"#, "1..=16"),
            (r#","passes":17"#, "--max-refine-passes"),
        ] {
            let r = render(extra);
            assert_eq!(r.status, 400, "{extra}: {}", r.text());
            let body = json(&r);
            assert_eq!(body["field"], "passes", "{body}");
            assert!(
                body["message"].as_str().is_some_and(|m| m.contains(says)),
                "{body}"
            );
        }
    })
    .await;
    server.stop().await;
}
