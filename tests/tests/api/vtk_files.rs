//! `isoray push` of VTK files as the tools scientists use write them: a fixture script
//! (`tests/fixtures/vtk_meshes.py`, VTK's Python package and meshio) writes a mesh of
//! 215,622 tets in every encoding they offer (raw, base64 and appended data; zlib, LZ4 and
//! xz blocks; UInt32 and UInt64 headers; ASCII; legacy `.vtk` ASCII and binary, versions
//! 4.2 and 5.1; a `.pvd`
//! series), and every file pushes through the real binary and renders the same image as
//! the raw, uncompressed one. Hexahedra with cell data push and render alike from both
//! tools; legacy files in each tool's default version (5.1) push like 4.2 ones, and a
//! truncated 5.1 file is refused naming the array it ends in.

use super::*;
use crate::e2e::support::pixel_stddev;

fn not_blank(png: &[u8]) {
    let img = image::load_from_memory(png).expect("a PNG").to_rgb8();
    assert!(pixel_stddev(&img) > 5.0, "the image shows something");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn vtk_files_in_every_encoding_render_the_same_image() {
    let dir = tempfile::tempdir().expect("temp dir");
    let files = dir.path().join("files");
    run_fixture("vtk_meshes.py", &files);
    let server = Server::start(&dir.path().join("data"), &[]).await;
    let base = server.base.clone();
    call(move || {
        let f = |name: &str| files.join(name);
        let (ok, text) = push_files(&base, &[f("vtk_raw.vtu")]);
        assert!(ok, "{text}");
        assert!(text.contains("215622 tets"), "{text}");
        let reference = render_png(&base, &created_scene_id(&text), 0);
        not_blank(&reference);
        for name in [
            "vtk_default.vtu",
            "vtk_raw_zlib.vtu",
            "vtk_ascii.vtu",
            "vtk_base64.vtu",
            "vtk_base64_raw.vtu",
            "vtk_lz4.vtu",
            "vtk_lzma.vtu",
            "vtk_uint64.vtu",
            "vtk_uint64_base64.vtu",
            "vtk_small_blocks.vtu",
            "vtk_legacy_ascii.vtk",
            "vtk_legacy_binary.vtk",
            "meshio_default.vtu",
            "meshio_raw.vtu",
            "meshio_lzma.vtu",
            "meshio_ascii.vtu",
            "meshio_legacy.vtk",
            "vtk_legacy_default.vtk",
            "meshio_legacy_default.vtk",
        ] {
            let (ok, text) = push_files(&base, &[f(name)]);
            assert!(ok, "{name}: {text}");
            let png = render_png(&base, &created_scene_id(&text), 0);
            assert!(png == reference, "{name} renders as the raw file does");
        }

        // A .pvd series: two steps at the collection's times, the first the same image.
        let (ok, text) = push_files(&base, &[f("series.pvd")]);
        assert!(ok, "{text}");
        let id = created_scene_id(&text);
        let listed = steps(&base, &id);
        let times: Vec<f64> = listed
            .as_array()
            .expect("steps")
            .iter()
            .map(|s| s["time"].as_f64().expect("time"))
            .collect();
        assert_eq!(times, vec![0.0, 0.5]);
        assert!(render_png(&base, &id, 0) == reference);
        assert!(
            render_png(&base, &id, 1) != reference,
            "step 1's field is scaled"
        );

        // Hexahedra with cell data: split, moved to the points, the same from both tools.
        let (ok, text) = push_files(&base, &[f("hex_vtk.vtu")]);
        assert!(
            ok && text.contains("hexahedra") && text.contains("cell array"),
            "{text}"
        );
        let hex = render_png(&base, &created_scene_id(&text), 0);
        not_blank(&hex);
        let (ok, text) = push_files(&base, &[f("hex_meshio.vtu")]);
        assert!(ok, "{text}");
        assert!(render_png(&base, &created_scene_id(&text), 0) == hex);

        // A version 5.1 file cut inside its connectivity is refused, naming the array.
        let whole = std::fs::read(f("meshio_legacy_default.vtk")).expect("read");
        let conn = whole
            .windows(12)
            .position(|w| w == b"CONNECTIVITY")
            .expect("a CONNECTIVITY array");
        std::fs::write(f("cut51.vtk"), &whole[..conn + 4_000]).expect("write");
        let (ok, text) = push_files(&base, &[f("cut51.vtk")]);
        assert!(!ok);
        assert!(
            text.contains("cut51.vtk") && text.contains("CONNECTIVITY") && text.contains("ends"),
            "{text}"
        );
    })
    .await;
    server.stop().await;
}
