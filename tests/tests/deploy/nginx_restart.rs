//! One of three processes behind nginx (deploy/nginx/isoray.conf) is SIGKILLed while it
//! streams to a viewer and takes pushes, then restarted on its address and store: its viewer
//! sees the connection end and, reconnecting through nginx after the restart, receives frames
//! again; every step whose push got a 2xx is listed with the checksum it was stored with; the
//! other processes' viewers stay on their first connection throughout and keep receiving
//! frames of steps pushed during the outage and after it.

use super::nginx::{
    frame_at_time, json_step, open_viewer, replace_exactly, request, shards_of, shipped_conf, WAIT,
};
use super::{free_port, Backend, Nginx};
use crate::api::{call, json, push};
use futures_util::StreamExt;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;

/// Steps pushed to the victim scene: index → checksum from the 2xx answer; and how many
/// attempts failed (nginx's 503/502 while the process was down).
#[derive(Default)]
struct Pushed {
    completed: BTreeMap<u64, String>,
    failed: u64,
}

fn backend_args<'a>(name: &'a str, dir: &'a str) -> [&'a str; 10] {
    [
        "--shard",
        name,
        "--data-dir",
        dir,
        "--threads",
        "1",
        "--default-width",
        "48",
        "--default-height",
        "32",
    ]
}

fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + WAIT;
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting: {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_process_killed_behind_nginx_comes_back_with_its_steps_and_viewers() {
    let conf = shipped_conf();
    let shards = shards_of(&conf);
    let dirs: Vec<tempfile::TempDir> = shards
        .iter()
        .map(|_| tempfile::tempdir().expect("temp dir"))
        .collect();
    let dir_names: Vec<String> = dirs
        .iter()
        .map(|d| d.path().to_str().expect("utf-8").to_string())
        .collect();
    // Fixed addresses: the restarted process is where nginx expects it.
    let addrs: Vec<String> = shards
        .iter()
        .map(|_| format!("127.0.0.1:{}", free_port()))
        .collect();
    let mut backends: Vec<Option<Backend>> = shards
        .iter()
        .enumerate()
        .map(|(k, (name, _))| {
            Some(Backend::start_on(
                &addrs[k],
                &backend_args(name, &dir_names[k]),
            ))
        })
        .collect();
    let port = free_port();
    let mut test_conf = replace_exactly(
        &conf,
        "listen 8080;",
        &format!("listen 127.0.0.1:{port};"),
        1,
    );
    for ((_, shipped), addr) in shards.iter().zip(&addrs) {
        test_conf = replace_exactly(&test_conf, &format!("{shipped};"), &format!("{addr};"), 2);
    }
    let lb = Nginx::start(&test_conf, port);
    let lb_base = lb.base.clone();

    // Scenes through nginx until every shard holds one: (id, token) per shard.
    let names: Vec<String> = shards.iter().map(|(n, _)| n.clone()).collect();
    let scenes: Vec<(String, String)> = call({
        let lb = lb_base.clone();
        let names = names.clone();
        move || {
            let mut per_shard: Vec<Option<(String, String)>> = vec![None; names.len()];
            for _ in 0..60 {
                if per_shard.iter().all(Option::is_some) {
                    break;
                }
                let r = request(&lb, "POST", "/api/v1/scenes", br#"{"kind":"metaballs"}"#);
                assert_eq!(r.status, 201, "create through nginx: {}", r.text());
                let v = json(&r);
                let id = v["scene"]["id"].as_str().expect("id").to_string();
                let token = v["write_token"].as_str().expect("token").to_string();
                let k = names
                    .iter()
                    .position(|n| id.starts_with(&format!("{n}_")))
                    .expect("the id names a shard");
                let r = push(
                    &lb,
                    &id,
                    "0?time=1",
                    &token,
                    "application/json",
                    &json_step(4, k),
                );
                assert_eq!(r.status, 201, "push through nginx: {}", r.text());
                per_shard[k].get_or_insert((id, token));
            }
            per_shard
                .into_iter()
                .map(|s| s.expect("creation reached every shard"))
                .collect()
        }
    })
    .await;

    // A viewer of each scene through nginx, on the frame of step 0.
    let mut viewers = Vec::new();
    for (id, _) in &scenes {
        let mut ws = open_viewer(&lb_base, id).await;
        frame_at_time(&mut ws, id, 1.0).await;
        viewers.push(ws);
    }

    // The victim is shard s1: a pusher adds steps 1, 2, ... (time = 10 + index) through nginx,
    // retrying an index until it gets a 2xx.
    const VICTIM: usize = 1;
    let (victim_id, victim_token) = scenes[VICTIM].clone();
    let pushed = Arc::new(Mutex::new(Pushed::default()));
    let stop = Arc::new(AtomicBool::new(false));
    let pusher = std::thread::spawn({
        let (lb, id, token) = (lb_base.clone(), victim_id.clone(), victim_token.clone());
        let (pushed, stop) = (pushed.clone(), stop.clone());
        move || {
            let mut index = 1u64;
            while !stop.load(Ordering::SeqCst) {
                let r = push(
                    &lb,
                    &id,
                    &format!("{index}?time={}", 10 + index),
                    &token,
                    "application/json",
                    &json_step(4 + index as usize % 5, index as usize),
                );
                let mut p = pushed.lock().expect("pushed");
                if r.status == 200 || r.status == 201 {
                    let checksum = json(&r)["step"]["checksum"]
                        .as_str()
                        .expect("checksum")
                        .to_string();
                    p.completed.insert(index, checksum);
                    index += 1;
                } else {
                    assert!(
                        [502, 503].contains(&r.status),
                        "a push while the process is down: {} {}",
                        r.status,
                        r.text()
                    );
                    p.failed += 1;
                    drop(p);
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
        }
    });
    let completed = || pushed.lock().expect("pushed").completed.len();
    let pushes_before = call({
        let pushed = pushed.clone();
        move || {
            wait_until("two pushes to the victim complete", || {
                pushed.lock().expect("pushed").completed.len() >= 2
            });
            pushed.lock().expect("pushed").completed.len()
        }
    })
    .await;
    assert!(pushes_before >= 2);

    // SIGKILL while it streams and takes pushes.
    backends[VICTIM].take().expect("victim").kill();

    // Its viewer sees the connection end (nginx drops it; frames in flight may come first).
    let mut victim_ws = viewers.remove(VICTIM);
    let end = tokio::time::timeout(WAIT, async {
        loop {
            match victim_ws.next().await {
                Some(Ok(Message::Binary(_) | Message::Ping(_) | Message::Pong(_))) => continue,
                other => return format!("{other:?}"),
            }
        }
    })
    .await
    .expect("the victim's viewer sees its connection end");
    println!("the victim's viewer saw: {end}");

    // Meanwhile the other processes' viewers, on their first connection, see new steps.
    for (k, ws) in viewers.iter_mut().enumerate() {
        let (id, token) = &scenes[if k < VICTIM { k } else { k + 1 }];
        let r = call({
            let (lb, id, token) = (lb_base.clone(), id.clone(), token.clone());
            move || {
                push(
                    &lb,
                    &id,
                    "1?time=2",
                    &token,
                    "application/json",
                    &json_step(5, 7),
                )
            }
        })
        .await;
        assert_eq!(
            r.status,
            201,
            "push to a live shard during the outage: {}",
            r.text()
        );
        frame_at_time(ws, id, 2.0).await;
    }
    let failed_during_outage = call({
        let pushed = pushed.clone();
        move || {
            let failed = pushed.lock().expect("pushed").failed;
            wait_until("a push to the dead shard fails", || {
                pushed.lock().expect("pushed").failed > failed
            });
            pushed.lock().expect("pushed").failed
        }
    })
    .await;

    // Restart on the same address and store; pushes to the victim succeed again.
    backends[VICTIM] = Some(Backend::start_on(
        &addrs[VICTIM],
        &backend_args(&names[VICTIM], &dir_names[VICTIM]),
    ));
    let before_restart = completed();
    call({
        let pushed = pushed.clone();
        move || {
            wait_until("pushes complete after the restart", || {
                pushed.lock().expect("pushed").completed.len() >= before_restart + 2
            })
        }
    })
    .await;
    stop.store(true, Ordering::SeqCst);
    pusher.join().expect("the pusher did not panic");
    let pushed = Arc::try_unwrap(pushed)
        .ok()
        .expect("pusher done")
        .into_inner()
        .expect("pushed");

    // Every completed step is listed, through nginx, with the checksum it was stored with.
    let listed = call({
        let (lb, id) = (lb_base.clone(), victim_id.clone());
        move || {
            json(&request(
                &lb,
                "GET",
                &format!("/api/v1/scenes/{id}/steps"),
                b"",
            ))
        }
    })
    .await;
    let listed = crate::api::step_checksums(&listed["steps"]);
    let lost: Vec<u64> = pushed
        .completed
        .iter()
        .filter(|(i, c)| listed.get(i) != Some(c))
        .map(|(i, _)| *i)
        .collect();
    println!(
        "nginx restart: {} pushes completed to the killed process's scene ({} before the kill), \
         {} refused while it was down, completed steps lost {}",
        pushed.completed.len(),
        pushes_before,
        failed_during_outage,
        lost.len()
    );
    assert!(
        lost.is_empty(),
        "completed steps lost: {lost:?} (listed {listed:?})"
    );

    // The victim's viewer reconnects through nginx and sees the newest step.
    let last = *pushed.completed.keys().last().expect("a completed push");
    let mut again = open_viewer(&lb_base, &victim_id).await;
    frame_at_time(&mut again, &victim_id, (10 + last) as f64).await;

    // The other viewers never reconnected and still stream: a step pushed now reaches them.
    for (k, ws) in viewers.iter_mut().enumerate() {
        let (id, token) = &scenes[if k < VICTIM { k } else { k + 1 }];
        let r = call({
            let (lb, id, token) = (lb_base.clone(), id.clone(), token.clone());
            move || {
                push(
                    &lb,
                    &id,
                    "2?time=3",
                    &token,
                    "application/json",
                    &json_step(6, 8),
                )
            }
        })
        .await;
        assert_eq!(r.status, 201, "{}", r.text());
        frame_at_time(ws, id, 3.0).await;
    }
    let _ = again.close(None).await;
    for mut ws in viewers {
        let _ = ws.close(None).await;
    }
    drop(lb);
    drop(backends);
}
