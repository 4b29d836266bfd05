//! `isoray-bench load`: many websocket viewers against a running server or load balancer.
//!
//! Each of `--sessions` viewers opens `/api/v1/scenes/{scene}/stream` (sessions take the
//! `--scene`s in turn), asks for `--size` frames, then drives a moving camera like a person
//! dragging in the browser: a camera input every 1/`--input-hz` s along an orbit around the
//! scene's default target (each session starts at its own angle), and acknowledges every
//! frame as soon as it has arrived, as the browser does once a frame is shown (PROTOCOL.md,
//! flow control). It counts frames and bytes and measures input-to-frame latency the way the
//! browser's stats overlay does: from sending an input to the first frame whose header names
//! that input (or a later one) as applied; inputs a frame skipped over are not counted.
//!
//! The report is one row per session (frames per second, latency percentiles, KB per frame,
//! errors) and a line over all sessions, with the machine it ran on. Everything it sends
//! goes to `--url` only; the run stops by itself after `--seconds`.

use crate::common::{quantile, Machine};
use futures_util::{SinkExt, StreamExt};
use isoray_protocol::{FrameHeader, ServerMessage, SessionInfo, FRAME_HEADER_LEN};
use serde::Serialize;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;

#[derive(clap::Args)]
pub struct LoadArgs {
    /// Base URL of the server or load balancer, `http://HOST:PORT`.
    #[arg(long)]
    url: String,
    /// Concurrent viewers.
    #[arg(long, default_value_t = 8)]
    sessions: usize,
    /// How long every viewer drives its camera.
    #[arg(long, default_value_t = 20.0)]
    seconds: f64,
    /// Scene to watch; repeat to spread the sessions over several (default: `blobs`).
    #[arg(long)]
    scene: Vec<String>,
    /// Frame size each viewer asks for, `WIDTHxHEIGHT`.
    #[arg(long, default_value = "640x360")]
    size: String,
    /// Camera inputs per second per viewer.
    #[arg(long, default_value_t = 30.0)]
    input_hz: f64,
    /// Target frame rate each viewer asks for (the `stream` message's `fps`; default: the
    /// server's `--max-fps`).
    #[arg(long)]
    fps: Option<f64>,
    /// View token, when the server needs one (sent as `?token=`).
    #[arg(long)]
    token: Option<String>,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Create this many metaball scenes through `--url` (pushing step 0 to each) and spread
    /// the viewers over them instead of `--scene`.
    #[arg(long, default_value_t = 0)]
    create: usize,
    /// Balls per step of the created scenes.
    #[arg(long, default_value_t = 1000)]
    balls: usize,
    /// Push a new step to the first N created scenes every 1/`--push-hz` s while the
    /// viewers watch.
    #[arg(long, default_value_t = 0)]
    push_to: usize,
    #[arg(long, default_value_t = 1.0)]
    push_hz: f64,
    /// A process behind the balancer, `NAME=http://HOST:PORT` (NAME: its `--shard`); repeat.
    /// Its `/metrics` is read at mid-run to show which process served each scene.
    #[arg(long)]
    backend: Vec<String>,
    /// Token for the backends' `/metrics` (their `--metrics-token`).
    #[arg(long)]
    metrics_token: Option<String>,
}

/// One viewer's outcome.
#[derive(Clone, Debug, Default, Serialize)]
struct SessionReport {
    session: usize,
    scene: String,
    frames: u64,
    bytes: u64,
    /// Seconds from the first frame to the end of the run.
    seconds: f64,
    fps: f64,
    /// Input-to-frame latency, milliseconds, one sample per input answered.
    latency_p50_ms: f64,
    latency_p95_ms: f64,
    latency_p99_ms: f64,
    latency_samples: usize,
    /// Server `error` messages, connection failures and early closes.
    errors: u64,
    error_messages: Vec<String>,
    /// The frame size the server's adaptive controller settled on: the most frequent size
    /// among the frames of the second half of the run (`WIDTHxHEIGHT`).
    settled_size: String,
    /// Connections opened again after the server closed one (a process restarted, say).
    reconnects: u64,
    /// Scene seconds the frames' headers advanced per wall second, from the first frame to the
    /// last (1: an animated demo runs in real time, whatever the number of viewers); `None`
    /// with fewer than two frames.
    animation_rate: Option<f64>,
    #[serde(skip)]
    latencies_ms: Vec<f64>,
    /// (arrival, scene time) of the first and the latest frame.
    #[serde(skip)]
    scene_span: Option<((Instant, f64), (Instant, f64))>,
    /// (arrival, width, height) of every frame.
    #[serde(skip)]
    sizes: Vec<(Instant, u32, u32)>,
}

