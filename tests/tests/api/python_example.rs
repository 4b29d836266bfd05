//! The README's Python example against a fresh server: `examples/push_particles.py` creates a
//! metaball scene and pushes 100 steps of 50,000 particles as `.npy` through the Python client
//! in `clients/python` (NumPy and requests required; CI
//! installs it), while a websocket viewer opened during the run watches the animation advance.

use super::*;
use crate::e2e::support::{decode_frame, mean_abs_diff, pixel_stddev, send_json, Ws};
use futures_util::StreamExt;
use isoray_protocol::ServerMessage;
use std::io::{BufRead, BufReader, Read};
use std::process::{Command, Stdio};
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;

const PARTICLES: usize = 50_000;
const STEPS: usize = 100;
const DT: f64 = 0.02;

/// What the example printed and how it ended.
struct Run {
    success: bool,
    stdout: Vec<String>,
    stderr: String,
}

/// The next binary frame (acknowledged), or `None` if none arrives within `wait`. The wait is
/// one deadline: pings and text messages in between do not extend it.
async fn frame_within(ws: &mut Ws, wait: Duration) -> Option<crate::e2e::support::Frame> {
    let deadline = tokio::time::Instant::now() + wait;
    loop {
        let msg = tokio::time::timeout_at(deadline, ws.next())
            .await
            .ok()??
            .ok()?;
        match msg {
            Message::Binary(bytes) => {
                let frame = decode_frame(&bytes);
                send_json(
                    ws,
                    serde_json::json!({"type": "ack", "sequence": frame.header.sequence}),
                )
                .await;
                return Some(frame);
            }
            Message::Text(t) => {
                if let Ok(ServerMessage::Error(e)) = serde_json::from_str(t.as_str()) {
                    panic!("the server reported an error to the viewer: {e:?}");
                }
            }
            _ => {}
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_example_pushes_100_steps_and_a_viewer_watches_them_advance() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--min-scale", "1"]).await;
    let mut child = Command::new(python())
        .arg(repo_root().join("examples").join("push_particles.py"))
        .args(["--server", &server.base])
        .args(["--particles", &PARTICLES.to_string()])
        .args(["--steps", &STEPS.to_string()])
        .args(["--dt", &DT.to_string()])
        // A step every 80 ms, like a simulation producing output at that rate, so the run
        // lasts several of the viewer's rebuilds of a 50,000-ball state.
        .args(["--interval", "0.08"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python runs (CI installs NumPy into ISORAY_PYTHON)");
    let stdout = child.stdout.take().expect("stdout");
    let mut stderr = child.stderr.take().expect("stderr");
    let (id_tx, id_rx) = std::sync::mpsc::channel::<String>();
    let (done_tx, mut done_rx) = tokio::sync::oneshot::channel::<Run>();
    std::thread::spawn(move || {
        let mut lines = Vec::new();
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(rest) = line.strip_prefix("scene ") {
                let _ = id_tx.send(rest.split(':').next().unwrap_or("").to_string());
            }
            lines.push(line);
        }
        let mut err = String::new();
        let _ = stderr.read_to_string(&mut err);
        let status = child.wait().expect("python exits");
        let _ = done_tx.send(Run {
            success: status.success(),
            stdout: lines,
            stderr: err,
        });
    });
    let id = call(move || id_rx.recv_timeout(Duration::from_secs(120)))
        .await
        .expect("the example prints its scene id first");

    // The viewer opens while the example runs.
    let (mut ws, _) =
        tokio_tungstenite::connect_async(format!("ws://{}/api/v1/scenes/{id}/stream", server.addr))
            .await
            .expect("websocket connects");
    send_json(
        &mut ws,
        serde_json::json!({"type": "resize", "input_id": 1, "width": 96, "height": 64}),
    )
    .await;
    // (step time, image) of every frame while the example runs.
    let mut during = Vec::new();
    let run = loop {
        tokio::select! {
            run = &mut done_rx => break run.expect("the example's runner thread reports"),
            frame = frame_within(&mut ws, Duration::from_secs(120)) => {
                let f = frame.expect("frames keep coming while steps arrive");
                during.push((f.header.scene_time, f.image));
            }
        }
    };
    assert!(
        run.success,
        "the example succeeded:\n{}\n{}",
        run.stdout.join("\n"),
        run.stderr
    );
    assert!(
        run.stdout.last().is_some_and(
            |l| l.starts_with(&format!("pushed {STEPS} steps of {PARTICLES} particles"))
        ),
        "{:?}",
        run.stdout
    );

    // After the run the viewer catches up with the last step, unless a frame of it already
    // arrived during the run (the view then rests: the server sends nothing more).
    let last_time = (STEPS - 1) as f64 * DT;
    let is_last = |t: f64| (t - last_time).abs() < 1e-9;
    let last_image = match during.last() {
        Some((t, img)) if is_last(*t) => img.clone(),
        _ => loop {
            let f = frame_within(&mut ws, Duration::from_secs(60))
                .await
                .expect("a frame of the last step");
            if is_last(f.header.scene_time) {
                break f.image;
            }
        },
    };

    // What the viewer saw during the run: several different steps, in order.
    let times: Vec<f64> = during.iter().map(|(t, _)| *t).collect();
    assert!(
        times.windows(2).all(|w| w[0] <= w[1]),
        "step times never go back: {times:?}"
    );
    let mut distinct = times.clone();
    distinct.dedup();
    assert!(
        distinct.len() >= 4,
        "the viewer saw the animation advance through several steps during the run: {distinct:?}"
    );
    let pushed: Vec<f64> = (0..STEPS).map(|i| i as f64 * DT).collect();
    assert!(
        distinct
            .iter()
            .all(|t| *t == 0.0 || pushed.iter().any(|p| (p - t).abs() < 1e-9)),
        "every frame shows a pushed step's time: {distinct:?}"
    );
    let first_step = during
        .iter()
        .find(|(t, img)| *t > 0.0 && pixel_stddev(img) > 1.0)
        .expect("a frame of a step during the run");
    assert!(
        pixel_stddev(&last_image) > 5.0,
        "the last frame shows particles, not a flat fill"
    );
    let diff = mean_abs_diff(&first_step.1, &last_image);
    assert!(
        diff > 1.0,
        "the particles moved between step time {} and {last_time} (mean abs diff {diff:.2})",
        first_step.0
    );

    let base = server.base.clone();
    let listed = call(move || steps(&base, &id)).await;
    let listed = listed.as_array().expect("steps");
    assert_eq!(listed.len(), STEPS, "every step stored");
    assert!(listed
        .iter()
        .all(|s| s["primitives"] == PARTICLES as u64 && s["columns"] == 3));
    drop(ws);
    server.stop().await;
}
