//! Kill-and-restart cycles during pushes: one `isoray` process on a fixed loopback port, a
//! pusher adding `.npy` steps of varying size (up to 640 KB) to a stored scene, and viewers
//! streaming it. Each cycle SIGKILLs the process at a seeded random moment (after a random
//! number of the cycle's pushes completed, with others still to send or in flight), restarts
//! it on the same store and port, and checks that
//! - every viewer saw its connection end, reconnected and received a frame again;
//! - every step whose push got a 2xx is listed with the checksum of what was sent;
//!
//! and at the end every completed step's data is read back byte for byte, and no temporary
//! file is left. It prints the figures: faults injected, sessions recovered, completed steps
//! lost (must be 0).
//!
//! CI runs 3 cycles; `deploy/local/faults.sh` runs 20 (`ISORAY_FAULT_CYCLES`, and
//! `ISORAY_FAULT_SEED` for another sequence of moments).

use super::{free_port, Backend};
use crate::api::{json, npy, temp_files};
use crate::e2e::support::decode_frame;
use futures_util::{SinkExt, StreamExt};
use isoray_server::api::client::{npy_header_f32, Body, Client, ClientError};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;

const WAIT: Duration = Duration::from_secs(90);
const VIEWERS: usize = 2;

/// SplitMix64: the seeded moments and step sizes.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .map(|v| {
            v.parse()
                .unwrap_or_else(|_| panic!("{name}={v} is not a number"))
        })
        .unwrap_or(default)
}

/// The balls of step `index`: between 2,000 and 40,000 rows of small balls.
fn step_values(index: u64) -> Vec<f32> {
    let mut rng = Rng(index.wrapping_mul(0xA076_1D64_78BD_642F) ^ 0x5EED);
    let rows = 2_000 + (rng.next() % 38_000) as usize;
    let mut v = Vec::with_capacity(rows * 4);
    for _ in 0..rows {
        let mut u = || (rng.next() % 1_000_000) as f32 / 1_000_000.0;
        v.extend_from_slice(&[
            3.0 * u() - 1.5,
            3.0 * u() - 1.5,
            3.0 * u() - 1.5,
            0.01 + 0.03 * u(),
        ]);
    }
    v
}

/// What the pusher knows: the steps whose push got a 2xx (index → little-endian values and
/// their XXH3-128); attempts cut by a kill (sent, then no answer) and attempts refused while
/// the process was down.
#[derive(Default)]
struct Ledger {
    completed: BTreeMap<u64, (Vec<u8>, String)>,
    cut: u64,
    refused: u64,
}

/// One viewer's history: connections opened, frames on the current one, connections ended.
#[derive(Default, Clone, Copy)]
struct ViewerLog {
    connections: u64,
    frames_on_current: u64,
    ends: u64,
}

/// Pushes steps 0, 1, 2... while fewer than `granted` completed, retrying an index whose
/// push got no answer (the process was killed) until it gets one.
fn pusher(
    base: String,
    id: String,
    token: String,
    ledger: Arc<Mutex<Ledger>>,
    granted: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
) {
    let auth = format!("Bearer {token}");
    let mut index = ledger.lock().expect("ledger").completed.len() as u64;
    while !stop.load(Ordering::SeqCst) {
        if index >= granted.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(5));
            continue;
        }
        let values = step_values(index);
        let body = npy(&values, 4);
        let answer = Client::new(&base).expect("url").request(
            "PUT",
            &format!("/api/v1/scenes/{id}/steps/{index}"),
            &[("Content-Type", crate::api::NPY), ("Authorization", &auth)],
            Body::Bytes(&body),
        );
        match answer {
            Ok(r) if r.status == 200 || r.status == 201 => {
                let payload: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
                let checksum = format!("{:032x}", xxhash_rust::xxh3::xxh3_128(&payload));
                assert_eq!(
                    json(&r)["step"]["checksum"],
                    checksum.as_str(),
                    "step {index}: the server's checksum is that of what was sent"
                );
                ledger
                    .lock()
                    .expect("ledger")
                    .completed
                    .insert(index, (payload, checksum));
                index += 1;
            }
            Ok(r) => panic!("push of step {index}: {} {}", r.status, r.text()),
            Err(e) => {
                // No answer: killed mid-push, or not yet restarted. The same index again.
                let refused = matches!(
                    &e,
                    ClientError::Io(io) if io.kind() == std::io::ErrorKind::ConnectionRefused
                );
                let mut l = ledger.lock().expect("ledger");
                if refused {
                    l.refused += 1;
                } else {
                    l.cut += 1;
                }
                drop(l);
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }
}