#[derive(Serialize)]
struct Report {
    url: String,
    sessions: usize,
    seconds: f64,
    width: u32,
    height: u32,
    input_hz: f64,
    machine: String,
    total_frames_per_sec: f64,
    fps_median: f64,
    fps_min: f64,
    fps_max: f64,
    /// Sessions whose fps is below half the mean over all sessions.
    below_half_mean: usize,
    latency_p50_ms: f64,
    latency_p95_ms: f64,
    latency_p99_ms: f64,
    /// Median over the viewers of [`SessionReport::animation_rate`].
    animation_rate_median: Option<f64>,
    errors: u64,
    reconnects: u64,
    per_session: Vec<SessionReport>,
    pushers: Vec<crate::load_cluster::PushReport>,
    processes: Vec<crate::load_cluster::ProcessReport>,
    /// Processes whose session count at mid-run differs from the viewers of the scenes
    /// their shard created (a scene served by a process that does not hold it).
    misplaced_processes: usize,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let parsed = s
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)));
    match parsed {
        Some((w, h)) if w > 0 && h > 0 => Ok((w, h)),
        _ => Err(format!("--size {s:?} is not WIDTHxHEIGHT")),
    }
}

/// The most frequent frame size in the second half of the frames' arrival times (ties: the
/// larger); `-` without frames.
fn settled_size(sizes: &[(Instant, u32, u32)]) -> String {
    let (Some(first), Some(last)) = (sizes.first(), sizes.last()) else {
        return "-".into();
    };
    let middle = first.0 + last.0.duration_since(first.0) / 2;
    let mut counts: std::collections::BTreeMap<(u32, u32), usize> = Default::default();
    for &(_, w, h) in sizes.iter().filter(|s| s.0 >= middle) {
        *counts.entry((w, h)).or_default() += 1;
    }
    counts
        .into_iter()
        .max_by_key(|&((w, h), n)| (n, u64::from(w) * u64::from(h)))
        .map_or_else(|| "-".into(), |((w, h), _)| format!("{w}x{h}"))
}

/// `ws://HOST:PORT` from `http://HOST:PORT[/]`.
fn ws_base(url: &str) -> Result<String, String> {
    let rest = url
        .strip_prefix("http://")
        .ok_or_else(|| format!("--url {url:?}: expected http://HOST:PORT"))?;
    Ok(format!("ws://{}", rest.trim_end_matches('/')))
}

