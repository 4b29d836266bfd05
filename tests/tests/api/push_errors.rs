//! Every way a push can be wrong gets a 4xx with a JSON error that names the field or the byte
//! offset, and changes nothing stored: checked file by file on disk after each bad push.

use super::*;
use glam::Vec3;
use std::io::{Read, Write};

/// What the error must name.
enum Where {
    Field(&'static str),
    Offset(u64),
}

fn raw_header(dtype: u8, columns: u16, rows: u64) -> Vec<u8> {
    let mut h = b"ISRA".to_vec();
    h.push(1);
    h.push(dtype);
    h.extend_from_slice(&columns.to_le_bytes());
    h.extend_from_slice(&rows.to_le_bytes());
    h
}

/// Sends a request by hand and returns the status line's code and the body (for bodies the
/// blocking client will not send: chunked, or cut short with the connection closed).
fn raw_request(addr: std::net::SocketAddr, head: &str, body: &[u8], close_write: bool) -> String {
    let mut s = std::net::TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(std::time::Duration::from_secs(20)))
        .expect("timeout");
    s.write_all(head.as_bytes()).expect("head");
    let _ = s.write_all(body);
    if close_write {
        let _ = s.shutdown(std::net::Shutdown::Write);
    }
    let mut answer = Vec::new();
    let _ = s.read_to_end(&mut answer);
    String::from_utf8_lossy(&answer).into_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_wrong_push_is_a_4xx_naming_where_and_changes_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(
        dir.path(),
        &[
            "--max-step-index",
            "100",
            "--max-push-bytes",
            "4096",
            "--max-primitives",
            "300",
        ],
    )
    .await;
    let base = server.base.clone();
    let addr = server.addr;
    let root = dir.path().to_path_buf();
    call(move || {
        let (id, token) = create(&base);
        let good = npy(&[0.0, 0.0, 0.0, 0.5, 0.5, 0.5], 3);
        let r = push(&base, &id, "0", &token, NPY, &good);
        assert_eq!(r.status, 201, "{}", r.text());
        // Tet scenes: one with a mesh of one tet, one still waiting for its mesh.
        let tet_scene = |mesh: &str| {
            let r = super::tets::post_json(&base, "/api/v1/scenes", &format!(r#"{{"kind":"tets"{mesh}}}"#));
            assert_eq!(r.status, 201, "{}", r.text());
            let v = json(&r);
            let id = v["scene"]["id"].as_str().expect("id").to_string();
            (id, v["write_token"].as_str().expect("token").to_string())
        };
        let one_tet = r#"{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],"cells":[[0,1,2,3]]}"#;
        let (tet_id, tet_token) = tet_scene(&format!(r#","tets":{{"mesh":{one_tet}}}"#));
        let (bare_id, bare_token) = tet_scene("");
        let corners = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let missing_vertex = super::tets::mesh_npy(&corners, &[[0, 1, 2, 3], [0, 1, 2, 4]]);
        let missing_at = missing_vertex.len() - 8; // tet 1, corner 3
        let before_api = steps(&base, &id);
        let before_disk = store_snapshot(&root);
        assert!(
            before_disk.keys().any(|k| k.ends_with("00000000000000000000.step")),
            "the good step is on disk: {before_disk:?}"
        );

        let mut nan = good.clone();
        let nan_at = good.len() - 8; // row 1, column 1
        nan[nan_at..nan_at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let mut int_dtype = good.clone();
        let d = int_dtype.windows(3).position(|w| w == b"<f4").expect("descr");
        int_dtype[d..d + 3].copy_from_slice(b"<i4");
        let mut fortran = good.clone();
        let f = fortran.windows(5).position(|w| w == b"False").expect("order");
        fortran[f..f + 5].copy_from_slice(b"True ");
        let mut one_d = good.clone();
        let s = one_d.windows(6).position(|w| w == b"(2, 3)").expect("shape");
        one_d[s..s + 6].copy_from_slice(b"(6,)  ");
        let mut short = npy(&[0.5; 8], 4);
        short.truncate(short.len() - 16); // two rows declared, one sent
        let short_len = short.len() as u64;
        let mut trailing = good.clone();
        trailing.extend_from_slice(&[0, 0, 0, 0]);
        let mut negative_radius = npy(&[0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0, 0.5], 4);
        let r_at = negative_radius.len() - 4; // row 1, column 3
        negative_radius[r_at..r_at + 4].copy_from_slice(&(-0.5f32).to_le_bytes());
        let mut raw_nan = raw_header(1, 3, 1);
        raw_nan.extend([1.0f32, f32::INFINITY, 0.0].iter().flat_map(|v| v.to_le_bytes()));
        let mut raw_bad_dtype = raw_header(7, 3, 1);
        raw_bad_dtype.extend_from_slice(&[0; 12]);
        let too_many = npy(&vec![0.5; 301 * 3], 3);
        // 300 rows of 4 columns: within the row limit, over the 4096-byte body limit.
        let huge = npy(&[0.5; 1200], 4);
        let demo = "blobs";

        let p = |index: &str, ct: &str, body: &[u8]| push(&base, &id, index, &token, ct, body);
        let mut cases: Vec<(&str, Response, u16, Where)> = vec![
            (
                "no token",
                Client::new(&base)
                    .expect("url")
                    .request(
                        "PUT",
                        &format!("/api/v1/scenes/{id}/steps/1"),
                        &[("Content-Type", NPY)],
                        Body::Bytes(&good),
                    )
                    .expect("answer"),
                401,
                Where::Field("Authorization"),
            ),
            (
                "wrong token",
                push(&base, &id, "1", "not-the-token", NPY, &good),
                403,
                Where::Field("Authorization"),
            ),
            (
                // Authorization comes before the lookup: a scene's token is refused for any
                // other id, whether or not that scene exists (nothing says which ids exist).
                "unknown scene",
                push(&base, "0123456789abcdef0123456789abcdef", "1", &token, NPY, &good),
                403,
                Where::Field("Authorization"),
            ),
            (
                // Another scene's token is refused before the demo is looked up.
                "a built-in demo scene",
                push(&base, demo, "1", &token, NPY, &good),
                403,
                Where::Field("Authorization"),
            ),
            ("wrong dtype (.npy)", p("1", NPY, &int_dtype), 400, Where::Field("descr")),
            ("wrong dtype (raw)", p("1", "application/octet-stream", &raw_bad_dtype), 400, Where::Field("dtype")),
            ("Fortran order", p("1", NPY, &fortran), 400, Where::Field("fortran_order")),
            ("wrong shape: 6 columns", p("1", NPY, &npy(&[0.5; 12], 6)), 400, Where::Field("shape")),
            ("wrong shape: 1-D", p("1", NPY, &one_d), 400, Where::Field("shape")),
            ("too many rows", p("1", NPY, &too_many), 400, Where::Field("shape")),
            (
                "NaN value (.npy)",
                p("1", NPY, &nan),
                400,
                Where::Offset(nan_at as u64),
            ),
            (
                "infinite value (raw)",
                p("1", "application/octet-stream", &raw_nan),
                400,
                Where::Offset(16 + 4),
            ),
            (
                "negative radius",
                p("1", NPY, &negative_radius),
                400,
                Where::Offset(r_at as u64),
            ),
            (
                "number out of range (JSON)",
                p("1", "application/json", br#"{"positions":[[0,1e999,0]]}"#),
                400,
                Where::Field("positions[0][1]"),
            ),
            (
                "radii do not match positions (JSON)",
                p("1", "application/json", br#"{"positions":[[0,0,0]],"radii":[0.1,0.2]}"#),
                // Each array fits the schema; the rule between them does not: 422.
                422,
                Where::Field("radii"),
            ),
            (
                "truncated body (array shorter than its header says)",
                p("1", NPY, &short),
                400,
                Where::Offset(short_len),
            ),
            ("bytes after the array", p("1", NPY, &trailing), 400, Where::Offset(good.len() as u64)),
            ("not a .npy", p("1", NPY, b"PK\x03\x04 a zip file"), 400, Where::Offset(0)),
            (
                "oversized body (Content-Length)",
                p("1", NPY, &huge),
                413,
                Where::Field("Content-Length"),
            ),
            ("index beyond the limit", p("101", NPY, &good), 400, Where::Field("index")),
            ("index not a number", p("-1", NPY, &good), 400, Where::Field("index")),
            (
                "different content at an existing index",
                p("0", NPY, &npy(&[0.0; 3], 3)),
                409,
                Where::Field("index"),
            ),
            ("unsupported media type", p("1", "text/csv", b"0,0,0\n"), 415, Where::Field("Content-Type")),
            (
                "unknown query parameter",
                push(&base, &id, "1?replce=true", &token, NPY, &good),
                400,
                Where::Field("replce"),
            ),
            (
                "a tet referencing a missing vertex (mesh inline at creation)",
                super::tets::post_json(
                    &base,
                    "/api/v1/scenes",
                    r#"{"kind":"tets","tets":{"mesh":{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],
                        "cells":[[0,1,2,3],[0,1,2,4]]}}}"#,
                ),
                422,
                Where::Field("tets.mesh.cells[1][3]"),
            ),
            (
                "a tet referencing a missing vertex (mesh upload, JSON)",
                super::tets::put_mesh(
                    &base,
                    &bare_id,
                    &bare_token,
                    "application/json",
                    br#"{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],"cells":[[0,1,2,3],[4,1,2,3]]}"#,
                ),
                422,
                Where::Field("cells[1][0]"),
            ),
            (
                "a tet referencing a missing vertex (mesh upload, .npy)",
                super::tets::put_mesh(&base, &bare_id, &bare_token, NPY, &missing_vertex),
                422,
                Where::Offset(missing_at as u64),
            ),
            (
                "a step before the tet scene's mesh",
                push(&base, &bare_id, "0", &bare_token, NPY, &npy(&[0.5; 4], 1)),
                409,
                Where::Field("mesh"),
            ),
            (
                "tet scalars of the wrong count",
                push(&base, &tet_id, "0", &tet_token, NPY, &npy(&[0.5; 5], 1)),
                400,
                Where::Field("shape"),
            ),
            (
                "tet scalar not a number (JSON null)",
                push(&base, &tet_id, "0", &tet_token, "application/json", br#"{"scalars":[0,1,null,2]}"#),
                400,
                Where::Field("scalars[2]"),
            ),
            (
                // Neither JsonStep (no `scalars`) nor JsonTetStep (`scalars` is an array): the
                // document forbids it, so it is not read as "absent" (schemathesis, ST201).
                "scalars: null beside a metaball step's positions",
                push(&base, &id, "1", &token, "application/json", br#"{"positions":[],"scalars":null}"#),
                400,
                Where::Field("scalars"),
            ),
        ];
        // An oversized body without a declared length: cut off while streaming.
        let mut chunked = String::new();
        let mut body = Vec::new();
        body.extend_from_slice(format!("{:x}\r\n", huge.len()).as_bytes());
        body.extend_from_slice(&huge);
        body.extend_from_slice(b"\r\n0\r\n\r\n");
        chunked.push_str(&format!(
            "PUT /api/v1/scenes/{id}/steps/1 HTTP/1.1\r\nHost: x\r\nContent-Type: {NPY}\r\n\
             Authorization: Bearer {token}\r\nTransfer-Encoding: chunked\r\nConnection: close\r\n\r\n"
        ));
        let answer = raw_request(addr, &chunked, &body, false);
        let (head, text) = answer.split_once("\r\n\r\n").expect("an HTTP answer");
        assert!(head.starts_with("HTTP/1.1 413"), "chunked oversized body: {head}");
        let text = text.rsplit_once('}').map_or(text.to_string(), |(a, _)| format!("{a}}}"));
        let text = &text[text.find('{').expect("a JSON body")..];
        cases.push((
            "oversized body (chunked)",
            Response { status: 413, headers: Vec::new(), body: text.as_bytes().to_vec() },
            413,
            Where::Offset(4096),
        ));

        for (what, r, status, place) in cases {
            assert_eq!(r.status, status, "{what}: {}", r.text());
            let v = json(&r);
            assert!(
                v["code"].as_str().is_some_and(|c| !c.is_empty())
                    && v["message"].as_str().is_some_and(|m| !m.is_empty()),
                "{what}: an error has a code and a message: {v}"
            );
            match place {
                Where::Field(f) => assert_eq!(v["field"], f, "{what} names the field: {v}"),
                Where::Offset(o) => assert_eq!(v["offset"], o, "{what} names the byte offset: {v}"),
            }
            assert_eq!(steps(&base, &id), before_api, "{what}: the API shows no change");
            assert_eq!(store_snapshot(&root), before_disk, "{what}: no file in the store changed");
        }

        // A client that sends half a body and hangs up gets no answer, and leaves nothing.
        let head = format!(
            "PUT /api/v1/scenes/{id}/steps/1 HTTP/1.1\r\nHost: x\r\nContent-Type: {NPY}\r\n\
             Authorization: Bearer {token}\r\nContent-Length: {}\r\n\r\n",
            good.len()
        );
        let _ = raw_request(addr, &head, &good[..good.len() / 2], true);
        // The server notices the hang-up asynchronously; give it a moment, then look.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while !temp_files(&root).is_empty() && std::time::Instant::now() < deadline {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        assert_eq!(steps(&base, &id), before_api, "hang-up: the API shows no change");
        assert_eq!(store_snapshot(&root), before_disk, "hang-up: no file in the store changed");

        // The same step again is a no-op, and a replace must be asked for.
        let r = p("0", NPY, &good);
        assert_eq!((r.status, json(&r)["outcome"].clone()), (200, Value::from("unchanged")));
        assert_eq!(store_snapshot(&root), before_disk, "an unchanged push changes nothing");
        let r = p("0?replace=true", NPY, &npy(&[0.0; 3], 3));
        assert_eq!((r.status, json(&r)["outcome"].clone()), (200, Value::from("replaced")));
        assert_ne!(steps(&base, &id), before_api, "a replace does change the step");
    })
    .await;
    server.stop().await;
    assert!(temp_files(dir.path()).is_empty(), "no temporary files left");
}
