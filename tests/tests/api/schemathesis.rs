//! The OpenAPI document as a contract: schemathesis (from PyPI, in `ISORAY_PYTHON`'s
//! environment; CI installs it) runs against a live server and the document it serves, with
//! every check on and all four phases, the stateful one included (create a scene, push steps,
//! render, delete). Any failure fails the test, with schemathesis's report.
//!
//! What the run is told besides the document:
//! - the admin token (`-H Authorization`), so the stateful phase may create scenes and write
//!   to them (the document says which operations need a token; schemathesis also tries each
//!   without one and with a wrong one, `ignored_auth` and `missing_required_header`);
//! - that a 422 is an accepted answer to a schema-valid request: the server answers 422 (and
//!   only then) when values that each fit the schema break a rule between them that JSON
//!   Schema cannot state and the document names in prose (eye and target differ, low below
//!   high, indices within the mesh, an isovalue inside the scene's range);
//! - to leave out the websocket route, which schemathesis cannot speak (the websocket tests
//!   cover it), and positive cases with binary bodies (`HOOKS`);
//! - `--render-rate`/`--write-rate` high enough that the run is not throttled;
//! - the ids of two empty stored scenes (a metaball and a tet scene, made before the run) for
//!   the step push and the mesh upload outside the stateful phase (`HOOKS`, `before_call`), so
//!   their generated bodies reach the body checks. Not in the stateful phase: there ids come
//!   from links, and a scenario may delete these scenes (it lists every scene), after which
//!   schemathesis would read a forced id's 404 as "created resource not found".
//!
//! The run is bounded by an example count and a fixed seed (`ISORAY_SCHEMATHESIS_SEED` and
//! `ISORAY_SCHEMATHESIS_EXAMPLES` change them), not by time, so CI runs the same cases.

use super::*;
use serde_json::Value;

const CONFIG: &str = r#"
[checks.positive_data_acceptance]
expected-statuses = ["2xx", "401", "403", "404", "409", "422", "429"]
"#;

/// Positive cases with a binary body (`.npy`, raw `ISRA`) are left out: JSON Schema cannot
/// describe those formats, so a generated one is never valid. Negative ones stay; the push and
/// mesh tests send real binary bodies.
const HOOKS: &str = r#"
import os

import schemathesis

BINARY = {"application/x-npy", "application/octet-stream"}

# Operations whose generated cases go to a stored scene made before the run (ids from the
# test, in the environment), outside the stateful phase, whose links carry real ids.
TARGETS = {
    ("PUT", "/api/v1/scenes/{id}/steps/{index}"): os.environ["ISORAY_ST_METABALLS"],
    ("PUT", "/api/v1/scenes/{id}/mesh"): os.environ["ISORAY_ST_TETS"],
}


@schemathesis.hook
def filter_case(ctx, case):
    meta = case.meta
    positive = meta is not None and meta.generation.mode.is_positive
    return not (positive and case.media_type in BINARY)


@schemathesis.hook
def before_call(ctx, case, kwargs):
    meta = case.meta
    if meta is None or meta.phase.name == "stateful" or meta.is_negative_at("path"):
        return
    target = TARGETS.get((case.operation.method.upper(), case.operation.path))
    if target is not None and isinstance(case.path_parameters, dict):
        case.path_parameters["id"] = target
