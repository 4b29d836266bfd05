//! `isoray-bench overlap`: whether a live view of an animated demo overlaps the build of the
//! next state with the trace of the current frame (fitted-bvh-metaballs.txt Fig. 7; issue
//! 14, Must show 3).
//!
//! Starts the server in-process on loopback (`--backend cpu --min-scale 1`, so the adaptive
//! controller keeps the asked size; or uses `--url`), opens one websocket viewer of `--scene`
//! (default `scattered-100k`, 100,000 bobbing balls), asks for `--size`, keeps the camera
//! still (the scene animates by itself) and acknowledges every frame on arrival, as the
//! browser does. Frames of the first `--warmup` seconds are dropped; the rest, for `--seconds`,
//! give per frame:
//!
//! - interval: the time between this frame's arrival at the client and the previous one's,
//!   i.e. the frame time a viewer sees;
//! - build, trace, encode: the frame header's `build_us` (update + build of the state the
//!   frame shows, on the build pool, in its own wall time: for a state built ahead, while the
//!   previous frame traced), `trace_us` and `encode_us`.
//!
//! Each run streams twice. `pipelined`: the live view, the server's normal path for an
//! animated demo. `serial`: the same viewer pins the scene time and, as each frame arrives,
//! pins the next one (1/30 s on), so the server builds that state on the frame's own render
//! thread, then traces it: no overlap, the before row of the same run (the in-process server
//! never sends still frames, `--still-after-ms` being 10 minutes; with `--url` still frames
//! are left out).
//!
//! The table gives per run the medians of the interval, of each stage, of the per-frame
//! max(build, trace) and build + trace, and interval / max(build, trace). The header's
//! stage times are wall times measured while the two overlap on the same cores, so they are
//! longer than either stage alone; the "alone" line times one build and one trace of the
//! same state and view with nothing else running on the bench's pools (median of 3), to show
//! what the overlap costs each stage, and the CPU time each took. On `nproc` cores no
//! schedule makes a frame shorter than the work bound, (build CPU + trace CPU + encode CPU) /
//! `nproc`; the "busy cores" column (the process's CPU time over the measured wall time, in
//! process only) says how much of the machine the pipeline kept busy.

use crate::common::{median, serve_in_process, write_json, Machine};
use crate::stream::{demo, parse_size};
use futures_util::{SinkExt, StreamExt};
use isoray_protocol::{FrameHeader, ServerMessage, FLAG_STILL};
use isoray_render::Backend;
use isoray_server::Config;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;

#[derive(clap::Args)]
pub struct OverlapArgs {
    /// Demo scene id (an animated demo).
    #[arg(long, default_value = "scattered-100k")]
    scene: String,
    /// Frame size the viewer asks for, `WIDTHxHEIGHT`.
    #[arg(long, default_value = "640x480")]
    size: String,
    /// Seconds measured per run, after the warm-up.
    #[arg(long, default_value_t = 30.0)]
    seconds: f64,
    /// Seconds of frames dropped at the start of each run.
    #[arg(long, default_value_t = 8.0)]
    warmup: f64,
    /// Runs (one new viewer each); the summary is the median of the runs' medians.
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Render (and build) threads of the in-process server (0: one per core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Use this running server (`http://HOST:PORT`) instead of an in-process one.
    #[arg(long)]
    url: Option<String>,
    /// Skip the "alone" line (one build and one trace with nothing else running).
    #[arg(long)]
    no_alone: bool,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Switch hard shadows on (the viewer sends an `effects` message after connecting).
    #[arg(long)]
    shadows: bool,
}

/// One frame as the client saw it.
#[derive(Clone, Copy, Debug)]
struct Sample {
    interval_ms: f64,
    build_ms: f64,
    trace_ms: f64,
    encode_ms: f64,
    /// The frame shows a state no earlier frame showed (its header reports the build).
    fresh: bool,
}

/// Per-frame medians of one run.
#[derive(Clone, Debug, Default, Serialize)]
struct RunRow {
    run: usize,
    mode: &'static str,
    frames: usize,
    /// Frames that showed a new state (the others repeat one; their build field is 0).
    fresh_frames: usize,
    interval_ms: f64,
    build_ms: f64,
    trace_ms: f64,
    encode_ms: f64,
    max_build_trace_ms: f64,
    sum_build_trace_ms: f64,
    /// interval / max(build, trace), medians of each.
    ratio_to_max: f64,
    /// interval / (build + trace), medians of each.
    ratio_to_sum: f64,
    /// The process's CPU seconds per wall second while measured (in-process server only).
    busy_cores: Option<f64>,
    load_average: String,
}

#[derive(Serialize)]
struct Alone {
    build_ms: f64,
    trace_ms: f64,
    encode_ms: f64,
    /// CPU time of the process while building, tracing and encoding (all threads).
    build_cpu_ms: f64,
    trace_cpu_ms: f64,
    encode_cpu_ms: f64,
}

impl Alone {
    /// The shortest frame interval any schedule of both stages could reach on `cores`.
    fn work_bound_ms(&self, cores: usize) -> f64 {
        (self.build_cpu_ms + self.trace_cpu_ms + self.encode_cpu_ms) / cores.max(1) as f64
    }
}

/// The process's user + system CPU seconds, all threads (`/proc/self/stat`, in the 100 Hz
/// ticks of Linux's fixed user-space clock).
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // After the name: state is field 3, utime 14, stime 15.
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

#[derive(Serialize)]
struct Report {
    machine: String,
    scene: String,
    width: u32,
    height: u32,
    alone: Option<Alone>,
    runs: Vec<RunRow>,
    median: Vec<RunRow>,
}

/// How the viewer asks for states (see the module's documentation).
#[derive(Clone, Copy, PartialEq)]
enum Mode {
    Pipelined,
    Serial,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Pipelined => "pipelined",
            Mode::Serial => "serial",
        }
    }
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

