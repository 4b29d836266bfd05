//! Tet scenes over the REST API: a mesh that is wrong in any way is refused naming the tet,
//! corner, field or byte offset and nothing stored changes; steps are one scalar per vertex;
//! a stored tet scene renders, streams over the websocket and survives a restart; and
//! `isoray push` sends a `.vtu` series.

use super::*;
use crate::e2e::support::{frame_for_input, pixel_stddev, send_json};
use glam::Vec3;
use isoray_render::kinds::tets::generate::box_mesh;
use isoray_render::kinds::tets::TetMesh;

/// Two `.npy` arrays back to back: vertices `(V, 3)` f32, cells `(T, 4)` i64.
pub(super) fn mesh_npy(vertices: &[Vec3], cells: &[[i64; 4]]) -> Vec<u8> {
    let mut out = npy(
        &vertices
            .iter()
            .flat_map(|v| v.to_array())
            .collect::<Vec<f32>>(),
        3,
    );
    let mut header = format!(
        "{{'descr': '<i8', 'fortran_order': False, 'shape': ({}, 4), }}",
        cells.len()
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend(cells.iter().flatten().flat_map(|c| c.to_le_bytes()));
    out
}

fn cells_of(mesh: &TetMesh) -> Vec<[i64; 4]> {
    mesh.tets().iter().map(|t| t.map(i64::from)).collect()
}

pub(super) fn put_mesh(base: &str, id: &str, token: &str, ct: &str, body: &[u8]) -> Response {
    let auth = format!("Bearer {token}");
    Client::new(base)
        .expect("url")
        .request(
            "PUT",
            &format!("/api/v1/scenes/{id}/mesh"),
            &[("Content-Type", ct), ("Authorization", &auth)],
            Body::Bytes(body),
        )
        .expect("answer")
}

pub(super) fn post_json(base: &str, path: &str, body: &str) -> Response {
    Client::new(base)
        .expect("url")
        .request(
            "POST",
            path,
            &[("Content-Type", "application/json")],
            Body::Bytes(body.as_bytes()),
        )
        .expect("answer")
}

/// The mesh used throughout: a jittered grid over [-1, 1]³, field |p| (spheres).
fn the_mesh() -> TetMesh {
    box_mesh([6, 6, 6], Vec3::splat(-1.0), Vec3::splat(1.0), 0.15, 11)
}

fn scalars(mesh: &TetMesh, scale: f32) -> Vec<f32> {
    mesh.vertices().iter().map(|p| p.length() * scale).collect()
}

/// Asserts a 4xx naming `field` (and, if given, text in the message) and that the store did
/// not change.
fn refused(
    r: &Response,
    status: u16,
    field: &str,
    says: &[&str],
    root: &Path,
    before: &BTreeMap<String, u128>,
) {
    assert_eq!(r.status, status, "{}", r.text());
    let body = json(r);
    assert_eq!(body["field"], field, "{body}");
    for s in says {
        assert!(
            body["message"].as_str().is_some_and(|m| m.contains(s)),
            "message says {s:?}: {body}"
        );
    }
    assert_eq!(&store_snapshot(root), before, "nothing stored changed");
    assert!(temp_files(root).is_empty(), "no temporary file left");
}

const SPEC: &str = r#"{"kind":"tets","name":"radial","isovalue":0.6,"isovalue_slider":[0,1.7],
    "camera":{"eye":[0.3,0.4,3.0],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":45}}"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tet_scenes_are_validated_stored_streamed_and_reloaded() {
    let dir = tempfile::tempdir().expect("temp dir");
    let root = dir.path().to_path_buf();
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    let (id, token, png, listed) = call(move || {
        let mesh = the_mesh();
        let (nv, nt) = (mesh.vertices().len(), mesh.tets().len());
        // Inline mesh with a tet referencing a missing vertex: refused, no scene made.
        let before = store_snapshot(&root);
        let bad = r#"{"kind":"tets","tets":{"mesh":{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],
            "cells":[[0,1,2,3],[0,1,2,9]]}}}"#;
        let r = post_json(&base, "/api/v1/scenes", bad);
        refused(
            &r,
            422,
            "tets.mesh.cells[1][3]",
            &["tet 1", "vertex 9"],
            &root,
            &before,
        );
        let r = post_json(&base, "/api/v1/scenes", SPEC);
        assert_eq!(r.status, 201, "{}", r.text());
        let created = json(&r);
        let id = created["scene"]["id"].as_str().expect("id").to_string();
        let token = created["write_token"].as_str().expect("token").to_string();
        assert_eq!(created["scene"]["kind"], "tets");
        let before = store_snapshot(&root);

        // Steps wait for the mesh.
        let step = npy(&scalars(&mesh, 1.0), 1);
        let r = push(&base, &id, "0", &token, NPY, &step);
        refused(&r, 409, "mesh", &["no mesh"], &root, &before);

        // Binary meshes with a missing vertex, an inverted tet, a NaN position: each named.
        let mut cells = cells_of(&mesh);
        cells[7][2] = nv as i64 + 5;
        let body = mesh_npy(mesh.vertices(), &cells);
        let r = put_mesh(&base, &id, &token, NPY, &body);
        refused(
            &r,
            422,
            "cells[7][2]",
            &["tet 7", &format!("vertex {}", nv + 5)],
            &root,
            &before,
        );
        let at = json(&r)["offset"].as_u64().expect("an offset") as usize;
        assert_eq!(
            &body[at..at + 8],
            &(nv as i64 + 5).to_le_bytes(),
            "the offset is the value's"
        );
        let mut cells = cells_of(&mesh);
        cells[3].swap(1, 2);
        let r = put_mesh(&base, &id, &token, NPY, &mesh_npy(mesh.vertices(), &cells));
        refused(&r, 422, "cells[3]", &["tet 3", "inverted"], &root, &before);
        let mut vertices = mesh.vertices().to_vec();
        vertices[4].y = f32::NAN;
        let r = put_mesh(
            &base,
            &id,
            &token,
            NPY,
            &mesh_npy(&vertices, &cells_of(&mesh)),
        );
        refused(&r, 400, "vertices[4]", &["vertex 4"], &root, &before);
        let short = mesh_npy(mesh.vertices(), &cells_of(&mesh));
        let r = put_mesh(&base, &id, &token, NPY, &short[..short.len() - 5]);
        assert_eq!(json(&r)["code"], "truncated", "{}", r.text());
        assert_eq!(store_snapshot(&root), before);
        // JSON meshes are checked the same way.
        let r = put_mesh(
            &base,
            &id,
            &token,
            "application/json",
            br#"{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],"cells":[[0,1,2,4]]}"#,
        );
        refused(&r, 422, "cells[0][3]", &["tet 0"], &root, &before);
        // The wrong token changes nothing either.
        let r = put_mesh(
            &base,
            &id,
            "0000",
            NPY,
            &mesh_npy(mesh.vertices(), &cells_of(&mesh)),
        );
        assert_eq!(r.status, 403, "{}", r.text());
        assert_eq!(store_snapshot(&root), before);

        // The mesh, then the same again (a no-op), then a different one (refused).
        let body = mesh_npy(mesh.vertices(), &cells_of(&mesh));
        let r = put_mesh(&base, &id, &token, NPY, &body);
        assert_eq!(r.status, 201, "{}", r.text());
        let info = json(&r);
        assert_eq!(
            (info["vertices"].as_u64(), info["tets"].as_u64()),
            (Some(nv as u64), Some(nt as u64))
        );
        let r = put_mesh(&base, &id, &token, NPY, &body);
        assert_eq!(
            (r.status, json(&r)["outcome"].as_str()),
            (200, Some("unchanged"))
        );
        let before = store_snapshot(&root);
        let moved: Vec<Vec3> = mesh.vertices().iter().map(|p| *p * 1.5).collect();
        let r = put_mesh(&base, &id, &token, NPY, &mesh_npy(&moved, &cells_of(&mesh)));
        refused(&r, 409, "mesh", &["different mesh"], &root, &before);

        // Steps: wrong length, NaN, bad JSON, each refused naming where.
        let r = push(
            &base,
            &id,
            "0",
            &token,
            NPY,
            &npy(&scalars(&mesh, 1.0)[1..], 1),
        );
        refused(
            &r,
            400,
            "shape",
            &[&format!("{nv} vertices")],
            &root,
            &before,
        );
        let r = push(&base, &id, "0", &token, NPY, &npy(&scalars(&mesh, 1.0), 3));
        assert_eq!(r.status, 400, "three columns: {}", r.text());
        let mut nan = scalars(&mesh, 1.0);
        nan[17] = f32::NAN;
        let r = push(&base, &id, "0", &token, NPY, &npy(&nan, 1));
        assert_eq!(r.status, 400, "{}", r.text());
        assert!(
            json(&r)["offset"].as_u64().is_some() || json(&r)["field"].is_string(),
            "{}",
            r.text()
        );
        assert!(
            r.text().contains("17") || r.text().contains("finite"),
            "{}",
            r.text()
        );
        assert_eq!(store_snapshot(&root), before);
        let js = format!("{{\"scalars\":{:?}}}", &scalars(&mesh, 1.0)[..nv - 2]);
        let r = push(&base, &id, "0", &token, "application/json", js.as_bytes());
        refused(
            &r,
            422,
            "scalars",
            &[&format!("{nv} vertices")],
            &root,
            &before,
        );

        // Good steps: JSON, then .npy.
        let values: Vec<f64> = scalars(&mesh, 1.0).iter().map(|&v| v as f64).collect();
        let js = serde_json::json!({ "scalars": values }).to_string();
        let r = push(&base, &id, "0", &token, "application/json", js.as_bytes());
        assert_eq!(r.status, 201, "{}", r.text());
        let r = push(&base, &id, "1", &token, NPY, &npy(&scalars(&mesh, 1.2), 1));
        assert_eq!(r.status, 201, "{}", r.text());
        let listed = steps(&base, &id);
        assert_eq!(listed.as_array().map(Vec::len), Some(2));
        let scene = json(&get(&base, &format!("/api/v1/scenes/{id}")));
        assert_eq!(scene["primitives"].as_u64(), Some(nt as u64), "{scene}");

        // A one-shot render of step 1 shows the sphere.
        let r = post_json(
            &base,
            &format!("/api/v1/scenes/{id}/render"),
            r#"{"step":1,"width":64,"height":48}"#,
        );
        assert_eq!(r.status, 200, "{}", r.text());
        let img = image::load_from_memory(&r.body).expect("PNG").to_rgb8();
        let corner = *img.get_pixel(0, 0);
        let centre = *img.get_pixel(32, 24);
        assert_ne!(
            centre, corner,
            "the sphere covers the middle, not the corner"
        );
        // A step the scene does not hold: the scene exists, so the body's `step` is what is
        // wrong (422 naming it), not a missing resource (a 404 here broke schemathesis's
        // "created resource not found" check).
        let missing = post_json(
            &base,
            &format!("/api/v1/scenes/{id}/render"),
            r#"{"step":7,"width":64,"height":48}"#,
        );
        assert_eq!(missing.status, 422, "{}", missing.text());
        let err = json(&missing);
        assert_eq!(err["field"], "step", "{err}");
        assert!(
            err["message"]
                .as_str()
                .is_some_and(|m| m.contains("no step 7")),
            "{err}"
        );
        (id, token, r.body, listed)
    })
    .await;

    // A viewer streams the stored scene, and may pick a negative isovalue.
    let (mut ws, _) =
        tokio_tungstenite::connect_async(format!("ws://{}/api/v1/scenes/{id}/stream", server.addr))
            .await
            .expect("websocket connects");
    send_json(
        &mut ws,
        serde_json::json!({"type": "resize", "input_id": 1, "width": 64, "height": 48}),
    )
    .await;
    let frame = frame_for_input(&mut ws, 1).await;
    assert_eq!((frame.image.width(), frame.image.height()), (64, 48));
    assert!(pixel_stddev(&frame.image) > 2.0, "the surface shows");
    send_json(
        &mut ws,
        serde_json::json!({"type": "isovalue", "input_id": 2, "value": -0.25}),
    )
    .await;
    let frame = frame_for_input(&mut ws, 2).await;
    assert!(
        frame.header.input_id >= 2,
        "a negative isovalue is accepted for a tet scene"
    );
    drop(ws);
    server.stop().await;

    // After a restart: the mesh, steps and images are the same.
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    call(move || {
        let mesh = the_mesh();
        let r = put_mesh(
            &base,
            &id,
            &token,
            NPY,
            &mesh_npy(mesh.vertices(), &cells_of(&mesh)),
        );
        assert_eq!(
            (r.status, json(&r)["outcome"].as_str()),
            (200, Some("unchanged"))
        );
        assert_eq!(steps(&base, &id), listed);
        let r = post_json(
            &base,
            &format!("/api/v1/scenes/{id}/render"),
            r#"{"step":1,"width":64,"height":48}"#,
        );
        assert_eq!(r.status, 200);
        assert_eq!(r.body, png, "the same image after a restart");
    })
    .await;
    server.stop().await;
}

