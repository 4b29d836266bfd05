//! `isoray-bench ingest`: how fast simulation state goes into the scene store.
//!
//! Starts the server in-process on loopback with a fresh data directory, creates a metaball
//! scene, and pushes `--steps` steps of `--particles` balls (`x y z radius`, little-endian f32)
//! as `.npy` bodies over real HTTP, one after another, as a simulation would. A push is
//! answered only once its step file is written, fsynced, renamed into place and its
//! directory fsynced, so the time covers the whole path into the store: socket, streaming
//! parser, value checks, checksum, write and fsync. The figure is body bytes per second
//! (MB = 10⁶ bytes), the median over `--runs`; each run uses a new scene, deleted afterwards.
//! Issue 5 asks for at least 200 MB/s for 100 steps of 1M particles.

use crate::common::{median, serve_in_process, write_json, InProcess, Machine};
use clap::Args;
use isoray_server::api::client::{npy_header_f32, Body, Client};
use isoray_server::Config;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct IngestArgs {
    /// Steps pushed per run.
    #[arg(long, default_value_t = 100)]
    steps: usize,
    /// Balls per step.
    #[arg(long, default_value_t = 1_000_000)]
    particles: usize,
    /// Timed runs; the median is reported.
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Where the store lives during the benchmark (default: a new directory under the
    /// system's temporary directory, removed afterwards). The disk is part of what is measured.
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Also write the results as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
}

#[derive(Serialize)]
struct Run {
    seconds: f64,
    bytes: u64,
    mb_per_s: f64,
    step_ms_median: f64,
    step_ms_max: f64,
}

#[derive(Serialize)]
struct Report {
    machine: Machine,
    steps: usize,
    particles: usize,
    body_bytes_per_step: usize,
    runs: Vec<Run>,
    median_mb_per_s: f64,
}

/// Two different step bodies, alternated so that consecutive steps differ.
fn bodies(particles: usize) -> [Vec<u8>; 2] {
    [0u32, 1].map(|seed| {
        let mut out = npy_header_f32(particles as u64, 4);
        out.reserve(particles * 16);
        let mut h = 0x9e37_79b9u32 ^ seed;
        for _ in 0..particles {
            for k in 0..4 {
                h ^= h << 13;
                h ^= h >> 17;
                h ^= h << 5;
                let u = (h % 1_000_000) as f32 / 1_000_000.0;
                let v = if k == 3 {
                    0.02 + 0.03 * u
                } else {
                    4.0 * u - 2.0
                };
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    })
}

pub fn run(args: IngestArgs) -> Result<(), String> {
    let runs = args.runs.max(1);
    let temp = match &args.data_dir {
        Some(_) => None,
        None => Some(tempfile::tempdir().map_err(|e| format!("temp dir: {e}"))?),
    };
    let dir = args
        .data_dir
        .clone()
        .or_else(|| temp.as_ref().map(|t| t.path().to_path_buf()))
        .ok_or("no data directory")?;
    let body_bytes = npy_header_f32(args.particles as u64, 4).len() + args.particles * 16;
    let budget = ((body_bytes as u64) * (args.steps as u64 + 1))
        .max(1 << 30)
        .to_string();
    let config = <Config as clap::Parser>::try_parse_from([
        "isoray",
        "--listen",
        "127.0.0.1:0",
        "--threads",
        "1",
        "--log",
        "warn",
        "--data-dir",
        &dir.to_string_lossy(),
        "--max-primitives",
        &args.particles.max(1).to_string(),
        "--max-push-bytes",
        &(body_bytes as u64 + 1).to_string(),
        "--max-steps-per-scene",
        &args.steps.max(1).to_string(),
        "--max-scene-bytes",
        &budget,
        "--max-store-bytes",
        &budget,
        "--write-rate",
        "100000",
        "--write-burst",
        "100000",
    ])
    .map_err(|e| format!("config: {e}"))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("runtime: {e}"))?;
    let InProcess {
        addr,
        stop: stop_tx,
        task: server,
    } = serve_in_process(&runtime, config)?;
    let client = Client::new(&format!("http://{addr}")).map_err(|e| e.to_string())?;
    let bodies = bodies(args.particles);

    let mut results = Vec::new();
    for run in 0..runs {
        let r = client
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"kind":"metaballs","name":"ingest benchmark"}"#),
            )
            .map_err(|e| e.to_string())?;
        let created: serde_json::Value = r.json().map_err(|e| e.to_string())?;
        let (Some(id), Some(token)) = (
            created["scene"]["id"].as_str(),
            created["write_token"].as_str(),
        ) else {
            return Err(format!("creating a scene: {}", r.text()));
        };
        let auth = format!("Bearer {token}");
        let headers = [
            ("Content-Type", "application/x-npy"),
            ("Authorization", auth.as_str()),
        ];
        let mut step_ms = Vec::with_capacity(args.steps);
        let mut bytes = 0u64;
        let t0 = Instant::now();
        for step in 0..args.steps {
            let body = &bodies[step % 2];
            let t = Instant::now();
            let r = client
                .request(
                    "PUT",
                    &format!("/api/v1/scenes/{id}/steps/{step}"),
                    &headers,
                    Body::Bytes(body),
                )
                .map_err(|e| format!("step {step}: {e}"))?;
            if r.status != 201 {
                return Err(format!("step {step}: {} {}", r.status, r.text()));
            }
            step_ms.push(t.elapsed().as_secs_f64() * 1e3);
            bytes += body.len() as u64;
        }
        let seconds = t0.elapsed().as_secs_f64();
        let r = client
            .request(
                "DELETE",
                &format!("/api/v1/scenes/{id}"),
                &[("Authorization", auth.as_str())],
                Body::Empty,
            )
            .map_err(|e| e.to_string())?;
        if r.status != 204 {
            return Err(format!("deleting the scene: {} {}", r.status, r.text()));
        }
        let max = step_ms.iter().copied().fold(0.0, f64::max);
        let result = Run {
            seconds,
            bytes,
            mb_per_s: bytes as f64 / 1e6 / seconds,
            step_ms_median: median(step_ms),
            step_ms_max: max,
        };
        eprintln!(
            "run {}: {:.0} MB in {:.2} s = {:.0} MB/s",
            run + 1,
            bytes as f64 / 1e6,
            seconds,
            result.mb_per_s
        );
        results.push(result);
    }
    let _ = stop_tx.send(());
    let _ = runtime.block_on(server);

    let report = Report {
        machine: Machine::here(),
        steps: args.steps,
        particles: args.particles,
        body_bytes_per_step: body_bytes,
        median_mb_per_s: median(results.iter().map(|r| r.mb_per_s).collect()),
        runs: results,
    };
    println!(
        "Store ingest: {} steps × {} particles as .npy (<f4, 4 columns, {} bytes per body), \
         pushed over loopback HTTP into {}",
        report.steps,
        report.particles,
        report.body_bytes_per_step,
        dir.display()
    );
    println!("machine: {}", report.machine.line());
    println!();
    println!("| run | seconds | MB/s | step ms (median) | step ms (max) |");
    println!("| --- | ---: | ---: | ---: | ---: |");
    for (i, r) in report.runs.iter().enumerate() {
        println!(
            "| {} | {:.2} | {:.0} | {:.1} | {:.1} |",
            i + 1,
            r.seconds,
            r.mb_per_s,
            r.step_ms_median,
            r.step_ms_max
        );
    }
    println!();
    println!(
        "median: {:.0} MB/s (target ≥ 200 MB/s)",
        report.median_mb_per_s
    );
    if let Some(path) = &args.json {
        write_json(path, &report)?;
    }
    drop(temp);
    Ok(())
}
