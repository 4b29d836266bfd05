//! The REST API over real sockets: every wrong push is a 4xx naming the field or byte offset
//! and changes nothing stored; steps survive a restart; the OpenAPI document lists the routes.

use isoray_server::api::client::{npy_header_f32, Body, Client, Response};
use isoray_server::{AppState, Config};
use serde_json::Value;
use std::path::Path;

/// Starts a server on an ephemeral port over `data_dir`; returns its base URL and a stopper.
async fn start(
    data_dir: &Path,
    extra: &[&str],
) -> (
    String,
    tokio::sync::oneshot::Sender<()>,
    tokio::task::JoinHandle<std::io::Result<()>>,
) {
    let dir = data_dir.to_str().expect("utf-8 temp path").to_string();
    let mut argv = vec!["isoray", "--listen", "127.0.0.1:0", "--data-dir", &dir];
    argv.extend_from_slice(extra);
    let config = <Config as clap::Parser>::parse_from(argv);
    let state = AppState::new(config).expect("valid config");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = listener.local_addr().expect("addr");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let handle = tokio::spawn(isoray_server::serve(listener, state, async move {
        let _ = rx.await;
    }));
    (format!("http://{addr}"), tx, handle)
}

/// Runs blocking client calls off the runtime.
async fn call<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f).await.expect("client thread")
}

fn json(r: &Response) -> Value {
    serde_json::from_slice(&r.body).unwrap_or_else(|e| panic!("JSON body ({e}): {}", r.text()))
}

fn npy(values: &[f32], columns: u32) -> Vec<u8> {
    let mut out = npy_header_f32((values.len() / columns as usize) as u64, columns);
    out.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    out
}

fn create(base: &str) -> (String, String) {
    let c = Client::new(base).expect("url");
    let r = c
        .request(
            "POST",
            "/api/v1/scenes",
            &[("Content-Type", "application/json")],
            Body::Bytes(br#"{"kind":"metaballs"}"#),
        )
        .expect("create");
    assert_eq!(r.status, 201, "{}", r.text());
    let v = json(&r);
    (
        v["scene"]["id"].as_str().expect("id").into(),
        v["write_token"].as_str().expect("token").into(),
    )
}

fn push(base: &str, id: &str, index: &str, token: &str, ct: &str, body: &[u8]) -> Response {
    let auth = format!("Bearer {token}");
    Client::new(base)
        .expect("url")
        .request(
            "PUT",
            &format!("/api/v1/scenes/{id}/steps/{index}"),
            &[("Content-Type", ct), ("Authorization", &auth)],
            Body::Bytes(body),
        )
        .expect("push answered")
}

fn steps(base: &str, id: &str) -> Value {
    let r = Client::new(base)
        .expect("url")
        .request(
            "GET",
            &format!("/api/v1/scenes/{id}/steps"),
            &[],
            Body::Empty,
        )
        .expect("list");
    json(&r)["steps"].clone()
}

const NPY: &str = "application/x-npy";

#[tokio::test]
async fn every_wrong_push_is_a_4xx_naming_where_and_changes_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (base, stop, handle) = start(
        dir.path(),
        &["--max-step-index", "100", "--max-push-bytes", "4096"],
    )
    .await;
    call(move || {
        let (id, token) = create(&base);
        let good = npy(&[0.0, 0.0, 0.0, 0.5, 0.5, 0.5], 3);
        let r = push(&base, &id, "0", &token, NPY, &good);
        assert_eq!(r.status, 201, "{}", r.text());
        let before = steps(&base, &id);

        let mut nan = good.clone();
        let at = nan.len() - 8;
        nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let mut int_dtype = good.clone();
        let d = int_dtype
            .windows(3)
            .position(|w| w == b"<f4")
            .expect("descr");
        int_dtype[d..d + 3].copy_from_slice(b"<i4");
        let mut bad_shape = npy(&[0.0; 8], 4);
        bad_shape.truncate(bad_shape.len() - 16); // declared 2 rows, one sent
        let wide = npy(&[0.5; 12], 6);
        let huge = npy(&[0.5; 2000], 4);
        let cases: Vec<(&str, Response, u16, &str)> = vec![
            (
                "wrong token",
                push(&base, &id, "1", "not-the-token", NPY, &good),
                403,
                "Authorization",
            ),
            (
                "unknown scene",
                push(
                    &base,
                    "0123456789abcdef0123456789abcdef",
                    "1",
                    &token,
                    NPY,
                    &good,
                ),
                404,
                "id",
            ),
            (
                "wrong dtype",
                push(&base, &id, "1", &token, NPY, &int_dtype),
                400,
                "descr",
            ),
            (
                "wrong shape",
                push(&base, &id, "1", &token, NPY, &wide),
                400,
                "shape",
            ),
            (
                "NaN value",
                push(&base, &id, "1", &token, NPY, &nan),
                400,
                "[1][1]",
            ),
            (
                "truncated body",
                push(&base, &id, "1", &token, NPY, &bad_shape),
                400,
                "offset",
            ),
            (
                "oversized body",
                push(&base, &id, "1", &token, NPY, &huge),
                413,
                "offset",
            ),
            (
                "index beyond limit",
                push(&base, &id, "101", &token, NPY, &good),
                400,
                "index",
            ),
            (
                "different content at an index",
                push(&base, &id, "0", &token, NPY, &npy(&[0.0; 3], 3)),
                409,
                "index",
            ),
        ];
        for (what, r, status, place) in cases {
            assert_eq!(r.status, status, "{what}: {}", r.text());
            let v = json(&r);
            assert!(
                v["code"].is_string() && v["message"].is_string(),
                "{what}: {v}"
            );
            if place == "offset" {
                assert!(v["offset"].is_u64(), "{what} names a byte offset: {v}");
            } else {
                assert_eq!(v["field"], place, "{what} names the field: {v}");
            }
        }
        assert_eq!(steps(&base, &id), before, "rejected pushes changed nothing");
        let r = push(&base, &id, "0", &token, NPY, &good);
        assert_eq!(
            (r.status, json(&r)["outcome"].clone()),
            (200, Value::from("unchanged"))
        );
    })
    .await;
    let _ = stop.send(());
    handle.await.expect("server task").expect("server ran");
    let step_files: Vec<_> = walk(dir.path());
    assert!(
        step_files.iter().all(|p| !p.contains(".tmp-")),
        "no temporary files left: {step_files:?}"
    );
}

