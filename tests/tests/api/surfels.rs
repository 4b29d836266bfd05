//! Surfel scenes over the REST API (deforming-point-sampled-surfaces.txt): a scene is created
//! from its surfels and simulation nodes, and every bad object (a zero-length tangent axis, a
//! value out of range, no nodes, a clipping relation naming a missing surface) is refused
//! naming the field, with nothing stored; steps are node positions (JSON or `.npy`), and a
//! wrong row count (a node that does not exist), a NaN or wrong columns are refused the same
//! way; a deformation too large for the hierarchy is drawn through the rebuild fallback; the
//! scene renders and streams, and the surfel demos are listed and stream too.

use super::*;
use crate::e2e::support::{frame_for_input, pixel_stddev, send_json};
use glam::Vec3;
use isoray_render::kinds::surfels::sample;
use serde_json::json as j;

/// A unit sphere of `n` surfels about the origin and a lattice of nodes inside it.
fn sphere_spec(n: usize) -> (Value, Vec<Vec3>) {
    let surfels: Vec<Value> = sample::sphere(Vec3::ZERO, 1.0, n, Vec3::new(0.8, 0.3, 0.2), 0)
        .iter()
        .map(|s| {
            j!({"centre": s.centre.to_array(), "t1": s.t1.to_array(), "t2": s.t2.to_array(),
                "radius": s.radius, "color": s.colour.to_array()})
        })
        .collect();
    let nodes = sample::lattice(Vec3::splat(-1.0), Vec3::splat(1.0), 0.5, |p| {
        p.length() <= 1.0
    });
    let spec = j!({
        "kind": "surfels",
        "name": "sphere",
        "camera": {"eye": [0.0, 0.0, 4.5], "target": [0.0, 0.0, 0.0]},
        "surfels": {"surfels": surfels, "nodes": nodes.iter().map(|p| p.to_array()).collect::<Vec<_>>()},
    });
    (spec, nodes)
}

fn post(base: &str, path: &str, body: &Value) -> Response {
    Client::new(base)
        .expect("url")
        .request(
            "POST",
            path,
            &[("Content-Type", "application/json")],
            Body::Bytes(body.to_string().as_bytes()),
        )
        .expect("answer")
}

/// `r` is the error `status` (400: the body breaks the schema; 422: a rule between values),
/// naming `field`, and nothing stored changed.
fn refused(
    r: &Response,
    status: u16,
    field: &str,
    says: &str,
    root: &Path,
    before: &BTreeMap<String, u128>,
) {
    assert_eq!(r.status, status, "{field}: {}", r.text());
    let body = json(r);
    assert_eq!(body["field"], field, "{body}");
    assert!(
        body["message"].as_str().is_some_and(|m| m.contains(says)),
        "message says {says:?}: {body}"
    );
    assert_eq!(&store_snapshot(root), before, "nothing stored changed");
    assert!(temp_files(root).is_empty(), "no temporary file left");
}