pub fn run(args: OverlapArgs) -> Result<(), String> {
    if args.runs == 0 || args.runs > 100 {
        return Err("--runs must be in 1..=100".into());
    }
    for (name, v) in [("--seconds", args.seconds), ("--warmup", args.warmup)] {
        if !(v.is_finite() && (0.0..=3600.0).contains(&v)) {
            return Err(format!("{name} must be in [0, 3600]"));
        }
    }
    let scene = demo(&args.scene)?;
    let (width, height) = parse_size(&args.size)?;
    let machine = Machine::here();
    println!("## isoray-bench overlap\n");
    println!(
        "machine: {} (nproc {}); load average at start: {}",
        machine.cpu,
        machine.nproc,
        load_average()
    );
    println!(
        "scene {} ({} balls), {width}x{height}, one viewer, still camera, every frame \
         acknowledged; {} s measured per run after {} s of warm-up\n",
        scene.id(),
        scene.ball_count(),
        args.seconds,
        args.warmup
    );
    let alone = if args.no_alone {
        None
    } else {
        Some(alone(scene, width, height, args.threads, args.shadows)?)
    };
    if let Some(a) = &alone {
        println!(
            "alone (nothing else running, median of 3): build {:.1} ms, trace {:.1} ms, encode \
             {:.1} ms; build + trace {:.1} ms; CPU time build {:.0} ms, trace {:.0} ms, encode \
             {:.0} ms: work bound on {} cores {:.1} ms\n",
            a.build_ms,
            a.trace_ms,
            a.encode_ms,
            a.build_ms + a.trace_ms,
            a.build_cpu_ms,
            a.trace_cpu_ms,
            a.encode_cpu_ms,
            machine.nproc,
            a.work_bound_ms(machine.nproc)
        );
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("runtime: {e}"))?;
    let (base, stop) = match &args.url {
        Some(url) => (url.trim_end_matches('/').to_string(), None),
        None => {
            let (addr, stop) = start_server(&runtime, args.threads)?;
            (format!("http://{addr}"), Some(stop))
        }
    };
    let ws = base
        .strip_prefix("http://")
        .map(|rest| format!("ws://{rest}/api/v1/scenes/{}/stream", scene.id()))
        .ok_or_else(|| format!("--url {base:?}: expected http://HOST:PORT"))?;
    println!("| run | mode | frames | new states | interval ms | build ms | trace ms | encode ms | max(b,t) ms | b+t ms | interval/max | interval/sum | busy cores | load avg |");
    println!("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    let mut rows = Vec::new();
    for run in 0..args.runs {
        for mode in [Mode::Pipelined, Mode::Serial] {
            let (samples, busy_cores) = runtime.block_on(viewer(
                &ws,
                (width, height),
                args.shadows,
                mode,
                Duration::from_secs_f64(args.warmup),
                Duration::from_secs_f64(args.seconds),
            ))?;
            let mut row = summarize(run + 1, &samples, load_average());
            row.mode = mode.name();
            row.busy_cores = busy_cores.filter(|_| args.url.is_none());
            print_row(&row.run.to_string(), &row);
            rows.push(row);
        }
    }
    if let Some(stop) = stop {
        let _ = stop.send(());
    }
    let summary: Vec<RunRow> = [Mode::Pipelined, Mode::Serial]
        .into_iter()
        .map(|mode| medians(mode.name(), &rows))
        .collect();
    for row in &summary {
        print_row("median", row);
    }
    if let Some(path) = &args.json {
        let report = Report {
            machine: machine.line(),
            scene: scene.id().into(),
            width,
            height,
            alone,
            runs: rows,
            median: summary,
        };
        write_json(path, &report)?;
    }
    Ok(())
}

/// The median of the runs' medians of one mode.
fn medians(mode: &'static str, all: &[RunRow]) -> RunRow {
    let rows: Vec<&RunRow> = all.iter().filter(|r| r.mode == mode).collect();
    let pick = |f: fn(&RunRow) -> f64| median(rows.iter().map(|r| f(r)).collect());
    RunRow {
        run: 0,
        mode,
        frames: rows.iter().map(|r| r.frames).sum(),
        fresh_frames: rows.iter().map(|r| r.fresh_frames).sum(),
        interval_ms: pick(|r| r.interval_ms),
        build_ms: pick(|r| r.build_ms),
        trace_ms: pick(|r| r.trace_ms),
        encode_ms: pick(|r| r.encode_ms),
        max_build_trace_ms: pick(|r| r.max_build_trace_ms),
        sum_build_trace_ms: pick(|r| r.sum_build_trace_ms),
        ratio_to_max: pick(|r| r.ratio_to_max),
        ratio_to_sum: pick(|r| r.ratio_to_sum),
        busy_cores: rows
            .iter()
            .map(|r| r.busy_cores)
            .collect::<Option<Vec<f64>>>()
            .map(median),
        load_average: load_average(),
    }
}

fn print_row(name: &str, r: &RunRow) {
    println!(
        "| {name} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} | {} | {} |",
        r.mode,
        r.frames,
        r.fresh_frames,
        r.interval_ms,
        r.build_ms,
        r.trace_ms,
        r.encode_ms,
        r.max_build_trace_ms,
        r.sum_build_trace_ms,
        r.ratio_to_max,
        r.ratio_to_sum,
        r.busy_cores.map_or("-".into(), |c| format!("{c:.2}")),
        r.load_average
    );
}

/// Medians over the frames that show a new state (a repeated state's header has no build).
fn summarize(run: usize, samples: &[Sample], load_average: String) -> RunRow {
    let fresh: Vec<&Sample> = samples.iter().filter(|s| s.fresh).collect();
    let of = |f: fn(&Sample) -> f64| median(fresh.iter().map(|s| f(s)).collect());
    let interval = of(|s| s.interval_ms);
    let max = of(|s| s.build_ms.max(s.trace_ms));
    let sum = of(|s| s.build_ms + s.trace_ms);
    RunRow {
        run,
        mode: "",
        frames: samples.len(),
        fresh_frames: fresh.len(),
        interval_ms: interval,
        build_ms: of(|s| s.build_ms),
        trace_ms: of(|s| s.trace_ms),
        encode_ms: of(|s| s.encode_ms),
        max_build_trace_ms: max,
        sum_build_trace_ms: sum,
        ratio_to_max: interval / max.max(1e-9),
        ratio_to_sum: interval / sum.max(1e-9),
        busy_cores: None,
        load_average,
    }
}

/// The server in-process on loopback; the sender stops it.
fn start_server(
    runtime: &tokio::runtime::Runtime,
    threads: usize,
) -> Result<(std::net::SocketAddr, tokio::sync::oneshot::Sender<()>), String> {
    let config = <Config as clap::Parser>::try_parse_from([
        "isoray",
        "--listen",
        "127.0.0.1:0",
        "--threads",
        &threads.to_string(),
        "--log",
        "warn",
        "--demos-only",
        "--backend",
        "cpu",
        "--min-scale",
        "1",
        "--still-after-ms",
        "600000",
    ])
    .map_err(|e| format!("config: {e}"))?;
    let server = serve_in_process(runtime, config)?;
    Ok((server.addr, server.stop))
}

/// One build and one trace of the state at 1 s with nothing else running: medians of 3.
fn alone(
    scene: isoray_render::scenes::DemoScene,
    width: u32,
    height: u32,
    threads: usize,
    shadows: bool,
) -> Result<Alone, String> {
    let backend = Backend::cpu(threads).map_err(|e| e.to_string())?;
    // The server's build pool: its own pool of the same size.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| e.to_string())?;
    let view = scene.default_view(width, height);
    let mut effects = scene.lighting().effects;
    effects.shadows |= shadows;
    let (mut build, mut trace, mut encode) = (Vec::new(), Vec::new(), Vec::new());
    // CPU time summed over the repetitions (the clock ticks at 100 Hz), then per repetition.
    let mut cpu = [0.0f64; 3];
    let now_cpu = || cpu_seconds().unwrap_or(f64::NAN);
    const REPS: usize = 3;
    for i in 0..REPS {
        let time = 1.0 + i as f64 / 30.0;
        let (t0, c0) = (Instant::now(), now_cpu());
        let prepared = pool.install(|| Arc::new(scene.state_at(time)).prepare());
        build.push(t0.elapsed().as_secs_f64() * 1e3);
        let (t1, c1) = (Instant::now(), now_cpu());
        let (fb, _) = backend.render_effects(&prepared, &view, &effects);
        trace.push(t1.elapsed().as_secs_f64() * 1e3);
        let (t2, c2) = (Instant::now(), now_cpu());
        isoray_server::encode::jpeg(&fb, 80).map_err(|e| e.to_string())?;
        encode.push(t2.elapsed().as_secs_f64() * 1e3);
        let c3 = now_cpu();
        for (slot, spent) in cpu.iter_mut().zip([c1 - c0, c2 - c1, c3 - c2]) {
            *slot += spent * 1e3 / REPS as f64;
        }
    }
    Ok(Alone {
        build_ms: median(build),
        trace_ms: median(trace),
        encode_ms: median(encode),
        build_cpu_ms: cpu[0],
        trace_cpu_ms: cpu[1],
        encode_cpu_ms: cpu[2],
    })
}

/// One viewer: the frames after `warmup`, for `seconds`, and the process's busy cores (CPU
/// seconds per wall second) from the first measured frame to the last.
async fn viewer(
    url: &str,
    size: (u32, u32),
    shadows: bool,
    mode: Mode,
    warmup: Duration,
    seconds: Duration,
) -> Result<(Vec<Sample>, Option<f64>), String> {
    let (mut ws, _) = tokio::time::timeout(
        Duration::from_secs(30),
        tokio_tungstenite::connect_async(url),
    )
    .await
    .map_err(|_| "connect: no answer in 30 s".to_string())?
    .map_err(|e| format!("connect: {e}"))?;
    let resize =
        serde_json::json!({"type": "resize", "input_id": 1, "width": size.0, "height": size.1});
    ws.send(Message::Text(resize.to_string().into()))
        .await
        .map_err(|e| format!("send: {e}"))?;
    if shadows {
        let effects =
            serde_json::json!({"type": "effects", "input_id": 2, "effects": {"shadows": true}});
        ws.send(Message::Text(effects.to_string().into()))
            .await
            .map_err(|e| format!("send: {e}"))?;
    }
    // Serial: the time pinned last (and its input id), far from the live clock's states.
    let mut pinned = (3, 1000.0f64);
    if mode == Mode::Serial {
        pin(&mut ws, pinned).await?;
    }
    let start = Instant::now();
    let (measure_from, end) = (start + warmup, start + warmup + seconds);
    let mut last: Option<(Instant, f64)> = None;
    let mut samples = Vec::new();
    let mut cpu: Option<(Instant, f64)> = None;
    let mut busy = None;
    while Instant::now() < end {
        let msg = tokio::time::timeout(Duration::from_secs(60), ws.next())
            .await
            .map_err(|_| "no frame in 60 s".to_string())?
            .ok_or("the server closed the stream")?
            .map_err(|e| format!("websocket: {e}"))?;
        let bytes = match msg {
            Message::Binary(bytes) => bytes,
            Message::Text(text) => {
                if let Ok(ServerMessage::Error(e)) = serde_json::from_str(text.as_str()) {
                    return Err(format!("server error {}: {}", e.code, e.message));
                }
                continue;
            }
            Message::Close(frame) => return Err(format!("closed by the server: {frame:?}")),
            _ => continue,
        };
        let now = Instant::now();
        let header = FrameHeader::decode(&bytes).map_err(|e| format!("frame header: {e:?}"))?;
        let ack = serde_json::json!({"type": "ack", "sequence": header.sequence});
        ws.send(Message::Text(ack.to_string().into()))
            .await
            .map_err(|e| format!("send: {e}"))?;
        let sized = (header.width, header.height) == size && header.flags & FLAG_STILL == 0;
        // Serial: only the frames of the time pinned last count, and each pins the next.
        if mode == Mode::Serial {
            if header.scene_time != pinned.1 || header.input_id < pinned.0 {
                continue;
            }
            pinned = (pinned.0 + 1, pinned.1 + 1.0 / 30.0);
            pin(&mut ws, pinned).await?;
        }
        if let Some((previous, previous_time)) = last.filter(|_| now >= measure_from && sized) {
            match (cpu, cpu_seconds()) {
                (None, Some(c)) => cpu = Some((now, c)),
                (Some((t0, c0)), Some(c)) => {
                    busy = Some((c - c0) / now.duration_since(t0).as_secs_f64().max(1e-9))
                }
                (_, None) => {}
            }
            let t = header.timings;
            samples.push(Sample {
                interval_ms: now.duration_since(previous).as_secs_f64() * 1e3,
                build_ms: (t.update_us as f64 + t.build_us as f64) / 1e3,
                trace_ms: t.trace_us as f64 / 1e3,
                encode_ms: t.encode_us as f64 / 1e3,
                fresh: header.scene_time != previous_time,
            });
        }
        last = Some((now, header.scene_time));
    }
    let _ = ws.close(None).await;
    if samples.is_empty() {
        return Err(format!("no {}x{} frames after the warm-up", size.0, size.1));
    }
    Ok((samples, busy))
}

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// Pins the scene `time` with input `id`.
async fn pin(ws: &mut Socket, (id, time): (u64, f64)) -> Result<(), String> {
    let input = serde_json::json!({"type": "time", "input_id": id, "time": time});
    ws.send(Message::Text(input.to_string().into()))
        .await
        .map_err(|e| format!("send: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(interval_ms: f64, build_ms: f64, trace_ms: f64, fresh: bool) -> Sample {
        Sample {
            interval_ms,
            build_ms,
            trace_ms,
            encode_ms: 1.0,
            fresh,
        }
    }

    #[test]
    fn medians_are_over_the_frames_that_show_a_new_state() {
        let samples = [
            sample(100.0, 60.0, 90.0, true),
            sample(110.0, 80.0, 100.0, true),
            sample(120.0, 120.0, 70.0, true),
            // A repeated state: no build in its header; left out.
            sample(5.0, 0.0, 1.0, false),
        ];
        let row = summarize(1, &samples, "0 0 0".into());
        assert_eq!((row.frames, row.fresh_frames), (4, 3));
        assert_eq!(row.interval_ms, 110.0);
        assert_eq!((row.build_ms, row.trace_ms), (80.0, 90.0));
        // Per-frame max: 90, 100, 120; per-frame sum: 150, 180, 190.
        assert_eq!(row.max_build_trace_ms, 100.0);
        assert_eq!(row.sum_build_trace_ms, 180.0);
        assert!((row.ratio_to_max - 1.1).abs() < 1e-12);
        assert!((row.ratio_to_sum - 110.0 / 180.0).abs() < 1e-12);
    }
}
