//! Depth and normals as output (`format: "npy"`): `POST .../render` and `isoray render
//! --format npy` give the same `(H, W, 4)` float32 array of hit distance and outward normal,
//! and it agrees with the `f64` references (which share no code with the tracers) on a paper
//! scene (Tornado 4k, fitted-bvh-metaballs.txt Table 1) and on the tet demo. Each case
//! prints its maximum distance error, silhouette agreement and worst normal angle.

use super::*;
use glam::DVec3;
use isoray_render::kinds::metaballs::reference::ReferenceRay;
use isoray_render::kinds::tets::reference::reference_hit as tet_reference_hit;
use isoray_render::scene::Geometry;
use isoray_render::scenes::DemoScene;
use std::ffi::OsStr;

const SIZE: (u32, u32) = (48, 36);

/// The `(H, W, 4)` values of a little-endian `f32` `.npy` file.
pub fn read_surface_npy(bytes: &[u8]) -> (Vec<u64>, Vec<f32>) {
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00", "a version 1.0 .npy");
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + len]).expect("ascii header");
    assert!(header.contains("'descr': '<f4'"), "{header}");
    let shape = isoray_server::npy::dict_value(header, "shape").expect("a shape");
    let shape = isoray_server::npy::shape(shape).expect("readable shape");
    let values: Vec<f32> = bytes[10 + len..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(values.len() as u64, shape.iter().product::<u64>());
    (shape, values)
}

/// The pixel's ray: the camera's own `f32` ray (the input both sides trace), in `f64`.
fn pixel_dir(demo: DemoScene, (x, y): (u32, u32)) -> (DVec3, DVec3) {
    let ray = demo
        .default_camera()
        .rays(SIZE.0, SIZE.1)
        .through_pixel(x, y);
    (ray.origin.as_dvec3(), ray.dir.as_dvec3())
}

/// The reference's hit distance and outward normal for pixel `(x, y)` of `demo` at time 0.
fn reference(
    demo: DemoScene,
    geometry: &Geometry,
    vertex: &[DVec3],
    px: (u32, u32),
) -> Option<(f64, DVec3)> {
    let (eye, dir) = pixel_dir(demo, px);
    let isovalue = demo.default_isovalue() as f64;
    match geometry {
        Geometry::Metaballs(balls) => {
            let ray = ReferenceRay::new(balls, eye, dir, 0.0, 1.0e4);
            let t = ray.first_at_least(isovalue, 0.0)?;
            Some((t, ray.normal(t).unwrap_or(DVec3::ZERO)))
        }
        Geometry::Tets(step) => {
            let (t, tet) = tet_reference_hit(
                step.positions(),
                step.scalars(),
                step.mesh().tets(),
                eye,
                dir,
                0.0,
                1.0e4,
                isovalue,
            )?;
            // Smooth normals (the demo's): per-vertex gradients, the volume-weighted mean of
            // the incident tets' gradients, interpolated at the hit; outward is down the field.
            let p = eye + t * dir;
            let corners = step.mesh().tets()[tet as usize];
            let lambda = barycentric_in(step, corners, p);
            let g: DVec3 = (0..4)
                .map(|k| lambda[k] * vertex[corners[k] as usize])
                .sum();
            Some((t, (-g).normalize_or_zero()))
        }
        Geometry::Surfels(_) => unreachable!("the depth test renders metaball and tet scenes"),
    }
}

/// A tet's field gradient and volume.
fn tet_gradient(step: &isoray_render::kinds::tets::TetScene, ids: [u32; 4]) -> (DVec3, f64) {
    let p = ids.map(|v| step.positions()[v as usize].as_dvec3());
    let s = ids.map(|v| step.scalars()[v as usize] as f64);
    let e = [p[1] - p[0], p[2] - p[0], p[3] - p[0]];
    let det = e[0].dot(e[1].cross(e[2]));
    let g = (e[1].cross(e[2]) * (s[1] - s[0])
        + e[2].cross(e[0]) * (s[2] - s[0])
        + e[0].cross(e[1]) * (s[3] - s[0]))
        / det;
    (g, det.abs() / 6.0)
}

