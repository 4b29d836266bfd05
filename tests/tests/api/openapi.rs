//! The OpenAPI document the server serves validates (openapi-spec-validator, from PyPI, run
//! here and so in CI), and it and the router agree: every route registered in the server's
//! source is in the document, every documented operation is routed, and every method the
//! document leaves out of a path is refused by the router with 405.

use super::*;
use serde_json::Value;

const METHODS: [&str; 5] = ["get", "put", "post", "delete", "patch"];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn served_document_validates_with_openapi_spec_validator() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    let doc = call(move || get(&base, "/api/v1/openapi.json")).await;
    server.stop().await;
    assert_eq!(doc.status, 200);
    assert_eq!(doc.header("content-type"), Some("application/json"));
    let file = dir.path().join("openapi.json");
    std::fs::write(&file, &doc.body).expect("write the document");
    let out = std::process::Command::new(python())
        .args(["-m", "openapi_spec_validator"])
        .arg(&file)
        .output()
        .expect("python runs (CI installs openapi-spec-validator into ISORAY_PYTHON)");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "openapi-spec-validator: {text}");
    assert!(text.contains("OK"), "the validator says OK: {text}");

    // The validator does fail on a broken document (so its OK above means something).
    let mut broken: Value = serde_json::from_slice(&doc.body).expect("JSON");
    broken["paths"]["/api/v1/scenes"]["get"]["responses"] = Value::String("none".into());
    std::fs::write(&file, broken.to_string()).expect("write");
    let out = std::process::Command::new(python())
        .args(["-m", "openapi_spec_validator"])
        .arg(&file)
        .output()
        .expect("python runs");
    assert!(!out.status.success(), "a broken document is refused");
}

/// Every `.route("...")` path in the server's source.
fn routes_in_source() -> Vec<String> {
    let src = repo_root().join("server").join("src");
    let mut paths = Vec::new();
    for file in walk(&src) {
        if file.extension().is_none_or(|e| e != "rs") {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("read source");
        let mut rest = text.as_str();
        while let Some(at) = rest.find(".route(\"") {
            rest = &rest[at + 8..];
            let end = rest.find('"').expect("closing quote");
            paths.push(rest[..end].to_string());
        }
    }
    paths
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_in_the_router_is_in_the_document() {
    let doc = serde_json::to_value(isoray_server::api::openapi()).expect("document serializes");
    let paths = doc["paths"].as_object().expect("paths").clone();

    let in_source = routes_in_source();
    assert!(
        in_source.len() >= 4,
        "found the app's own routes in lib.rs: {in_source:?}"
    );
    for path in &in_source {
        assert!(
            paths.contains_key(path),
            "route `{path}` is registered in the server but missing from the OpenAPI document"
        );
    }

    // Probe the running router with every documented operation (and every other method).
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    call(move || {
        let (id, token) = create(&base);
        let r = push(&base, &id, "0", &token, NPY, &npy(&[0.0, 0.0, 0.0], 3));
        assert_eq!(r.status, 201);
        let client = Client::new(&base).expect("url");
        for (path, item) in &paths {
            let concrete = path
                .replace("{id}", &id)
                .replace("{index}", "0")
                .replace("{file}", "app.js");
            for method in METHODS {
                let documented = item.get(method).is_some();
                // DELETE would remove what later probes need; a wrong token still reaches the
                // handler, which is all this checks.
                let auth = "Bearer not-the-token";
                let r = client
                    .request(
                        &method.to_uppercase(),
                        &concrete,
                        &[
                            ("Content-Type", "application/json"),
                            ("Authorization", auth),
                        ],
                        Body::Bytes(b"{}"),
                    )
                    .expect("answer");
                let routed = r.status != 405 && !(r.status == 404 && r.body.is_empty());
                assert_eq!(
                    routed,
                    documented,
                    "{method} {path}: documented {documented}, router answered {} {}",
                    r.status,
                    r.text()
                );
            }
        }
    })
    .await;
    server.stop().await;
}
