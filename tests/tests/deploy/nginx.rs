//! A real nginx running deploy/nginx/isoray.conf (only its addresses changed) in front of
//! three `isoray` processes, one per shard the file names. Scenes created through the load
//! balancer land on every process; every later request for a scene (pushes of steps, a
//! 1.6 MB `.npy` among them, step listings, websocket viewers) reaches the process that
//! created it, which the processes' own listings and nginx's access log both show; viewers
//! opened through nginx receive frames of the pushed steps. Then one process is killed: its
//! scenes fail with a clear 503 while the others' keep taking pushes and streaming, and new
//! scenes are still created (on the live ones).

use super::{free_port, Backend, Nginx};
use crate::api::{call, json, npy, push, NPY};
use crate::e2e::support::{decode_frame, send_json, Ws};
use futures_util::StreamExt;
use isoray_protocol::ServerMessage;
use isoray_server::api::client::{Body, Client, Response};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;

const SCENES: usize = 12;
pub(super) const WAIT: Duration = Duration::from_secs(30);

/// The shipped file: deploy/nginx/isoray.conf.
pub(crate) fn shipped_conf() -> String {
    let path = crate::api::repo_root().join("deploy/nginx/isoray.conf");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// `upstream isoray_shard_NAME { server ADDR; }` blocks: shard name → address, in order.
pub(crate) fn shards_of(conf: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut lines = conf.lines().map(str::trim);
    while let Some(line) = lines.next() {
        let Some(rest) = line.strip_prefix("upstream isoray_shard_") else {
            continue;
        };
        let name = rest.trim_end_matches('{').trim().to_string();
        let server = lines
            .find(|l| l.starts_with("server "))
            .expect("a server line in the shard's upstream");
        let addr = server["server ".len()..]
            .trim_end_matches(';')
            .trim()
            .to_string();
        out.push((name, addr));
    }
    out
}

/// `text` with `from` replaced by `to`, which must occur exactly `times` times.
pub(super) fn replace_exactly(text: &str, from: &str, to: &str, times: usize) -> String {
    assert_eq!(
        text.matches(from).count(),
        times,
        "`{from}` occurs {times} times in deploy/nginx/isoray.conf"
    );
    text.replace(from, to)
}

pub(super) fn request(base: &str, method: &str, path: &str, body: &[u8]) -> Response {
    let headers: &[(&str, &str)] = if body.is_empty() {
        &[]
    } else {
        &[("Content-Type", "application/json")]
    };
    Client::new(base)
        .expect("url")
        .request(method, path, headers, Body::Bytes(body))
        .expect("an answer")
}

/// `n` balls of one step as JSON, placed by `seed`.
pub(super) fn json_step(n: usize, seed: usize) -> Vec<u8> {
    let positions: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let a = (i + seed) as f64 * 0.7;
            [a.cos() * 0.8, (i as f64 * 0.3).sin() * 0.5, a.sin() * 0.8]
        })
        .collect();
    serde_json::json!({ "positions": positions, "radii": vec![0.6; n] })
        .to_string()
        .into_bytes()
}

/// Opens a viewer through `base`, checks `info`, and asks for small frames.
pub(super) async fn open_viewer(base: &str, id: &str) -> Ws {
    let url = format!(
        "{}/api/v1/scenes/{id}/stream",
        base.replace("http://", "ws://")
    );
    let (mut ws, _) = tokio::time::timeout(WAIT, tokio_tungstenite::connect_async(url))
        .await
        .expect("connects in time")
        .unwrap_or_else(|e| panic!("viewer of {id} through nginx: {e}"));
    let first = tokio::time::timeout(WAIT, ws.next())
        .await
        .expect("info in time")
        .expect("open")
        .expect("no error");
    let Message::Text(text) = first else {
        panic!("info first, got {first:?}")
    };
    match serde_json::from_str::<ServerMessage>(text.as_str()).expect("a server message") {
        ServerMessage::Info(info) => assert_eq!(info.scene.id, id),
        other => panic!("info first, got {other:?}"),
    }
    send_json(
        &mut ws,
        serde_json::json!({"type": "resize", "input_id": 1, "width": 48, "height": 32}),
    )
    .await;
    ws
}