fn walk(p: &Path) -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(p) {
        for e in entries.flatten() {
            let path = e.path();
            out.push(path.display().to_string());
            if path.is_dir() {
                out.extend(walk(&path));
            }
        }
    }
    out
}

#[tokio::test]
async fn unsupported_kinds_are_refused_and_steps_survive_a_restart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (base, stop, handle) = start(dir.path(), &[]).await;
    let (id, before) = call(move || {
        let c = Client::new(&base).expect("url");
        for kind in ["surfels", "tets"] {
            let body = format!(r#"{{"kind":"{kind}"}}"#);
            let r = c
                .request(
                    "POST",
                    "/api/v1/scenes",
                    &[("Content-Type", "application/json")],
                    Body::Bytes(body.as_bytes()),
                )
                .expect("answer");
            assert_eq!(r.status, 422, "{}", r.text());
            assert_eq!(json(&r)["field"], "kind");
        }
        let (id, token) = create(&base);
        let js = br#"{"positions":[[0,0,0],[0.4,0,0]],"radii":[0.5,0.5]}"#;
        assert_eq!(
            push(&base, &id, "0", &token, "application/json", js).status,
            201
        );
        assert_eq!(
            push(&base, &id, "1", &token, NPY, &npy(&[0.1, 0.0, 0.0, 0.6], 4)).status,
            201
        );
        let r = c
            .request(
                "POST",
                &format!("/api/v1/scenes/{id}/render"),
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"width":32,"height":24}"#),
            )
            .expect("render");
        assert_eq!(r.status, 200);
        assert!(r.body.starts_with(b"\x89PNG"), "a PNG");
        let listed = steps(&base, &id);
        (id, listed)
    })
    .await;
    let _ = stop.send(());
    handle.await.expect("server task").expect("server ran");
    let (base, stop, handle) = start(dir.path(), &[]).await;
    let after = call(move || steps(&base, &id)).await;
    assert_eq!(after, before, "every step reloaded with the same checksum");
    let _ = stop.send(());
    handle.await.expect("server task").expect("server ran");
}

#[test]
fn openapi_lists_every_api_route() {
    let doc = serde_json::to_value(isoray_server::api::openapi()).expect("document serializes");
    let paths = doc["paths"].as_object().expect("paths");
    for (path, methods) in [
        ("/api/v1/scenes", &["get", "post"][..]),
        ("/api/v1/scenes/{id}", &["get", "delete"]),
        ("/api/v1/scenes/{id}/steps", &["get"]),
        (
            "/api/v1/scenes/{id}/steps/{index}",
            &["get", "put", "delete"],
        ),
        ("/api/v1/scenes/{id}/steps/{index}/data", &["get"]),
        ("/api/v1/scenes/{id}/render", &["post"]),
        ("/api/v1/scenes/{id}/stream", &["get"]),
        ("/api/v1/openapi.json", &["get"]),
    ] {
        for m in methods {
            assert!(
                paths.get(path).and_then(|p| p.get(*m)).is_some(),
                "{m} {path} missing from the document"
            );
        }
    }
}