/// Barycentric coordinates of `q` in a tet.
fn barycentric_in(
    step: &isoray_render::kinds::tets::TetScene,
    ids: [u32; 4],
    q: DVec3,
) -> [f64; 4] {
    let p = ids.map(|v| step.positions()[v as usize].as_dvec3());
    let vol = |a: DVec3, b: DVec3, c: DVec3, d: DVec3| (b - a).dot((c - a).cross(d - a));
    let total = vol(p[0], p[1], p[2], p[3]);
    [
        vol(q, p[1], p[2], p[3]) / total,
        vol(p[0], q, p[2], p[3]) / total,
        vol(p[0], p[1], q, p[3]) / total,
        vol(p[0], p[1], p[2], q) / total,
    ]
}

/// Per-vertex gradients: the volume-weighted mean of the incident tets' gradients.
fn vertex_gradients(step: &isoray_render::kinds::tets::TetScene) -> Vec<DVec3> {
    let n = step.positions().len();
    let (mut sum, mut weight) = (vec![DVec3::ZERO; n], vec![0.0f64; n]);
    for &ids in step.mesh().tets() {
        let (g, v) = tet_gradient(step, ids);
        for i in ids {
            sum[i as usize] += v * g;
            weight[i as usize] += v;
        }
    }
    sum.iter()
        .zip(&weight)
        .map(|(s, w)| *s / w.max(1e-300))
        .collect()
}