/// Reads frames (acknowledging each) until one shows scene time `time`.
pub(super) async fn frame_at_time(ws: &mut Ws, id: &str, time: f64) {
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let msg = tokio::time::timeout_at(deadline, ws.next())
            .await
            .unwrap_or_else(|_| panic!("{id}: no frame of time {time} in time"))
            .expect("stream open")
            .expect("no websocket error");
        if let Message::Binary(bytes) = msg {
            let frame = decode_frame(&bytes);
            send_json(
                ws,
                serde_json::json!({"type": "ack", "sequence": frame.header.sequence}),
            )
            .await;
            if frame.header.scene_time == time {
                return;
            }
        }
    }
}

/// The stored scenes a process holds, asked directly (not through nginx).
fn stored_ids(base: &str) -> BTreeSet<String> {
    let r = request(base, "GET", "/api/v1/scenes", b"");
    assert_eq!(r.status, 200);
    json(&r)["scenes"]
        .as_array()
        .expect("scenes")
        .iter()
        .filter(|s| s["source"] == "stored")
        .map(|s| s["id"].as_str().expect("id").to_string())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nginx_routes_every_scene_to_the_process_that_holds_it() {
    let conf = shipped_conf();
    let shards = shards_of(&conf);
    let names: Vec<&str> = shards.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        ["s0", "s1", "s2"],
        "deploy/nginx/isoray.conf names three shards"
    );

    // One process per shard, each with its own store, as deploy/ says.
    let dirs: Vec<tempfile::TempDir> = shards
        .iter()
        .map(|_| tempfile::tempdir().expect("temp dir"))
        .collect();
    let backends: Vec<Backend> = shards
        .iter()
        .zip(&dirs)
        .map(|((name, _), dir)| {
            Backend::start(&[
                "--shard",
                name,
                "--data-dir",
                dir.path().to_str().expect("utf-8 path"),
                "--threads",
                "1",
                "--default-width",
                "48",
                "--default-height",
                "32",
            ])
        })
        .collect();

    // The shipped file with the test's addresses: each shard's address is in its own upstream
    // and in `isoray_any`; nginx listens on a free loopback port.
    let port = free_port();
    let mut test_conf = replace_exactly(
        &conf,
        "listen 8080;",
        &format!("listen 127.0.0.1:{port};"),
        1,
    );
    for ((_, shipped_addr), backend) in shards.iter().zip(&backends) {
        test_conf = replace_exactly(
            &test_conf,
            &format!("{shipped_addr};"),
            &format!("{};", backend.addr),
            2,
        );
    }
    let lb = Nginx::start(&test_conf, port);
    let lb_base = lb.base.clone();

    // Create scenes and push a step to each, all through nginx.
    let created: Vec<(String, String, f64)> = call({
        let lb = lb_base.clone();
        move || {
            (0..SCENES)
                .map(|k| {
                    let r = request(&lb, "POST", "/api/v1/scenes", br#"{"kind":"metaballs"}"#);
                    assert_eq!(r.status, 201, "create through nginx: {}", r.text());
                    let v = json(&r);
                    let id = v["scene"]["id"].as_str().expect("id").to_string();
                    let token = v["write_token"].as_str().expect("token").to_string();
                    let time = 1.5 + k as f64;
                    let r = push(
                        &lb,
                        &id,
                        &format!("0?time={time}"),
                        &token,
                        "application/json",
                        &json_step(3 + k % 4, k),
                    );
                    assert_eq!(r.status, 201, "push through nginx: {}", r.text());
                    (id, token, time)
                })
                .collect()
        }
    })
    .await;

    let shard_of = |id: &str| -> usize {
        names
            .iter()
            .position(|n| id.starts_with(&format!("{n}_")))
            .unwrap_or_else(|| panic!("id {id} names one of the shards {names:?}"))
    };
    let mut per_shard = vec![Vec::new(); shards.len()];
    for (id, _, _) in &created {
        per_shard[shard_of(id)].push(id.clone());
    }
    for (k, ids) in per_shard.iter().enumerate() {
        assert!(
            ids.len() >= SCENES / 4,
            "creation spreads over the processes: shard {} got {} of {SCENES}",
            names[k],
            ids.len()
        );
    }
    println!(
        "scenes per shard: {:?}",
        per_shard.iter().map(Vec::len).collect::<Vec<_>>()
    );

    // A 1.6 MB `.npy` step through nginx (bodies are not capped at nginx's default 1 MB).
    let (big_id, big_token, _) = created[0].clone();
    let values: Vec<f32> = (0..100_000)
        .flat_map(|i| {
            let a = i as f32 * 0.001;
            [a.cos(), a.sin(), (a * 3.0).sin() * 0.2, 0.05]
        })
        .collect();
    let r = call({
        let lb = lb_base.clone();
        let id = big_id.clone();
        move || push(&lb, &id, "1?time=100", &big_token, NPY, &npy(&values, 4))
    })
    .await;
    assert_eq!(r.status, 201, "large push through nginx: {}", r.text());

    // Each process holds exactly the scenes whose id names it, with their steps.
    let holdings: Vec<BTreeSet<String>> = call({
        let bases: Vec<String> = backends.iter().map(|b| b.base.clone()).collect();
        move || bases.iter().map(|b| stored_ids(b)).collect()
    })
    .await;
    for (k, held) in holdings.iter().enumerate() {
        let expected: BTreeSet<String> = per_shard[k].iter().cloned().collect();
        assert_eq!(
            held, &expected,
            "process {} holds its shard's scenes",
            names[k]
        );
    }
    let steps = call({
        let base = backends[shard_of(&big_id)].base.clone();
        let id = big_id.clone();
        move || {
            json(&request(
                &base,
                "GET",
                &format!("/api/v1/scenes/{id}/steps"),
                b"",
            ))
        }
    })
    .await;
    let rows: Vec<u64> = steps["steps"]
        .as_array()
        .expect("steps")
        .iter()
        .map(|s| s["primitives"].as_u64().expect("primitives"))
        .collect();
    assert_eq!(
        rows,
        [3, 100_000],
        "both pushes are on the creating process"
    );

    // A request sent straight to the wrong process says it was misrouted.
    let (other_id, _, _) = created
        .iter()
        .find(|(id, _, _)| shard_of(id) == 1)
        .expect("a scene of shard 1")
        .clone();
    let r = call({
        let base = backends[0].base.clone();
        let id = other_id.clone();
        move || request(&base, "GET", &format!("/api/v1/scenes/{id}"), b"")
    })
    .await;
    assert_eq!(r.status, 421, "{}", r.text());
    assert_eq!(json(&r)["code"], "misrouted");

    // A viewer of every scene, through nginx, receives a frame of its pushed step.
    let mut viewers = Vec::new();
    for (id, _, time) in &created {
        let mut ws = open_viewer(&lb_base, id).await;
        let expected = if *id == big_id { 100.0 } else { *time };
        frame_at_time(&mut ws, id, expected).await;
        viewers.push((id.clone(), ws));
    }
    // Close all but one viewer per shard, so their requests reach the access log.
    let mut kept: BTreeMap<usize, (String, Ws)> = BTreeMap::new();
    for (id, mut ws) in viewers {
        match kept.entry(shard_of(&id)) {
            std::collections::btree_map::Entry::Occupied(_) => {
                let _ = ws.close(None).await;
            }
            std::collections::btree_map::Entry::Vacant(slot) => {
                slot.insert((id, ws));
            }
        }
    }
    tokio::time::sleep(Duration::from_millis(300)).await;

    // nginx's own record: every request for a scene went to the one process of its shard.
    let log = lb.access_log();
    let mut seen: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in log.lines() {
        let Some(path_at) = line.find("/api/v1/scenes/") else {
            continue;
        };
        let id: String = line[path_at + "/api/v1/scenes/".len()..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == '-')
            .collect();
        let addr = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix("addr="))
            .unwrap_or_else(|| panic!("addr= in {line}"));
        seen.entry(id).or_default().insert(addr.to_string());
    }
    for (id, _, _) in &created {
        let addrs = seen
            .get(id)
            .unwrap_or_else(|| panic!("{id} is in the access log:\n{log}"));
        let owner = &backends[shard_of(id)].addr;
        assert_eq!(
            addrs,
            &BTreeSet::from([owner.clone()]),
            "every request for {id} went to {owner}"
        );
    }
    let stream_lines = log.lines().filter(|l| l.contains("/stream ")).count();
    assert!(
        stream_lines >= SCENES - shards.len(),
        "the closed viewers are logged: {stream_lines}"
    );

    // Kill the process of shard 1.
    let mut backends = backends;
    let dead = backends.remove(1);
    dead.kill();
    let (live_ws_id, mut live_ws) = kept.remove(&0).expect("a viewer of shard 0");
    drop(kept);

    // Its scenes fail clearly: 503 with a JSON reason, for the API and for viewers.
    let r = call({
        let lb = lb_base.clone();
        let id = other_id.clone();
        move || request(&lb, "GET", &format!("/api/v1/scenes/{id}/steps"), b"")
    })
    .await;
    assert_eq!(r.status, 503, "{}", r.text());
    let body: Value = json(&r);
    assert_eq!(body["code"], "backend_unavailable", "{body}");
    assert!(
        body["message"]
            .as_str()
            .expect("message")
            .contains("isoray_shard_s1"),
        "{body}"
    );
    let (dead_id, dead_token, _) = created
        .iter()
        .find(|(id, _, _)| shard_of(id) == 1)
        .expect("a scene of shard 1")
        .clone();
    let r = call({
        let lb = lb_base.clone();
        move || {
            push(
                &lb,
                &dead_id,
                "1",
                &dead_token,
                "application/json",
                &json_step(3, 9),
            )
        }
    })
    .await;
    assert_eq!(r.status, 503, "a push to the dead shard: {}", r.text());
    let url = format!(
        "{}/api/v1/scenes/{other_id}/stream",
        lb_base.replace("http://", "ws://")
    );
    match tokio_tungstenite::connect_async(url).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => assert_eq!(r.status(), 503),
        other => panic!("a viewer of the dead shard is refused with 503: {other:?}"),
    }

    // The live process's scenes keep working: a new step reaches the viewer that stayed
    // open across the failure, and a new viewer.
    let (live_id, live_token, _) = created
        .iter()
        .find(|(id, _, _)| *id == live_ws_id)
        .expect("the kept viewer's scene")
        .clone();
    let r = call({
        let lb = lb_base.clone();
        let id = live_id.clone();
        move || {
            push(
                &lb,
                &id,
                "7?time=77",
                &live_token,
                "application/json",
                &json_step(5, 3),
            )
        }
    })
    .await;
    assert_eq!(r.status, 201, "push to the live shard: {}", r.text());
    frame_at_time(&mut live_ws, &live_id, 77.0).await;
    let mut fresh = open_viewer(&lb_base, &live_id).await;
    frame_at_time(&mut fresh, &live_id, 77.0).await;

    // New scenes are still created, all on the live processes.
    let ids: Vec<String> = call({
        let lb = lb_base.clone();
        move || {
            (0..3)
                .map(|_| {
                    let r = request(&lb, "POST", "/api/v1/scenes", br#"{"kind":"metaballs"}"#);
                    assert_eq!(r.status, 201, "create with one process down: {}", r.text());
                    json(&r)["scene"]["id"].as_str().expect("id").to_string()
                })
                .collect()
        }
    })
    .await;
    for id in &ids {
        assert_ne!(shard_of(id), 1, "{id} was created by a live process");
    }
    let _ = live_ws.close(None).await;
    let _ = fresh.close(None).await;
}

