//! A deforming tet mesh from a file series, as a simulation writes it: meshio writes three
//! `.vtu` steps with its defaults (zlib-compressed binary), the same cells in each and the
//! points moving (a twist, a stretch and a bend), and `isoray push` sends the `.pvd`. Every
//! step's depth output (`format: "npy"`) puts each hit on the isosurface of that step's
//! moved mesh, checked by interpolating the moved field at the hit point in `f64` here, from
//! the fixture's own NumPy copy of the points, cells and values (no code shared with the
//! reader or the tracer); the same hits would miss the isosurface of the rest mesh. A viewer
//! streams the moved scene over the websocket. A step that inverts a tet is refused naming
//! the tet, the corner and the vertex, through the CLI and through the API in JSON, `.npy`
//! and raw bodies, and nothing stored changes.

use super::*;
use crate::e2e::support::{frame_for_input, pixel_stddev, send_json};
use glam::DVec3;
use isoray_render::Camera;

const SIZE: (u32, u32) = (40, 30);
const ISOVALUE: f64 = 0.55;

/// A little-endian `<f8` or `<i8` `.npy` file's values as f64, with its shape.
fn read_npy(path: &Path) -> (Vec<u64>, Vec<f64>) {
    let bytes = std::fs::read(path).expect("the fixture wrote it");
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + len]).expect("ascii header");
    let shape = isoray_server::npy::dict_value(header, "shape").expect("a shape");
    let shape = isoray_server::npy::shape(shape).expect("readable shape");
    let data = &bytes[10 + len..];
    let values = if header.contains("'<f8'") {
        data.chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect()
    } else {
        assert!(header.contains("'<i8'"), "{header}");
        data.chunks_exact(8)
            .map(|c| i64::from_le_bytes(c.try_into().expect("8 bytes")) as f64)
            .collect()
    };
    (shape, values)
}

/// One step of the fixture's mesh, in f64.
struct Mesh {
    points: Vec<DVec3>,
    cells: Vec<[usize; 4]>,
    f: Vec<f64>,
}

impl Mesh {
    fn load(dir: &Path, points: usize, f: usize) -> Mesh {
        let (_, p) = read_npy(&dir.join(format!("points_{points}.npy")));
        let (_, c) = read_npy(&dir.join("cells.npy"));
        let (_, f) = read_npy(&dir.join(format!("f_{f}.npy")));
        Mesh {
            points: p
                .chunks_exact(3)
                .map(|p| DVec3::new(p[0], p[1], p[2]))
                .collect(),
            cells: c
                .chunks_exact(4)
                .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize, c[3] as usize])
                .collect(),
            f,
        }
    }

    /// The piecewise-linear field at `q`: barycentric interpolation in a tet that holds it
    /// (within `slack` of its barycentric range), or `None` outside the mesh.
    fn field_at(&self, q: DVec3, slack: f64) -> Option<f64> {
        let vol = |a: DVec3, b: DVec3, c: DVec3, d: DVec3| (b - a).dot((c - a).cross(d - a));
        for cell in &self.cells {
            let p = cell.map(|v| self.points[v]);
            let (lo, hi) = p
                .iter()
                .fold((p[0], p[0]), |(lo, hi), x| (lo.min(*x), hi.max(*x)));
            if (q - lo).min_element() < -1e-6 || (hi - q).min_element() < -1e-6 {
                continue;
            }
            let total = vol(p[0], p[1], p[2], p[3]);
            let l = [
                vol(q, p[1], p[2], p[3]) / total,
                vol(p[0], q, p[2], p[3]) / total,
                vol(p[0], p[1], q, p[3]) / total,
                vol(p[0], p[1], p[2], q) / total,
            ];
            if l.iter().all(|&x| x >= -slack) {
                return Some((0..4).map(|k| l[k] * self.f[cell[k]]).sum());
            }
        }
        None
    }
}

fn camera() -> Camera {
    Camera {
        eye: glam::Vec3::new(0.3, 0.7, 2.4),
        target: glam::Vec3::new(0.1, 0.0, 0.0),
        up: glam::Vec3::Y,
        fov_y_deg: 45.0,
    }
}

/// The `(H, W, 4)` depth and normals of `step`, seen from [`camera`] at [`ISOVALUE`].
fn depth(base: &str, id: &str, step: u64) -> Vec<f32> {
    let c = camera();
    let body = format!(
        r#"{{"step":{step},"format":"npy","width":{},"height":{},"isovalue":{ISOVALUE},
            "camera":{{"eye":{:?},"target":{:?},"up":[0,1,0],"fov_y_deg":45}}}}"#,
        SIZE.0,
        SIZE.1,
        c.eye.to_array(),
        c.target.to_array()
    );
    let r = Client::new(base)
        .expect("url")
        .request(
            "POST",
            &format!("/api/v1/scenes/{id}/render"),
            &[("Content-Type", "application/json")],
            Body::Bytes(body.as_bytes()),
        )
        .expect("render");
    assert_eq!(r.status, 200, "{}", r.text());
    let (shape, values) = super::depth::read_surface_npy(&r.body);
    assert_eq!(shape, vec![SIZE.1 as u64, SIZE.0 as u64, 4]);
    values
}