pub fn run(args: LoadArgs) -> Result<(), String> {
    if args.sessions == 0 || args.sessions > 10_000 {
        return Err("--sessions must be in 1..=10000".into());
    }
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 3600.0) {
        return Err("--seconds must be in (0, 3600]".into());
    }
    if !(args.input_hz.is_finite() && args.input_hz > 0.0 && args.input_hz <= 1000.0) {
        return Err("--input-hz must be in (0, 1000]".into());
    }
    if args
        .fps
        .is_some_and(|f| !(f.is_finite() && (1.0..=1000.0).contains(&f)))
    {
        return Err("--fps must be in [1, 1000]".into());
    }
    if !(args.push_hz.is_finite() && args.push_hz > 0.0 && args.push_hz <= 100.0) {
        return Err("--push-hz must be in (0, 100]".into());
    }
    if args.push_to > args.create {
        return Err("--push-to must be at most --create".into());
    }
    if args.create > 1000 || args.balls == 0 || args.balls > 1_000_000 {
        return Err("--create must be at most 1000 and --balls in 1..=1000000".into());
    }
    let backends = args
        .backend
        .iter()
        .map(|b| crate::load_cluster::parse_backend(b))
        .collect::<Result<Vec<_>, _>>()?;
    let (width, height) = parse_size(&args.size)?;
    let base = ws_base(&args.url)?;
    let created = crate::load_cluster::create_scenes(&args.url, args.create, args.balls)?;
    let scenes: Vec<String> = if !created.is_empty() {
        created.iter().map(|c| c.id.clone()).collect()
    } else if args.scene.is_empty() {
        vec!["blobs".to_string()]
    } else {
        args.scene.clone()
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the async runtime: {e}"))?;
    let duration = Duration::from_secs_f64(args.seconds);
    let input_interval = Duration::from_secs_f64(1.0 / args.input_hz);
    let (mut per_session, pushers, processes) = runtime.block_on(async {
        let pushers: Vec<_> = created
            .iter()
            .take(args.push_to)
            .map(|scene| {
                let (url, scene, balls, hz) =
                    (args.url.clone(), scene.clone(), args.balls, args.push_hz);
                tokio::task::spawn_blocking(move || {
                    crate::load_cluster::pusher(url, scene, balls, hz, duration)
                })
            })
            .collect();
        let scrape = {
            let (backends, token) = (backends.clone(), args.metrics_token.clone());
            tokio::spawn(async move {
                tokio::time::sleep(duration / 2).await;
                tokio::task::spawn_blocking(move || {
                    crate::load_cluster::scrape(&backends, token.as_deref())
                })
                .await
                .unwrap_or_default()
            })
        };
        let tasks: Vec<_> = (0..args.sessions)
            .map(|i| {
                let scene = scenes[i % scenes.len()].clone();
                let mut url = format!("{base}/api/v1/scenes/{scene}/stream");
                if let Some(t) = &args.token {
                    url.push_str(&format!("?token={t}"));
                }
                let phase = i as f64 / args.sessions as f64 * std::f64::consts::TAU;
                tokio::spawn(reconnecting_viewer(
                    i,
                    scene,
                    url,
                    (width, height),
                    phase,
                    input_interval,
                    duration,
                    args.fps,
                ))
            })
            .collect();
        let mut out = Vec::new();
        for (i, t) in tasks.into_iter().enumerate() {
            out.push(t.await.unwrap_or_else(|e| SessionReport {
                session: i,
                errors: 1,
                error_messages: vec![format!("the viewer task failed: {e}")],
                ..SessionReport::default()
            }));
        }
        let mut pushed = Vec::new();
        for p in pushers {
            pushed.push(p.await.unwrap_or_default());
        }
        (out, pushed, scrape.await.unwrap_or_default())
    });
    let mut processes = processes;
    for p in &mut processes {
        let prefix = format!("{}_", p.name);
        p.expected_sessions = per_session
            .iter()
            .filter(|s| s.scene.starts_with(&prefix))
            .count();
    }
    let misplaced_processes = processes
        .iter()
        .filter(|p| p.error.is_some() || p.sessions != p.expected_sessions as f64)
        .count();

    for s in &mut per_session {
        s.latencies_ms.sort_by(f64::total_cmp);
        s.latency_p50_ms = quantile(&s.latencies_ms, 0.50);
        s.latency_p95_ms = quantile(&s.latencies_ms, 0.95);
        s.latency_p99_ms = quantile(&s.latencies_ms, 0.99);
        s.latency_samples = s.latencies_ms.len();
        s.fps = if s.seconds > 0.0 {
            s.frames as f64 / s.seconds
        } else {
            0.0
        };
        s.settled_size = settled_size(&s.sizes);
        s.animation_rate = s.scene_span.and_then(|((t0, s0), (t1, s1))| {
            let wall = t1.saturating_duration_since(t0).as_secs_f64();
            (wall > 0.0).then(|| (s1 - s0) / wall)
        });
    }
    let rates: Vec<f64> = per_session
        .iter()
        .filter_map(|s| s.animation_rate)
        .collect();
    let mut all: Vec<f64> = per_session
        .iter()
        .flat_map(|s| s.latencies_ms.iter().copied())
        .collect();
    all.sort_by(f64::total_cmp);
    let mut fps: Vec<f64> = per_session.iter().map(|s| s.fps).collect();
    fps.sort_by(f64::total_cmp);
    let mean_fps = fps.iter().sum::<f64>() / fps.len().max(1) as f64;
    let below_half_mean = fps.iter().filter(|f| **f < 0.5 * mean_fps).count();
    let machine = Machine::here();
    let report = Report {
        url: args.url.clone(),
        sessions: args.sessions,
        seconds: args.seconds,
        width,
        height,
        input_hz: args.input_hz,
        machine: format!("{} (nproc {})", machine.cpu, machine.nproc),
        total_frames_per_sec: per_session.iter().map(|s| s.fps).sum(),
        fps_median: crate::common::median(fps.clone()),
        fps_min: fps.first().copied().unwrap_or(0.0),
        fps_max: fps.last().copied().unwrap_or(0.0),
        below_half_mean,
        latency_p50_ms: quantile(&all, 0.50),
        latency_p95_ms: quantile(&all, 0.95),
        latency_p99_ms: quantile(&all, 0.99),
        animation_rate_median: (!rates.is_empty()).then(|| crate::common::median(rates)),
        errors: per_session.iter().map(|s| s.errors).sum::<u64>()
            + pushers.iter().map(|p| p.failed).sum::<u64>(),
        reconnects: per_session.iter().map(|s| s.reconnects).sum(),
        per_session,
        pushers,
        processes,
        misplaced_processes,
    };
    print_report(&report);
    if let Some(path) = &args.json {
        crate::common::write_json(path, &report)?;
    }
    Ok(())
}