/// Tokens in URLs (`?token=` on the websocket, which a browser cannot authorize otherwise)
/// do not reach nginx's access log; the path still does.
#[test]
fn nginx_access_log_redacts_tokens() {
    let conf = shipped_conf();
    let port = free_port();
    let mut test_conf = replace_exactly(
        &conf,
        "listen 8080;",
        &format!("listen 127.0.0.1:{port};"),
        1,
    );
    // No process behind it: the requests get nginx's 503, and are logged all the same.
    for (_, shipped_addr) in shards_of(&conf) {
        let nobody = format!("127.0.0.1:{};", free_port());
        test_conf = replace_exactly(&test_conf, &format!("{shipped_addr};"), &nobody, 2);
    }
    let lb = Nginx::start(&test_conf, port);
    let secret = "SeCrEt%2B0123456789";
    let paths = [
        format!("/api/v1/scenes/blobs/stream?token={secret}"),
        format!("/api/v1/scenes/blobs/stream?reproject=off&token={secret}&x=1"),
        format!("/?scene=blobs&token={secret}"),
    ];
    for path in &paths {
        let r = request(&lb.base, "GET", path, b"");
        assert_eq!(r.status, 503, "{path}: {}", r.text());
    }
    // nginx writes a line once it has finished the request: wait for all three.
    let deadline = std::time::Instant::now() + WAIT;
    let log = loop {
        let log = lb.access_log();
        if log.lines().count() >= paths.len() {
            break log;
        }
        assert!(std::time::Instant::now() < deadline, "3 lines in:\n{log}");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(
        !log.contains("SeCrEt"),
        "a token is in the access log:\n{log}"
    );
    assert_eq!(
        log.matches("/api/v1/scenes/blobs/stream").count(),
        2,
        "the paths are logged:\n{log}"
    );
}
