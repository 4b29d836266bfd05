//! `/metrics` exposes what operators need: sessions, frames, bytes, stage times, latency.

use super::stream::reqwest_like_get;
use super::support::*;
use serde_json::json;

/// The value of the first sample line of `name` with all of `labels`, if any.
pub(super) fn sample(text: &str, name: &str, labels: &[&str]) -> Option<f64> {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .find(|l| l.starts_with(name) && labels.iter().all(|lab| l.contains(lab)))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_count_what_a_session_did() {
    let server = TestServer::start(&["--still-after-ms", "50"]).await;
    let (mut ws, _) = server.connect("blobs").await;
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 1.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 48, "height": 32}),
    )
    .await;
    for id in 3..8u64 {
        send_json(
            &mut ws,
            json!({"type": "isovalue", "input_id": id, "value": 0.3 + id as f64 * 0.05}),
        )
        .await;
        frame_for_input(&mut ws, id).await;
    }
    send_text(&mut ws, "not json").await;
    next_error(&mut ws).await;

    let text = reqwest_like_get(server.addr, "/metrics").await;
    let open = sample(&text, "isoray_sessions", &[]).expect("sessions gauge");
    assert!(open >= 1.0, "{text}");
    let jpeg =
        sample(&text, "isoray_frames_sent_total", &["codec=\"jpeg\""]).expect("frame counter");
    assert!(jpeg >= 5.0, "five inputs, five frames at least: {jpeg}");
    assert!(sample(&text, "isoray_frame_bytes_total", &[]).expect("bytes") > 0.0);
    let traced =
        sample(&text, "isoray_stage_seconds_count", &["stage=\"trace\""]).expect("trace histogram");
    assert!(traced >= 5.0);
    let on_cpu = sample(&text, "isoray_frames_traced_total", &["on=\"cpu\""]).expect("cpu frames");
    assert!(
        on_cpu >= 5.0,
        "the CPU backend's frames are counted: {on_cpu}"
    );
    let latency =
        sample(&text, "isoray_input_to_frame_seconds_count", &[]).expect("latency histogram");
    assert!(latency >= 5.0, "every answered input is timed: {latency}");
    assert!(sample(&text, "isoray_inputs_rejected_total", &[]).expect("rejections") >= 1.0);
    for (name, labels) in [
        (
            "isoray_frames_dropped_total",
            &["reason=\"session_end\""][..],
        ),
        ("isoray_render_queue_depth", &[]),
        ("isoray_render_jobs_running", &[]),
        ("isoray_depth_bytes_total", &[]),
        (
            "isoray_root_finder_capped_total",
            &["kind=\"metaballs\""][..],
        ),
        ("isoray_root_finder_capped_total", &["kind=\"surfels\""][..]),
    ] {
        assert!(
            sample(&text, name, labels).is_some(),
            "{name} missing:\n{text}"
        );
    }
    let waits = sample(&text, "isoray_render_queue_wait_seconds_count", &[]).expect("queue wait");
    assert!(
        waits >= 5.0,
        "every frame's wait in the render queue is timed: {waits}"
    );
    let built = sample(
        &text,
        "isoray_scene_states_built_total",
        &["scene=\"blobs\""],
    )
    .expect("states built");
    assert!(built >= 1.0);
    drop(ws);
    server.stop().await;
}

/// `/metrics` needs `--metrics-token` when it is set (and only that token); the series of
/// states built do not grow with the number of pushed scenes (no label per stored scene).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_have_their_own_token_and_bounded_series() {
    use isoray_server::api::client::{Body, Client};
    const METRICS: &str = "metrics-token-0123456789";
    const VIEW: &str = "view-token-0123456789";
    let server = TestServer::start(&["--metrics-token", METRICS, "--view-token", VIEW]).await;
    let base = format!("http://{}", server.addr);
    call_blocking(move || {
        let c = Client::new(&base).expect("url");
        let get = |token: Option<&str>| {
            let auth = token.map(|t| format!("Bearer {t}"));
            let headers: Vec<(&str, &str)> = auth
                .as_deref()
                .map(|a| ("Authorization", a))
                .into_iter()
                .collect();
            c.request("GET", "/metrics", &headers, Body::Empty)
                .expect("answer")
        };
        assert_eq!(get(None).status, 401);
        assert_eq!(
            get(Some(VIEW)).status,
            403,
            "the view token is not the metrics token"
        );
        let r = get(Some(METRICS));
        assert_eq!(r.status, 200, "{}", r.text());

        // A stored scene, one step, one render: its state is built and counted, without its id.
        let auth = format!("Bearer {VIEW}");
        let r = c
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"kind":"metaballs"}"#),
            )
            .expect("create");
        assert_eq!(r.status, 201, "{}", r.text());
        let v: serde_json::Value = serde_json::from_slice(&r.body).expect("json");
        let id = v["scene"]["id"].as_str().expect("id").to_string();
        let write = format!("Bearer {}", v["write_token"].as_str().expect("token"));
        let r = c
            .request(
                "PUT",
                &format!("/api/v1/scenes/{id}/steps/0"),
                &[
                    ("Content-Type", "application/json"),
                    ("Authorization", &write),
                ],
                Body::Bytes(br#"{"positions":[[0,0,0],[0.5,0,0]],"radii":[0.6,0.6]}"#),
            )
            .expect("push");
        assert_eq!(r.status, 201, "{}", r.text());
        let r = c
            .request(
                "POST",
                &format!("/api/v1/scenes/{id}/render"),
                &[
                    ("Content-Type", "application/json"),
                    ("Authorization", &auth),
                ],
                Body::Bytes(br#"{"width":16,"height":16}"#),
            )
            .expect("render");
        assert_eq!(r.status, 200, "{}", r.text());
        let text = get(Some(METRICS)).text();
        assert!(
            sample(
                &text,
                "isoray_scene_states_built_total",
                &["scene=\"stored\""]
            )
            .is_some_and(|n| n >= 1.0),
            "stored scenes' builds are counted together:\n{text}"
        );
        assert!(
            !text.contains(&id),
            "no series is labelled with a stored scene's id:\n{text}"
        );
    })
    .await;
    server.stop().await;
}

async fn call_blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f).await.expect("client thread")
}