fn print_report(r: &Report) {
    println!(
        "isoray-bench load: {} viewers x {} s against {} ({}x{}, camera input {} Hz, every frame acknowledged)",
        r.sessions, r.seconds, r.url, r.width, r.height, r.input_hz
    );
    println!("machine (load generator): {}", r.machine);
    println!(
        "{:>7}  {:<24}  {:>6}  {:>6}  {:>7}  {:>7}  {:>7}  {:>8}  {:>9}  {:>6}",
        "session",
        "scene",
        "frames",
        "fps",
        "p50 ms",
        "p95 ms",
        "p99 ms",
        "KB/frame",
        "settled",
        "errors"
    );
    for s in &r.per_session {
        let kb = if s.frames > 0 {
            s.bytes as f64 / s.frames as f64 / 1000.0
        } else {
            0.0
        };
        println!(
            "{:>7}  {:<24}  {:>6}  {:>6.1}  {:>7.1}  {:>7.1}  {:>7.1}  {:>8.1}  {:>9}  {:>6}",
            s.session,
            s.scene,
            s.frames,
            s.fps,
            s.latency_p50_ms,
            s.latency_p95_ms,
            s.latency_p99_ms,
            kb,
            s.settled_size,
            s.errors
        );
    }
    println!(
        "all: {:.1} frames/s in total; per viewer {:.1} fps median ({:.1}..{:.1}), {} below half \
         the mean; input-to-frame p50 {:.1} ms, p95 {:.1} ms, p99 {:.1} ms; {} errors, {} reconnects",
        r.total_frames_per_sec,
        r.fps_median,
        r.fps_min,
        r.fps_max,
        r.below_half_mean,
        r.latency_p50_ms,
        r.latency_p95_ms,
        r.latency_p99_ms,
        r.errors,
        r.reconnects
    );
    if let Some(rate) = r.animation_rate_median {
        println!(
            "scene time in the frames' headers: {rate:.2} s per wall second (median over the \
             viewers; 1.00 for an animated demo in real time, 0 for a still scene)"
        );
    }
    for p in &r.pushers {
        println!(
            "pusher {}: {} steps pushed, {} failed; push p50 {:.1} ms, p95 {:.1} ms, max {:.1} ms{}",
            p.scene,
            p.pushed,
            p.failed,
            p.latency_p50_ms,
            p.latency_p95_ms,
            p.latency_max_ms,
            if p.error_messages.is_empty() {
                String::new()
            } else {
                format!(" ({})", p.error_messages.join("; "))
            }
        );
    }
    for p in &r.processes {
        println!(
            "process {} ({}): {} sessions at mid-run, {} viewers of its shard's scenes{}",
            p.name,
            p.url,
            p.sessions,
            p.expected_sessions,
            p.error
                .as_deref()
                .map(|e| format!(" ({e})"))
                .unwrap_or_default()
        );
    }
    if !r.processes.is_empty() {
        println!(
            "placement: {} of {} processes serve exactly the viewers of their own scenes",
            r.processes.len() - r.misplaced_processes,
            r.processes.len()
        );
    }
    for s in r
        .per_session
        .iter()
        .filter(|s| !s.error_messages.is_empty())
    {
        println!("session {}: {}", s.session, s.error_messages.join("; "));
    }
}

/// Counts an error; the first few are kept to print.
fn fail(report: &mut SessionReport, why: String) {
    report.errors += 1;
    if report.error_messages.len() < 5 {
        report.error_messages.push(why);
    }
}