/// Watches `url`, acknowledging frames, and reconnects whenever the connection ends.
async fn viewer(url: String, log: Arc<Mutex<ViewerLog>>, stop: Arc<AtomicBool>) {
    while !stop.load(Ordering::SeqCst) {
        let Ok(Ok((mut ws, _))) = tokio::time::timeout(
            Duration::from_secs(10),
            tokio_tungstenite::connect_async(&url),
        )
        .await
        else {
            tokio::time::sleep(Duration::from_millis(20)).await;
            continue;
        };
        {
            let mut l = log.lock().expect("viewer log");
            l.connections += 1;
            l.frames_on_current = 0;
        }
        let resize =
            serde_json::json!({"type": "resize", "input_id": 1, "width": 32, "height": 24});
        let mut open = ws
            .send(Message::Text(resize.to_string().into()))
            .await
            .is_ok();
        while open {
            // Checked before every read: an acknowledging viewer of a live scene gets frames
            // back to back, so a read never times out and could not notice `stop` there
            // (that hung this test on an idle machine).
            if stop.load(Ordering::SeqCst) {
                let _ = tokio::time::timeout(Duration::from_secs(5), ws.close(None)).await;
                return;
            }
            // The timeout only bounds the wait, so that `stop` is noticed while idle too.
            match tokio::time::timeout(Duration::from_millis(200), ws.next()).await {
                Err(_) => {}
                Ok(Some(Ok(Message::Binary(bytes)))) => {
                    let sequence = decode_frame(&bytes).header.sequence;
                    log.lock().expect("viewer log").frames_on_current += 1;
                    let ack = serde_json::json!({"type": "ack", "sequence": sequence});
                    open = ws.send(Message::Text(ack.to_string().into())).await.is_ok();
                }
                Ok(Some(Ok(_))) => {}
                Ok(Some(Err(_)) | None) => open = false,
            }
        }
        log.lock().expect("viewer log").ends += 1;
    }
}