/// Writes one `.vtu` of `mesh` with point array `name` and its values.
fn write_vtu(path: &Path, mesh: &TetMesh, name: &str, values: &[f32], kinds: Option<&[u8]>) {
    use vtkio::model::*;
    let points: Vec<f64> = mesh
        .vertices()
        .iter()
        .flat_map(|p| p.to_array().map(f64::from))
        .collect();
    let connectivity: Vec<u64> = mesh
        .tets()
        .iter()
        .flatten()
        .map(|&v| u64::from(v))
        .collect();
    let offsets: Vec<u64> = (1..=mesh.tets().len() as u64).map(|i| 4 * i).collect();
    let types = match kinds {
        Some(k) => k
            .iter()
            .map(|&t| {
                if t == 10 {
                    CellType::Tetra
                } else {
                    CellType::Pyramid
                }
            })
            .collect(),
        None => vec![CellType::Tetra; mesh.tets().len()],
    };
    let vtk = Vtk {
        version: Version::new((1, 0)),
        title: String::new(),
        byte_order: ByteOrder::LittleEndian,
        file_path: None,
        data: DataSet::inline(UnstructuredGridPiece {
            points: IOBuffer::F64(points),
            cells: Cells {
                cell_verts: VertexNumbers::XML {
                    connectivity,
                    offsets,
                },
                types,
            },
            data: Attributes {
                point: vec![Attribute::DataArray(DataArray {
                    name: name.into(),
                    elem: ElementType::Scalars {
                        num_comp: 1,
                        lookup_table: None,
                    },
                    data: IOBuffer::F32(values.to_vec()),
                })],
                cell: vec![],
            },
        }),
    };
    vtk.export(path).expect("vtkio writes the .vtu");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn isoray_push_sends_a_vtu_series_as_a_tet_scene() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("data");
    let files = dir.path().join("series");
    std::fs::create_dir_all(&files).expect("mkdir");
    let mesh = box_mesh([4, 4, 4], Vec3::splat(-1.0), Vec3::splat(1.0), 0.1, 5);
    let paths: Vec<PathBuf> = (0..3)
        .map(|k| {
            let p = files.join(format!("step{k}.vtu"));
            write_vtu(
                &p,
                &mesh,
                "pressure",
                &scalars(&mesh, 1.0 + 0.1 * k as f32),
                None,
            );
            p
        })
        .collect();
    let server = Server::start(&data, &[]).await;
    let base = server.base.clone();
    call(move || {
        let run = |args: Vec<&std::ffi::OsStr>| {
            std::process::Command::new(isoray_binary())
                .arg("push")
                .args(args)
                .output()
                .expect("isoray push runs")
        };
        let out = run(vec![
            "--server".as_ref(),
            base.as_ref(),
            paths[0].as_os_str(),
            paths[1].as_os_str(),
            paths[2].as_os_str(),
        ]);
        let text = String::from_utf8_lossy(&out.stdout).to_string()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{text}");
        let id = text
            .lines()
            .find_map(|l| l.strip_prefix("created scene "))
            .expect("the new scene's id is printed")
            .trim()
            .to_string();
        let scene = json(&get(&base, &format!("/api/v1/scenes/{id}")));
        assert_eq!(scene["kind"], "tets");
        assert_eq!(scene["primitives"].as_u64(), Some(mesh.tets().len() as u64));
        let listed = steps(&base, &id);
        let listed = listed.as_array().expect("steps");
        assert_eq!(listed.len(), 3, "{text}");
        assert!(listed
            .iter()
            .all(|s| s["primitives"].as_u64() == Some(mesh.vertices().len() as u64)));
        // Step 2's stored scalars are the file's.
        let r = get(&base, &format!("/api/v1/scenes/{id}/steps/2/data"));
        assert_eq!(r.status, 200);
        let want: Vec<u8> = scalars(&mesh, 1.2)
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert!(
            r.body.ends_with(&want),
            "the third file's scalars were stored"
        );

        // A file with a non-tet cell, and one whose mesh differs, are refused naming them.
        let odd = files.join("pyramid.vtu");
        let mut kinds = vec![10u8; mesh.tets().len()];
        kinds[5] = 14;
        write_vtu(&odd, &mesh, "pressure", &scalars(&mesh, 1.0), Some(&kinds));
        let out = run(vec!["--server".as_ref(), base.as_ref(), odd.as_os_str()]);
        let text = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(!out.status.success());
        assert!(
            text.contains("cell 5") && text.contains("pyramid.vtu"),
            "{text}"
        );
        let other = box_mesh([3, 4, 4], Vec3::splat(-1.0), Vec3::splat(1.0), 0.1, 5);
        let changed = files.join("changed.vtu");
        write_vtu(&changed, &other, "pressure", &scalars(&other, 1.0), None);
        let out = run(vec![
            "--server".as_ref(),
            base.as_ref(),
            paths[0].as_os_str(),
            changed.as_os_str(),
        ]);
        let text = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(!out.status.success());
        assert!(
            text.contains("changed.vtu") && text.contains("cells differ"),
            "{text}"
        );
    })
    .await;
    server.stop().await;
}
