//! Particle files as simulation scripts write them with NumPy (`tests/fixtures/particles.py`):
//! a CSV (`np.savetxt` with a header), an `.npz` (`np.savez` with named arrays, two steps)
//! and a two-frame `.xyz` push through `isoray push` and render as metaballs; the CSV and the
//! `.npz`'s first step hold the same balls and render the same image. Broken files are
//! refused naming the line (CSV, XYZ) or the array (NPZ), and create nothing.

use super::*;
use crate::e2e::support::pixel_stddev;

fn render(base: &str, id: &str, step: u64) -> Vec<u8> {
    let png = render_png(base, id, step);
    let img = image::load_from_memory(&png).expect("a PNG").to_rgb8();
    assert!(pixel_stddev(&img) > 5.0, "step {step} shows something");
    png
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn csv_npz_and_xyz_particles_push_and_render_as_metaballs() {
    let dir = tempfile::tempdir().expect("temp dir");
    let files = dir.path().join("files");
    run_fixture("particles.py", &files);
    let server = Server::start(&dir.path().join("data"), &[]).await;
    let base = server.base.clone();
    call(move || {
        let f = |name: &str| files.join(name);
        let (ok, text) = push_files(&base, &[f("balls.csv")]);
        assert!(ok && text.contains("300 balls, 4 columns"), "{text}");
        let csv = render(&base, &created_scene_id(&text), 0);

        let (ok, text) = push_files(&base, &[f("balls.npz")]);
        assert!(ok && text.contains("2 steps of 300 particles"), "{text}");
        let id = created_scene_id(&text);
        assert!(
            render(&base, &id, 0) == csv,
            "the .npz's first step is the CSV's balls"
        );
        assert!(render(&base, &id, 1) != csv, "its second step moved");

        let (ok, text) = push_files(&base, &[f("balls.xyz")]);
        assert!(
            ok && text.contains("step 1: created (300 balls, 3 columns"),
            "{text}"
        );
        render(&base, &created_scene_id(&text), 1);

        let scenes_before = get(&base, "/api/v1/scenes").body;
        for (name, says) in [
            ("bad.csv", &["line 5", "column `y`", "`nan?`"][..]),
            ("bad.npz", &["array `positions`", "[300, 2]"][..]),
            ("bad.xyz", &["frame 1", "1 of 3"][..]),
        ] {
            let (ok, text) = push_files(&base, &[f(name)]);
            assert!(!ok, "{name}: {text}");
            assert!(
                text.contains(name) && says.iter().all(|s| text.contains(s)),
                "{name}: {text}"
            );
            assert!(!text.contains("created scene"), "{name}: {text}");
        }
        assert_eq!(
            get(&base, "/api/v1/scenes").body,
            scenes_before,
            "a refused file creates no scene"
        );
    })
    .await;
    server.stop().await;
}