/// Waits (polling) until `done` holds, or fails naming `what`.
fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + WAIT;
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting: {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn logs(viewers: &[Arc<Mutex<ViewerLog>>]) -> Vec<ViewerLog> {
    viewers
        .iter()
        .map(|v| *v.lock().expect("viewer log"))
        .collect()
}

/// Completed steps that the process at `base` does not list with their checksum.
fn lost_steps(base: &str, id: &str, ledger: &Mutex<Ledger>) -> Vec<u64> {
    let completed: Vec<(u64, String)> = ledger
        .lock()
        .expect("ledger")
        .completed
        .iter()
        .map(|(i, (_, c))| (*i, c.clone()))
        .collect();
    let listed = crate::api::step_checksums(&crate::api::steps(base, id));
    completed
        .into_iter()
        .filter(|(i, c)| listed.get(i) != Some(c))
        .map(|(i, _)| i)
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigkill_and_restart_cycles_during_pushes_lose_no_completed_step() {
    let cycles = env_u64("ISORAY_FAULT_CYCLES", 3);
    let seed = env_u64("ISORAY_FAULT_SEED", 15);
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().to_str().expect("utf-8 path").to_string();
    let listen = format!("127.0.0.1:{}", free_port());
    let args = [
        "--data-dir",
        &data,
        "--threads",
        "1",
        "--default-width",
        "32",
        "--default-height",
        "24",
    ]
    .map(String::from);
    let start = {
        let listen = listen.clone();
        move || {
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            Backend::start_on(&listen, &args)
        }
    };

    let backend = crate::api::call(start.clone()).await;
    let base = backend.base.clone();
    let (id, token) = crate::api::call({
        let base = base.clone();
        move || crate::api::create(&base)
    })
    .await;

    let ledger = Arc::new(Mutex::new(Ledger::default()));
    let granted = Arc::new(AtomicU64::new(1));
    let stop = Arc::new(AtomicBool::new(false));
    let pushing = std::thread::spawn({
        let (base, id, token) = (base.clone(), id.clone(), token.clone());
        let (ledger, granted, stop) = (ledger.clone(), granted.clone(), stop.clone());
        move || pusher(base, id, token, ledger, granted, stop)
    });
    let url = format!(
        "{}/api/v1/scenes/{id}/stream",
        base.replace("http://", "ws://")
    );
    let viewer_logs: Vec<Arc<Mutex<ViewerLog>>> = (0..VIEWERS)
        .map(|_| Arc::new(Mutex::new(ViewerLog::default())))
        .collect();
    let viewer_tasks: Vec<_> = viewer_logs
        .iter()
        .map(|log| tokio::spawn(viewer(url.clone(), log.clone(), stop.clone())))
        .collect();

    let figures = crate::api::call({
        let (ledger, granted, viewer_logs) = (ledger.clone(), granted.clone(), viewer_logs.clone());
        let id = id.clone();
        move || {
            let mut rng = Rng(seed);
            let mut backend = backend;
            let mut recovered = 0u64;
            let mut lost = Vec::new();
            // Viewers connected before the first cycle count from zero.
            let mut connections_at_restart = vec![0u64; VIEWERS];
            for cycle in 0..cycles {
                // Grant this cycle's pushes; the kill comes after `k` of them completed.
                let done = ledger.lock().expect("ledger").completed.len() as u64;
                let credits = 3 + rng.next() % 5;
                let k = rng.next() % credits;
                granted.store(done + credits, Ordering::SeqCst);
                wait_until(
                    &format!("cycle {cycle}: {k} pushes complete and every viewer has a frame"),
                    || {
                        ledger.lock().expect("ledger").completed.len() as u64 >= done + k
                            && logs(&viewer_logs)
                                .iter()
                                .zip(&connections_at_restart)
                                .all(|(l, &c)| l.connections > c && l.frames_on_current >= 1)
                    },
                );
                // The seeded moment within the pushes in flight.
                std::thread::sleep(Duration::from_millis(rng.next() % 30));
                let ends_before: Vec<u64> = logs(&viewer_logs).iter().map(|l| l.ends).collect();
                backend.kill();

                // Every viewer sees its connection end.
                wait_until(&format!("cycle {cycle}: viewers see the close"), || {
                    logs(&viewer_logs)
                        .iter()
                        .zip(&ends_before)
                        .all(|(l, &e)| l.ends > e)
                });
                connections_at_restart = logs(&viewer_logs).iter().map(|l| l.connections).collect();
                backend = start();

                // Every completed step is there with its checksum.
                let missing = lost_steps(&backend.base, &id, &ledger);
                assert!(
                    missing.is_empty(),
                    "cycle {cycle}: completed steps missing or changed after the restart: {missing:?}"
                );
                lost.extend(missing);

                // Every viewer reconnects and receives a frame again.
                wait_until(&format!("cycle {cycle}: viewers recover"), || {
                    logs(&viewer_logs)
                        .iter()
                        .zip(&connections_at_restart)
                        .all(|(l, &c)| l.connections > c && l.frames_on_current >= 1)
                });
                recovered += VIEWERS as u64;
            }
            // Let the last cycle's pushes finish, then read every step back byte for byte.
            let target = granted.load(Ordering::SeqCst);
            wait_until("the last pushes complete", || {
                ledger.lock().expect("ledger").completed.len() as u64 >= target
            });
            (backend, recovered, lost)
        }
    })
    .await;
    stop.store(true, Ordering::SeqCst);
    pushing.join().expect("the pusher did not panic");
    for task in viewer_tasks {
        tokio::time::timeout(WAIT, task)
            .await
            .expect("viewers stop")
            .expect("no viewer panicked");
    }
    let (backend, recovered, mut lost) = figures;

    let ledger = Arc::try_unwrap(ledger)
        .ok()
        .expect("the pusher is done")
        .into_inner()
        .expect("ledger");
    let base = backend.base.clone();
    let (ledger, mismatched) = crate::api::call(move || {
        let mut mismatched = Vec::new();
        for (index, (payload, _)) in &ledger.completed {
            let r = crate::api::get(&base, &format!("/api/v1/scenes/{id}/steps/{index}/data"));
            let header = npy_header_f32((payload.len() / 16) as u64, 4).len();
            if r.status != 200 || r.body.get(header..) != Some(&payload[..]) {
                mismatched.push(*index);
            }
        }
        (ledger, mismatched)
    })
    .await;
    lost.extend(mismatched);
    let leftovers = temp_files(dir.path());
    println!(
        "kill-and-restart: seed {seed}: faults injected {cycles}, sessions recovered {recovered} \
         (of {}), completed steps lost {} ({} steps completed; push attempts cut by a kill {}, \
         refused while down {})",
        cycles * VIEWERS as u64,
        lost.len(),
        ledger.completed.len(),
        ledger.cut,
        ledger.refused
    );
    assert!(lost.is_empty(), "completed steps lost: {lost:?}");
    assert_eq!(recovered, cycles * VIEWERS as u64);
    assert!(
        leftovers.is_empty(),
        "no temporary file once the pushes are done: {leftovers:?}"
    );
    backend.kill();
}