/// For every hit pixel, the field of `mesh` at the hit point minus the isovalue (`None`
/// where the point is outside `mesh`).
fn residuals(mesh: &Mesh, values: &[f32]) -> Vec<Option<f64>> {
    let rays = camera().rays(SIZE.0, SIZE.1);
    let mut out = Vec::new();
    for y in 0..SIZE.1 {
        for x in 0..SIZE.0 {
            let t = values[((y * SIZE.0 + x) * 4) as usize];
            if !t.is_finite() {
                continue;
            }
            let ray = rays.through_pixel(x, y);
            let q = ray.origin.as_dvec3() + t as f64 * ray.dir.as_dvec3();
            out.push(mesh.field_at(q, 1e-5).map(|f| f - ISOVALUE));
        }
    }
    out
}

fn line_after<'a>(text: &'a str, prefix: &str) -> &'a str {
    text.lines()
        .find_map(|l| l.strip_prefix(prefix))
        .unwrap_or_else(|| panic!("`{prefix}` is printed: {text}"))
        .split_whitespace()
        .next()
        .unwrap_or_default()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_deforming_vtu_series_renders_every_step_on_its_moved_isosurface() {
    let dir = tempfile::tempdir().expect("temp dir");
    let files = dir.path().join("files");
    let printed = run_fixture("deforming_vtu.py", &files);
    let invert_vertex = line_after(&printed, "points 1331 tets 6000 invert_vertex ").to_string();
    let server = Server::start(&dir.path().join("data"), &[]).await;
    let base = server.base.clone();
    let data = dir.path().join("data");
    let id = call(move || {
        let (ok, text) = push_files(&base, &[files.join("series.pvd")]);
        assert!(ok, "{text}");
        assert!(text.contains("6000 tets"), "{text}");
        assert!(
            text.contains("step 2: created") && text.contains("moved points"),
            "{text}"
        );
        let id = line_after(&text, "created scene ").to_string();
        let token = line_after(&text, "write token ").to_string();
        let rest = Mesh::load(&files, 0, 0);
        for step in 0..3u64 {
            let moved = Mesh::load(&files, step as usize, step as usize);
            let values = depth(&base, &id, step);
            let on_moved = residuals(&moved, &values);
            let hits = on_moved.len();
            // The field is a distance (|∇f| = 1), so a residual is a distance too: f32 hit
            // distances put points within about 1e-6 of the mesh's size of the surface.
            let worst = on_moved
                .iter()
                .map(|r| r.expect("every hit lies inside the moved mesh").abs())
                .fold(0.0f64, f64::max);
            let off_rest = residuals(&rest, &values)
                .iter()
                .filter(|r| r.is_none_or(|r| r.abs() > 1e-3))
                .count();
            eprintln!(
                "step {step}: {hits} hits, worst |f - v| on the moved mesh {worst:.2e}; \
                 {off_rest} hits off the rest mesh's isosurface by more than 1e-3"
            );
            assert!(
                hits > 150,
                "step {step}: the view shows the surface ({hits} hits)"
            );
            assert!(worst < 1e-4, "step {step}: worst residual {worst:.2e}");
            if step > 0 {
                assert!(
                    off_rest * 2 > hits,
                    "step {step}: the hits follow the moved mesh, not the rest one \
                     ({off_rest} of {hits} off the rest isosurface)"
                );
            }
        }

        // A step that inverts a tet: refused through the CLI, naming tet, corner and vertex.
        let before = store_snapshot(&data);
        let args = ["--scene", &id, "--token", &token, "--start", "3"];
        let out = Command::new(isoray_binary())
            .arg("push")
            .args(["--server", &base])
            .args(args)
            .arg(files.join("inverted.pvd"))
            .output()
            .expect("isoray push runs");
        let text = String::from_utf8_lossy(&out.stdout).to_string()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{text}");
        assert!(
            text.contains("step 4")
                && text.contains("422")
                && text.contains("inverted")
                && text.contains("of tet ")
                && text.contains("corner ")
                && text.contains(&format!("positions[{invert_vertex}]")),
            "{text}"
        );
        // Step 3 (the rest pose, scalars only) went in; step 4 did not.
        let listed = steps(&base, &id);
        let indices: Vec<u64> = listed
            .as_array()
            .expect("steps")
            .iter()
            .map(|s| s["index"].as_u64().expect("index"))
            .collect();
        assert_eq!(indices, vec![0, 1, 2, 3]);
        let after = store_snapshot(&data);
        assert_eq!(
            after.len(),
            before.len() + 1,
            "one step file more (step 3), nothing else changed"
        );
        assert!(before.iter().all(|(k, v)| after.get(k) == Some(v)));
        (id, token)
    })
    .await;

    // A viewer streams the deformed scene (its newest step).
    let (mut ws, _) = tokio_tungstenite::connect_async(format!(
        "ws://{}/api/v1/scenes/{}/stream",
        server.addr, id.0
    ))
    .await
    .expect("websocket connects");
    send_json(
        &mut ws,
        serde_json::json!({"type": "resize", "input_id": 1, "width": 48, "height": 36}),
    )
    .await;
    let frame = frame_for_input(&mut ws, 1).await;
    assert_eq!((frame.image.width(), frame.image.height()), (48, 36));
    assert!(pixel_stddev(&frame.image) > 2.0, "the surface shows");
    drop(ws);
    server.stop().await;
}
