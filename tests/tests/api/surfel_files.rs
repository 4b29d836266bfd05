//! `isoray push` of point clouds and meshes written by another tool: a fixture script
//! (`tests/fixtures/surfel_files.py`, meshio and numpy) writes an icosphere as binary PLY,
//! OBJ and OFF, an ellipsoid point cloud as ASCII PLY with normals, as binary PLY without
//! (normals estimated on the server) and as `.xyz`; every file pushes through the real
//! binary into a surfel scene that renders. An OFF mesh without faces is refused with a 4xx
//! naming the field, and no scene is stored.

use super::*;
use crate::e2e::support::pixel_stddev;

/// `isoray push --surfels 3000 FILE`.
fn push_surfels(base: &str, file: &Path) -> (bool, String) {
    push_files(base, &[Path::new("--surfels"), Path::new("3000"), file])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn point_clouds_and_meshes_from_meshio_push_and_render() {
    let dir = tempfile::tempdir().expect("temp dir");
    let files = dir.path().join("files");
    run_fixture("surfel_files.py", &files);
    let data = dir.path().join("data");
    let server = Server::start(&data, &[]).await;
    let base = server.base.clone();
    call(move || {
        for (name, surfels) in [
            ("sphere.ply", 3000),
            ("sphere.obj", 3000),
            ("sphere.off", 3000),
            ("cloud_normals.ply", 1500),
            ("cloud_bare.ply", 1500),
            ("cloud.xyz", 1500),
        ] {
            let (ok, text) = push_surfels(&base, &files.join(name));
            assert!(ok, "{name}: {text}");
            let id = created_scene_id(&text);
            let scene = json(&get(&base, &format!("/api/v1/scenes/{id}")));
            assert_eq!(scene["kind"], "surfels", "{name}: {scene}");
            assert_eq!(
                scene["primitives"].as_u64(),
                Some(surfels),
                "{name}: {scene}"
            );
            let r = Client::new(&base)
                .expect("url")
                .request(
                    "POST",
                    &format!("/api/v1/scenes/{id}/render"),
                    &[("Content-Type", "application/json")],
                    Body::Bytes(br#"{"step":0,"width":48,"height":36}"#),
                )
                .expect("answer");
            assert_eq!(r.status, 200, "{name}: {}", r.text());
            let img = image::load_from_memory(&r.body).expect("a PNG").to_rgb8();
            // The object fills the middle of the frame: the centre differs from the corner.
            let (c, k) = (*img.get_pixel(24, 18), *img.get_pixel(0, 0));
            assert_ne!(c, k, "{name}: the object covers the centre");
            assert!(
                pixel_stddev(&img) > 5.0,
                "{name}: the image shows something"
            );
        }
        let before = store_snapshot(&data);
        let (ok, text) = push_surfels(&base, &files.join("no_faces.off"));
        assert!(!ok, "a mesh without faces is refused: {text}");
        assert!(
            text.contains("400")
                && text.contains("surfels.mesh.triangles")
                && text.contains("no faces"),
            "the answer names the field: {text}"
        );
        assert_eq!(store_snapshot(&data), before, "nothing stored changed");
    })
    .await;
    server.stop().await;
}