/// Pixels that differ from the background (`bg`: per row, the sky's colour; it depends only
/// on the ray) and the mean column of those pixels.
fn covered(img: &image::RgbImage, bg: &[image::Rgb<u8>]) -> (usize, f64) {
    let mut n = 0usize;
    let mut sx = 0.0;
    for (x, y, p) in img.enumerate_pixels() {
        let b = bg[y as usize];
        let d: i32 = (0..3).map(|c| (p[c] as i32 - b[c] as i32).abs()).sum();
        if d > 30 {
            n += 1;
            sx += x as f64;
        }
    }
    (n, sx / n.max(1) as f64)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn surfel_scenes_are_validated_stored_rendered_and_streamed() {
    let dir = tempfile::tempdir().expect("temp dir");
    let root = dir.path().to_path_buf();
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    let id = call(move || {
        let (good, nodes) = sphere_spec(600);
        let before = store_snapshot(&root);
        // Bad objects, each named; no scene is made.
        let mut bad = good.clone();
        bad["surfels"]["surfels"][5]["t2"] = j!([0.0, 0.0, 0.0]);
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(
            &r,
            422,
            "surfels.surfels[5].t2",
            "zero-length",
            &root,
            &before,
        );
        let mut bad = good.clone();
        bad["surfels"]["surfels"][7]["centre"][1] = j!(1e39);
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(
            &r,
            400,
            "surfels.surfels[7].centre[1]",
            "finite",
            &root,
            &before,
        );
        let mut bad = good.clone();
        bad["surfels"]["surfels"][2]["radius"] = j!(0.0);
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(
            &r,
            400,
            "surfels.surfels[2].radius",
            "radius",
            &root,
            &before,
        );
        let mut bad = good.clone();
        bad["surfels"]["nodes"] = j!([]);
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(&r, 400, "surfels.nodes", "node", &root, &before);
        let mut bad = good.clone();
        bad["surfels"]["clip"] = j!([[0, 3]]);
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(&r, 422, "surfels.clip", "group 3", &root, &before);
        let mut bad = good.clone();
        bad["surfels"]["update"] = j!("fast");
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(&r, 400, "surfels.update", "fast", &root, &before);
        let r = post(&base, "/api/v1/scenes", &j!({"kind": "surfels"}));
        refused(&r, 422, "surfels", "surfels", &root, &before);
        // Surfels have no field to take an isovalue of.
        let mut bad = good.clone();
        bad["isovalue"] = j!(0.5);
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(&r, 422, "isovalue", "no scalar field", &root, &before);
        // Meshes to sample: no faces, a face naming a missing vertex.
        let tetra = j!([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]);
        let mut bad = good.clone();
        bad["surfels"]["mesh"] = j!({"vertices": tetra, "triangles": []});
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(
            &r,
            400,
            "surfels.mesh.triangles",
            "no faces",
            &root,
            &before,
        );
        bad["surfels"]["mesh"] = j!({"vertices": tetra, "triangles": [[0, 2, 1], [0, 1, 4]]});
        let r = post(&base, "/api/v1/scenes", &bad);
        refused(
            &r,
            422,
            "surfels.mesh.triangles[1][2]",
            "vertex 4",
            &root,
            &before,
        );
        // NaN is not JSON: the body is refused as such.
        let text = good
            .to_string()
            .replacen("\"radius\":", "\"radius\":NaN,\"x\":", 1);
        let r = Client::new(&base)
            .expect("url")
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(text.as_bytes()),
            )
            .expect("answer");
        assert_eq!(r.status, 400, "{}", r.text());
        assert_eq!(&store_snapshot(&root), &before);

        let r = post(&base, "/api/v1/scenes", &good);
        assert_eq!(r.status, 201, "{}", r.text());
        let created = json(&r);
        assert_eq!(created["scene"]["kind"], "surfels");
        assert_eq!(created["scene"]["primitives"].as_u64(), Some(600));
        let id = created["scene"]["id"].as_str().expect("id").to_string();
        let token = created["write_token"].as_str().expect("token").to_string();
        let before = store_snapshot(&root);

        // Steps: one node too many (a node that does not exist), a NaN, four columns.
        let flat = |ps: &[Vec3]| ps.iter().flat_map(|p| p.to_array()).collect::<Vec<f32>>();
        let mut extra = nodes.clone();
        extra.push(Vec3::ZERO);
        let r = push(&base, &id, "0", &token, NPY, &npy(&flat(&extra), 3));
        refused(
            &r,
            400,
            "shape",
            &format!("{} simulation nodes", nodes.len()),
            &root,
            &before,
        );
        let mut nan = flat(&nodes);
        nan[3 * 4 + 1] = f32::NAN;
        let r = push(&base, &id, "0", &token, NPY, &npy(&nan, 3));
        assert_eq!(r.status, 400, "{}", r.text());
        assert!(r.text().contains("finite"), "{}", r.text());
        assert_eq!(store_snapshot(&root), before);
        let four: Vec<f32> = nodes.iter().flat_map(|p| [p.x, p.y, p.z, 1.0]).collect();
        let r = push(&base, &id, "0", &token, NPY, &npy(&four, 4));
        assert_eq!(r.status, 400, "four columns: {}", r.text());
        assert!(r.text().contains("3 columns"), "{}", r.text());
        assert_eq!(store_snapshot(&root), before);
        let js = j!({"positions": nodes[1..].iter().map(|p| p.to_array()).collect::<Vec<_>>()});
        let r = push(
            &base,
            &id,
            "0",
            &token,
            "application/json",
            js.to_string().as_bytes(),
        );
        refused(&r, 422, "positions", "simulation nodes", &root, &before);
        // A metaball step's columns fit the document's JsonStep, not a surfel scene.
        let js = j!({"positions": nodes.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
                     "radii": vec![0.1; nodes.len()]});
        let r = push(
            &base,
            &id,
            "0",
            &token,
            "application/json",
            js.to_string().as_bytes(),
        );
        refused(&r, 422, "radii", "node positions only", &root, &before);

        // Good steps: the object moved right (JSON); then stretched sixfold along x (.npy), a
        // deformation far beyond what the hierarchy's bounds prune: drawn through the
        // rebuild fallback.
        let moved: Vec<[f32; 3]> = nodes
            .iter()
            .map(|p| (*p + Vec3::X * 0.6).to_array())
            .collect();
        let r = push(
            &base,
            &id,
            "0",
            &token,
            "application/json",
            j!({"positions": moved}).to_string().as_bytes(),
        );
        assert_eq!(r.status, 201, "{}", r.text());
        let stretched: Vec<Vec3> = nodes
            .iter()
            .map(|p| *p * Vec3::new(6.0, 1.0, 1.0))
            .collect();
        let r = push(&base, &id, "1", &token, NPY, &npy(&flat(&stretched), 3));
        assert_eq!(r.status, 201, "{}", r.text());

        let render = |step: u32| {
            let r = post(
                &base,
                &format!("/api/v1/scenes/{id}/render"),
                &j!({"step": step, "width": 64, "height": 48}),
            );
            assert_eq!(r.status, 200, "{}", r.text());
            image::load_from_memory(&r.body).expect("PNG").to_rgb8()
        };
        // Step 0 leaves the left edge clear: the background of every row.
        let img0 = render(0);
        let bg: Vec<image::Rgb<u8>> = (0..img0.height()).map(|y| *img0.get_pixel(0, y)).collect();
        let (n0, x0) = covered(&img0, &bg);
        let (n1, _) = covered(&render(1), &bg);
        // The unit sphere at 4.5 covers about a sixth of the frame, moved right of centre.
        assert!(n0 > 200, "the sphere shows: {n0} pixels");
        assert!(x0 > 33.0, "moved right: mean column {x0:.1}");
        assert!(
            n1 > 2 * n0,
            "stretched sixfold it covers more: {n1} vs {n0}"
        );
        id
    })
    .await;

    // A viewer streams the stored scene.
    let (mut ws, _) =
        tokio_tungstenite::connect_async(format!("ws://{}/api/v1/scenes/{id}/stream", server.addr))
            .await
            .expect("websocket connects");
    send_json(
        &mut ws,
        j!({"type": "resize", "input_id": 1, "width": 64, "height": 48}),
    )
    .await;
    let frame = frame_for_input(&mut ws, 1).await;
    // The adaptive controller may shrink a slow stream's frames a little (62×46 seen).
    assert!(
        frame.image.width() <= 64 && frame.image.width() >= 32,
        "{}",
        frame.image.width()
    );
    assert!(pixel_stddev(&frame.image) > 2.0, "the surface shows");
    drop(ws);

    // The served OpenAPI document describes surfel scenes with the constraints checked here.
    let base = server.base.clone();
    let doc = call(move || json(&get(&base, "/api/v1/openapi.json"))).await;
    let schemas = &doc["components"]["schemas"];
    let kinds = schemas["CreateScene"]["properties"]["kind"]["enum"].to_string();
    assert!(
        kinds.contains("\"surfels\""),
        "surfels is a served kind: {kinds}"
    );
    let spec = &schemas["SurfelSpec"]["properties"];
    assert_eq!(spec["nodes"]["minItems"], 1, "{spec}");
    assert_eq!(spec["update"]["enum"][3], "rebuild", "{spec}");
    let data = &schemas["SurfelData"]["properties"];
    assert_eq!(data["radius"]["maximum"], 1.0e6, "{data}");
    assert!(
        data["t2"]["description"].to_string().contains("422"),
        "{data}"
    );
    assert_eq!(
        schemas["SurfelMesh"]["properties"]["triangles"]["minItems"],
        1
    );
    assert!(
        schemas["JsonSurfelStep"].is_object(),
        "the step schema is listed"
    );
    let step_body = doc["paths"]["/api/v1/scenes/{id}/steps/{index}"]["put"]["requestBody"]
        ["content"]["application/json"]["schema"]["description"]
        .to_string();
    assert!(step_body.contains("surfel"), "{step_body}");

    // The surfel demos are listed; the small one streams.
    let base = server.base.clone();
    let listed = call(move || json(&get(&base, "/api/v1/scenes"))).await;
    let surfel_demos: Vec<&str> = listed["scenes"]
        .as_array()
        .expect("scenes")
        .iter()
        .filter(|s| s["kind"] == "surfels")
        .filter_map(|s| s["id"].as_str())
        .collect();
    for demo in ["surfel-balls", "surfel-impact", "surfel-heads"] {
        assert!(
            surfel_demos.contains(&demo),
            "{demo} listed: {surfel_demos:?}"
        );
    }
    let (mut ws, _) = tokio_tungstenite::connect_async(format!(
        "ws://{}/api/v1/scenes/surfel-heads/stream",
        server.addr
    ))
    .await
    .expect("websocket connects");
    send_json(
        &mut ws,
        j!({"type": "resize", "input_id": 1, "width": 64, "height": 48}),
    )
    .await;
    let frame = frame_for_input(&mut ws, 1).await;
    assert!(pixel_stddev(&frame.image) > 2.0, "the cubes show");
    drop(ws);
    server.stop().await;
}