/// The largest side of the geometry's bounding box.
pub fn extent(geometry: &Geometry) -> f64 {
    let (lo, hi) = match geometry {
        Geometry::Metaballs(balls) => balls.bounds().expect("balls"),
        Geometry::Tets(step) => step.positions().iter().fold(
            (glam::Vec3::splat(f32::MAX), glam::Vec3::splat(f32::MIN)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        ),
        Geometry::Surfels(s) => s.bounds().expect("surfels"),
    };
    (hi - lo).max_element() as f64
}

/// Compares the engine's array with the reference; returns (max |Δt| / extent, silhouette
/// mismatches, worst normal angle in degrees).
fn compare(demo: DemoScene, values: &[f32]) -> (f64, usize, f64) {
    let state = demo.state_at(0.0);
    let extent = extent(&state.geometry);
    let vertex = match &state.geometry {
        Geometry::Metaballs(_) => Vec::new(),
        Geometry::Tets(step) => vertex_gradients(step),
        Geometry::Surfels(_) => unreachable!("the depth test renders metaball and tet scenes"),
    };
    let mut worst = String::new();
    let mut loose = 0usize;
    let (mut max_err, mut mismatches, mut worst_angle, mut hits) = (0.0f64, 0usize, 0.0f64, 0);
    for y in 0..SIZE.1 {
        for x in 0..SIZE.0 {
            let i = ((y * SIZE.0 + x) * 4) as usize;
            let px = &values[i..i + 4];
            assert!(!px.iter().any(|v| v.is_nan()), "NaN at ({x}, {y}): {px:?}");
            let got = px[0].is_finite().then_some(px[0] as f64);
            match (got, reference(demo, &state.geometry, &vertex, (x, y))) {
                (Some(t), Some((r, n))) => {
                    hits += 1;
                    if (t - r).abs() / extent > 1e-5 {
                        loose += 1;
                    }
                    if (t - r).abs() / extent > max_err {
                        max_err = (t - r).abs() / extent;
                        worst = format!("({x}, {y}): {t} against {r}");
                    }
                    let engine_n = DVec3::new(px[1] as f64, px[2] as f64, px[3] as f64);
                    assert!((engine_n.length() - 1.0).abs() < 1e-3, "unit normal {px:?}");
                    let cos = engine_n.dot(n).clamp(-1.0, 1.0);
                    worst_angle = worst_angle.max(cos.acos().to_degrees());
                }
                (None, None) => assert_eq!(&px[1..], &[0.0, 0.0, 0.0], "a miss has no normal"),
                _ => mismatches += 1,
            }
        }
    }
    eprintln!(
        "{}: {hits} hits of {} pixels; max |Δt| {:.2e} of the extent {extent:.1}; silhouette \
         mismatches {mismatches}; worst normal angle {worst_angle:.3}°; worst pixel {worst}; \
         {loose} hits off by more than 1e-5 of the extent",
        demo.id(),
        SIZE.0 * SIZE.1,
        max_err
    );
    assert!(hits > 100, "{}: the view shows the surface", demo.id());
    assert!(
        loose * 100 <= hits,
        "{}: {loose} of {hits} hits off by more than 1e-5 of the extent",
        demo.id()
    );
    (max_err, mismatches, worst_angle)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn depth_and_normals_round_trip_through_the_api_and_the_cli() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(&dir.path().join("store"), &[]).await;
    let base = server.base.clone();
    let out_dir = dir.path().to_path_buf();
    call(move || {
        for demo in [DemoScene::Tornado4k, DemoScene::TetGyroid] {
            let body = format!(
                r#"{{"format":"npy","width":{},"height":{}}}"#,
                SIZE.0, SIZE.1
            );
            let r = Client::new(&base)
                .expect("url")
                .request(
                    "POST",
                    &format!("/api/v1/scenes/{}/render", demo.id()),
                    &[("Content-Type", "application/json")],
                    Body::Bytes(body.as_bytes()),
                )
                .expect("render");
            assert_eq!(r.status, 200, "{}", r.text());
            assert_eq!(r.header("content-type"), Some(NPY));
            let path = out_dir.join(format!("{}.npy", demo.id()));
            let (w, h) = (SIZE.0.to_string(), SIZE.1.to_string());
            let out = Command::new(isoray_binary())
                .args([
                    "render",
                    "--demo",
                    demo.id(),
                    "--format",
                    "npy",
                    "--width",
                    &w,
                ])
                .args(["--height", &h, "-o"])
                .arg(OsStr::new(&path))
                .output()
                .expect("isoray runs");
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let offline = std::fs::read(&path).expect("written");
            assert_eq!(
                offline, r.body,
                "the CLI's array is the server's, byte for byte"
            );
            let (shape, values) = read_surface_npy(&r.body);
            assert_eq!(shape, vec![SIZE.1 as u64, SIZE.0 as u64, 4]);
            let (err, mismatches, angle) = compare(demo, &values);
            // Distances: the finders' tolerance (1e-4) and f32 rounding at the eye's
            // distance, below 1e-5 of the extent for 99% of the hits (checked in `compare`).
            // The worst tet pixel, (27, 18), is 3e-3 early: its ray runs nearly in the plane of
            // the hit tet's isosurface, where rounding moves the crossing by δv / (g·d); 1e-3
            // of the extent bounds such grazing hits. A pixel may flip only where its ray
            // grazes the surface: at most 1% of them.
            assert!(
                err < 1e-3,
                "{}: max error {err:.2e} of the extent",
                demo.id()
            );
            assert!(
                mismatches * 100 <= (SIZE.0 * SIZE.1) as usize,
                "{}: {mismatches}",
                demo.id()
            );
            assert!(angle < 1.0, "{}: normal off by {angle}°", demo.id());
        }
        // A bad format is named.
        let r = Client::new(&base)
            .expect("url")
            .request(
                "POST",
                "/api/v1/scenes/blobs/render",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"format":"exr"}"#),
            )
            .expect("answer");
        assert_eq!(r.status, 400, "{}", r.text());
    })
    .await;
    server.stop().await;
}