/// A viewer that opens its stream again whenever it ends before `duration` (a process
/// restarted), counting the reconnects; the reports of its connections are summed.
#[allow(clippy::too_many_arguments)]
async fn reconnecting_viewer(
    session: usize,
    scene: String,
    url: String,
    size: (u32, u32),
    phase: f64,
    input_interval: Duration,
    duration: Duration,
    fps: Option<f64>,
) -> SessionReport {
    let end = Instant::now() + duration;
    let mut total = SessionReport {
        session,
        scene: scene.clone(),
        ..SessionReport::default()
    };
    loop {
        let left = end.saturating_duration_since(Instant::now());
        let r = viewer(
            session,
            scene.clone(),
            url.clone(),
            size,
            phase,
            input_interval,
            left,
            fps,
        )
        .await;
        total.frames += r.frames;
        total.bytes += r.bytes;
        total.seconds += r.seconds;
        total.errors += r.errors;
        for m in r.error_messages {
            if total.error_messages.len() < 5 {
                total.error_messages.push(m);
            }
        }
        total.latencies_ms.extend(r.latencies_ms);
        total.sizes.extend(r.sizes);
        total.scene_span = match (total.scene_span, r.scene_span) {
            (Some((first, _)), Some((_, last))) => Some((first, last)),
            (a, b) => a.or(b),
        };
        if r.errors == 0 || Instant::now() + Duration::from_millis(500) >= end {
            return total;
        }
        total.reconnects += 1;
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
}

/// Most recent inputs remembered for latency (older ones a frame skipped over are dropped).
const SENT_KEPT: usize = 256;

/// One viewer: connect, resize, drive the camera, acknowledge frames, until `duration`.
#[allow(clippy::too_many_arguments)]
async fn viewer(
    session: usize,
    scene: String,
    url: String,
    size: (u32, u32),
    phase: f64,
    input_interval: Duration,
    duration: Duration,
    fps: Option<f64>,
) -> SessionReport {
    let mut report = SessionReport {
        session,
        scene,
        ..SessionReport::default()
    };
    let ws = tokio::time::timeout(
        Duration::from_secs(30),
        tokio_tungstenite::connect_async(url.as_str()),
    )
    .await;
    let mut ws = match ws {
        Ok(Ok((ws, _))) => ws,
        Ok(Err(e)) => {
            fail(&mut report, format!("connect: {e}"));
            return report;
        }
        Err(_) => {
            fail(&mut report, "connect: no answer in 30 s".into());
            return report;
        }
    };
    // The first message is `info`: the camera to orbit around.
    let info: SessionInfo = loop {
        match tokio::time::timeout(Duration::from_secs(30), ws.next()).await {
            Ok(Some(Ok(Message::Text(text)))) => {
                match serde_json::from_str::<ServerMessage>(text.as_str()) {
                    Ok(ServerMessage::Info(info)) => break info,
                    Ok(other) => {
                        fail(&mut report, format!("before info: {other:?}"));
                        return report;
                    }
                    Err(e) => {
                        fail(&mut report, format!("unreadable message: {e}"));
                        return report;
                    }
                }
            }
            Ok(Some(Ok(_))) => {}
            other => {
                fail(&mut report, format!("no info: {other:?}"));
                return report;
            }
        }
    };
    let (w, h) = (size.0.min(info.max_width), size.1.min(info.max_height));
    let resize = serde_json::json!({"type": "resize", "input_id": 1, "width": w, "height": h});
    if let Err(e) = ws.send(Message::Text(resize.to_string().into())).await {
        fail(&mut report, format!("send: {e}"));
        return report;
    }
    if let Some(fps) = fps {
        let stream = serde_json::json!({"type": "stream", "input_id": 1, "fps": fps});
        if let Err(e) = ws.send(Message::Text(stream.to_string().into())).await {
            fail(&mut report, format!("send: {e}"));
            return report;
        }
    }
    let target = info.camera.target;
    let eye = info.camera.eye;
    let offset = [eye[0] - target[0], eye[1] - target[1], eye[2] - target[2]];
    let radius = (offset[0] * offset[0] + offset[2] * offset[2])
        .sqrt()
        .max(1e-3);
    let height = offset[1];
    let start = Instant::now();
    let end = start + duration;
    let mut first_frame: Option<Instant> = None;
    let mut ticker = tokio::time::interval(input_interval);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut next_input: u64 = 2;
    let mut sent: VecDeque<(u64, Instant)> = VecDeque::new();
    let mut answered: u64 = 1;
    loop {
        tokio::select! {
            _ = ticker.tick() => {
                let now = Instant::now();
                if now >= end {
                    break;
                }
                // Half a turn every 4 s, like a steady drag.
                let angle = phase + now.duration_since(start).as_secs_f64() * std::f64::consts::FRAC_PI_4;
                let camera = serde_json::json!({
                    "type": "camera",
                    "input_id": next_input,
                    "eye": [target[0] + radius * angle.sin(), target[1] + height, target[2] + radius * angle.cos()],
                    "target": target,
                    "up": info.camera.up,
                });
                if let Err(e) = ws.send(Message::Text(camera.to_string().into())).await {
                    fail(&mut report, format!("send: {e}"));
                    break;
                }
                sent.push_back((next_input, now));
                if sent.len() > SENT_KEPT {
                    sent.pop_front();
                }
                next_input += 1;
            }
            msg = tokio::time::timeout_at(tokio::time::Instant::from_std(end), ws.next()) => {
                let msg = match msg {
                    Err(_) => break,
                    Ok(None) => {
                        fail(&mut report, "the server closed the stream".into());
                        break;
                    }
                    Ok(Some(Err(e))) => {
                        fail(&mut report, format!("websocket: {e}"));
                        break;
                    }
                    Ok(Some(Ok(m))) => m,
                };
                match msg {
                    Message::Binary(bytes) => {
                        let now = Instant::now();
                        let header = match FrameHeader::decode(&bytes) {
                            Ok(h) => h,
                            Err(e) => {
                                fail(&mut report, format!("frame header: {e:?}"));
                                break;
                            }
                        };
                        let ack = serde_json::json!({"type": "ack", "sequence": header.sequence});
                        if let Err(e) = ws.send(Message::Text(ack.to_string().into())).await {
                            fail(&mut report, format!("send: {e}"));
                            break;
                        }
                        first_frame.get_or_insert(now);
                        report.frames += 1;
                        report.sizes.push((now, header.width, header.height));
                        let seen = (now, header.scene_time);
                        report.scene_span = Some(report.scene_span.map_or((seen, seen), |(first, _)| (first, seen)));
                        report.bytes += (bytes.len().saturating_sub(FRAME_HEADER_LEN)) as u64;
                        if header.input_id > answered {
                            answered = header.input_id;
                            while let Some(&(id, at)) = sent.front() {
                                if id > answered {
                                    break;
                                }
                                sent.pop_front();
                                if id == answered {
                                    report.latencies_ms.push(now.duration_since(at).as_secs_f64() * 1000.0);
                                }
                            }
                        }
                    }
                    Message::Text(text) => {
                        if let Ok(ServerMessage::Error(e)) = serde_json::from_str::<ServerMessage>(text.as_str()) {
                            fail(&mut report, format!("server error {}: {}", e.code, e.message));
                        }
                    }
                    Message::Close(frame) => {
                        fail(&mut report, format!("closed by the server: {frame:?}"));
                        break;
                    }
                    _ => {}
                }
            }
        }
    }
    let stopped = Instant::now().min(end);
    report.seconds =
        first_frame.map_or(0.0, |t| stopped.saturating_duration_since(t).as_secs_f64());
    let _ = ws.close(None).await;
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.5), 50.0);
        assert_eq!(quantile(&v, 0.95), 95.0);
        assert_eq!(quantile(&v, 0.99), 99.0);
        assert_eq!(quantile(&[7.0], 0.99), 7.0);
        assert_eq!(quantile(&[], 0.5), 0.0);
    }

    #[test]
    fn urls_and_sizes_are_checked() {
        assert_eq!(
            ws_base("http://127.0.0.1:8080/").as_deref(),
            Ok("ws://127.0.0.1:8080")
        );
        assert!(ws_base("https://x").is_err());
        assert_eq!(parse_size("320x180"), Ok((320, 180)));
        assert!(parse_size("0x10").is_err());
    }

    #[test]
    fn the_settled_size_is_the_commonest_of_the_second_half() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        // Small while the controller searches, then mostly 960x540.
        let sizes = [
            (at(0), 320, 180),
            (at(10), 320, 180),
            (at(20), 320, 180),
            (at(60), 640, 360),
            (at(70), 960, 540),
            (at(80), 960, 540),
            (at(100), 960, 540),
        ];
        assert_eq!(settled_size(&sizes), "960x540");
        assert_eq!(settled_size(&[]), "-");
    }
}