"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn schemathesis_finds_nothing_against_the_served_document() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("data");
    let admin = "schemathesis-admin-token";
    let server = Server::start(
        &data,
        &[
            "--admin-token",
            admin,
            "--write-rate",
            "100000",
            "--write-burst",
            "100000",
            "--render-rate",
            "100000",
            "--render-burst",
            "100000",
            "--max-size",
            "48",
            "--default-width",
            "32",
            "--default-height",
            "24",
            "--max-step-index",
            "1000",
            "--max-ray-depth",
            "2",
            "--max-samples",
            "2",
            "--max-json-bytes",
            "262144",
            "--max-push-bytes",
            "262144",
            "--max-primitives",
            "5000",
        ],
    )
    .await;
    let base = server.base.clone();
    let work = dir.path().to_path_buf();
    let (ok, out, har) = call(move || {
        // Two empty stored scenes for the write operations: generated ids almost never
        // name a scene, so without them pushes and mesh uploads would only ever meet 404s
        // and 409s and never reach the body checks (schemathesis's "missing test data").
        let admin_auth = format!("Bearer {admin}");
        let scene = |kind: &str| {
            let r = Client::new(&base)
                .expect("url")
                .request(
                    "POST",
                    "/api/v1/scenes",
                    &[
                        ("Content-Type", "application/json"),
                        ("Authorization", &admin_auth),
                    ],
                    Body::Bytes(format!(r#"{{"kind":"{kind}","name":"st-{kind}"}}"#).as_bytes()),
                )
                .expect("create answered");
            assert_eq!(r.status, 201, "{}", r.text());
            json(&r)["scene"]["id"].as_str().expect("id").to_string()
        };
        let (balls, tets) = (scene("metaballs"), scene("tets"));
        let config = work.join("schemathesis.toml");
        std::fs::write(&config, CONFIG).expect("write config");
        std::fs::write(work.join("isoray_st_hooks.py"), HOOKS).expect("write hooks");
        let seed = std::env::var("ISORAY_SCHEMATHESIS_SEED").unwrap_or_else(|_| "1".into());
        let examples =
            std::env::var("ISORAY_SCHEMATHESIS_EXAMPLES").unwrap_or_else(|_| "15".into());
        let har_path = work.join("exchanges.har");
        let st = std::process::Command::new(python())
            .args(["-m", "schemathesis.cli", "--config-file"])
            .arg(&config)
            .arg("run")
            .arg(format!("{base}/api/v1/openapi.json"))
            .args([
                "--checks",
                "all",
                "--phases",
                "examples,coverage,fuzzing,stateful",
            ])
            .args(["--max-examples", &examples, "--seed", &seed])
            .args(["--generation-database", "none", "--workers", "2"])
            .args(["--exclude-path", "/api/v1/scenes/{id}/stream"])
            .args(["--header", &format!("Authorization: Bearer {admin}")])
            .args(["--request-timeout", "60", "--no-color"])
            .args(["--report", "har", "--report-har-path"])
            .arg(&har_path)
            .current_dir(&work)
            .env("PYTHONUTF8", "1")
            .env("PYTHONPATH", &work)
            .env("SCHEMATHESIS_HOOKS", "isoray_st_hooks")
            .env("ISORAY_ST_METABALLS", &balls)
            .env("ISORAY_ST_TETS", &tets)
            .output()
            .expect("python runs (CI installs schemathesis into ISORAY_PYTHON)");
        let out = format!(
            "{}{}",
            String::from_utf8_lossy(&st.stdout),
            String::from_utf8_lossy(&st.stderr)
        );
        let har = std::fs::read_to_string(&har_path).ok();
        (st.status.success(), out, har)
    })
    .await;
    server.stop().await;
    assert!(ok, "schemathesis found failures:\n{out}");
    assert!(
        out.contains("Stateful") && out.contains("Tested:"),
        "schemathesis ran its phases: {out}"
    );

    // The run did reach the server's core, not only its refusals: the stateful phase created
    // scenes, pushed steps, rendered and deleted (the HAR report holds every exchange).
    let har: Value = serde_json::from_str(
        &har.unwrap_or_else(|| panic!("no HAR report; schemathesis said:\n{out}")),
    )
    .expect("HAR is JSON");
    let entries = har["log"]["entries"].as_array().expect("entries").clone();
    let answered = |method: &str, path_has: &str, status: u64| {
        entries.iter().any(|e| {
            e["request"]["method"] == method
                && e["request"]["url"]
                    .as_str()
                    .is_some_and(|u| u.contains(path_has))
                && e["response"]["status"] == status
        })
    };
    assert!(
        answered("POST", "/api/v1/scenes", 201),
        "a scene was created"
    );
    assert!(answered("PUT", "/steps/", 201), "a step was pushed");
    assert!(answered("POST", "/render", 200), "an image was rendered");
    assert!(
        answered("DELETE", "/api/v1/scenes/", 204),
        "something was deleted"
    );
    assert!(
        answered("PUT", "/steps/", 401),
        "a write without a token was refused 401"
    );
}