/// The clip box cuts the array as it cuts the image: with the gyroid demo's own box (the
/// octant `[0, 3]³`, `"clip_box": true`) a pixel whose ray passes clear of the box keeps its
/// hit and normal, and the pixels whose rays cross it see something else (the surface behind,
/// or the solid's inner side where the ray leaves the box inside it); the same array on the
/// server and offline. A viewer's own box around the whole mesh leaves nothing to see, on
/// the server and offline. An
/// averaged npy is refused, naming `passes`, by both. (That the hits are the clipped image's,
/// and right on an analytic sphere, the render crate's `surface_tests` check.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_clip_box_cuts_depth_and_normals() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(&dir.path().join("store"), &[]).await;
    let base = server.base.clone();
    let path = dir.path().join("clipped.npy");
    call(move || {
        let render = |extra: &str| {
            let body = format!(
                r#"{{"format":"npy","width":{},"height":{}{extra}}}"#,
                SIZE.0, SIZE.1
            );
            super::tets::post_json(&base, "/api/v1/scenes/tets-gyroid/render", &body)
        };
        let whole = render("");
        let clipped = render(r#","effects":{"clip_box":true}"#);
        assert_eq!(clipped.status, 200, "{}", clipped.text());
        let (_, full) = read_surface_npy(&whole.body);
        let (_, cut) = read_surface_npy(&clipped.body);
        // Whether the pixel's ray meets the octant grown (or shrunk) by `margin`.
        let meets = |(x, y): (u32, u32), margin: f64| {
            let (e, d) = pixel_dir(DemoScene::TetGyroid, (x, y));
            let (lo, hi) = (DVec3::splat(-margin), DVec3::splat(3.0 + margin));
            let (a, b) = ((lo - e) / d, (hi - e) / d);
            let (near, far) = (a.min(b).max_element(), a.max(b).min_element());
            near <= far && far > 0.0
        };
        let (mut clear, mut changed, mut crossing) = (0, 0, 0);
        for (i, (f, c)) in full.chunks_exact(4).zip(cut.chunks_exact(4)).enumerate() {
            let px = (i as u32 % SIZE.0, i as u32 / SIZE.0);
            if !meets(px, 1e-3) {
                assert_eq!(f, c, "{px:?} passes clear of the box");
                clear += 1;
            } else if meets(px, -1e-3) && f[0].is_finite() {
                crossing += 1;
                changed += usize::from(f != c);
            }
        }
        eprintln!(
            "tets-gyroid clipped: {clear} pixels clear of the box kept; {changed} of {crossing} \
             hits through it changed"
        );
        assert!(
            clear > 100 && changed > 50,
            "{clear} clear, {changed} changed"
        );

        // `isoray render` with `effects`, then `extra`: the array it wrote, or its error.
        let (w, h) = (SIZE.0.to_string(), SIZE.1.to_string());
        let cli = |effects: &str, extra: &[&str]| {
            let out = Command::new(isoray_binary())
                .args(["render", "--demo", "tets-gyroid", "--format", "npy"])
                .args(["--width", &w, "--height", &h, "--effects", effects])
                .args(extra)
                .arg("-o")
                .arg(OsStr::new(&path))
                .output()
                .expect("isoray runs");
            match out.status.success() {
                true => Ok(std::fs::read(&path).expect("written")),
                false => Err(String::from_utf8_lossy(&out.stderr).into_owned()),
            }
        };
        assert!(
            cli(r#"{"clip_box":true}"#, &[]) == Ok(clipped.body),
            "the CLI's clipped array is the server's"
        );

        let whole_box = r#"{"clip_box":true,"clip":{"min":[-3,-3,-3],"max":[3,3,3]}}"#;
        let served = render(&format!(r#","effects":{whole_box}"#)).body;
        let (_, none) = read_surface_npy(&served);
        assert!(
            none.chunks_exact(4)
                .all(|p| p == [f32::INFINITY, 0.0, 0.0, 0.0]),
            "a box around the whole mesh cuts all of it"
        );
        assert!(
            cli(whole_box, &[]) == Ok(served),
            "the viewer's box offline too"
        );

        let r = render(r#","passes":4"#);
        assert_eq!(r.status, 422, "{}", r.text());
        assert_eq!(json(&r)["field"], "passes", "{}", r.text());
        let refused = cli(r#"{"clip_box":true}"#, &["--passes", "4"]).expect_err("refused");
        assert!(refused.contains("--passes 4"), "{refused}");
    })
    .await;
    server.stop().await;
}
