//! Helpers every benchmark shares: the machine line printed with each table, medians, and
//! writing the `--json` report.

use isoray_render::scenes::DemoScene;
use serde::Serialize;
use std::path::Path;

/// The machine a table was measured on: CPU model, `nproc`, and the worker threads used.
#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    pub cpu: String,
    pub nproc: usize,
    pub threads: usize,
    /// `portable build (x86_64)` or the instruction-set extensions the build uses.
    pub build: String,
}

impl Machine {
    pub fn here() -> Machine {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split(':').nth(1))
                    .map(|m| m.trim().to_string())
            })
            .unwrap_or_else(|| "unknown CPU".into());
        Machine {
            cpu,
            nproc: std::thread::available_parallelism().map_or(1, |n| n.get()),
            threads: rayon::current_num_threads(),
            build: isoray_render::cpu::build_line(),
        }
    }

    pub fn line(&self) -> String {
        format!(
            "{} (nproc {}), {} worker threads, {}",
            self.cpu, self.nproc, self.threads, self.build
        )
    }
}

/// The median of `v` (the upper one of an even count); 0 when empty.
/// The `q` quantile (0..=1) of sorted `v`, nearest rank; 0 when empty.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The demos named by `ids` (scene ids), or `default`'s when `ids` is empty; an unknown id
/// is an error naming it.
pub fn demos(ids: &[String], default: &[&str]) -> Result<Vec<DemoScene>, String> {
    let find = |id: &str| {
        DemoScene::ALL
            .into_iter()
            .find(|d| d.id() == id)
            .ok_or_else(|| format!("unknown scene {id:?}"))
    };
    if ids.is_empty() {
        default.iter().map(|id| find(id)).collect()
    } else {
        ids.iter().map(|id| find(id)).collect()
    }
}

/// `n / d`, 0 when `d` is 0.
pub fn per(n: u64, d: u64) -> f64 {
    n as f64 / d.max(1) as f64
}

/// Writes `report` as pretty JSON to `path`.
pub fn write_json(path: &Path, report: &impl Serialize) -> Result<(), String> {
    let text = serde_json::to_string_pretty(report).map_err(|e| e.to_string())?;
    std::fs::write(path, text).map_err(|e| format!("could not write {}: {e}", path.display()))
}

/// A server started in-process on a loopback port: its address, the sender that stops it,
/// and the task that ends when it has stopped.
pub struct InProcess {
    pub addr: std::net::SocketAddr,
    pub stop: tokio::sync::oneshot::Sender<()>,
    pub task: tokio::task::JoinHandle<std::io::Result<()>>,
}

/// Starts the server with `config` on `runtime`, listening on a free loopback port.
pub fn serve_in_process(
    runtime: &tokio::runtime::Runtime,
    config: isoray_server::Config,
) -> Result<InProcess, String> {
    let state = isoray_server::AppState::new(config).map_err(|e| format!("server: {e}"))?;
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .map_err(|e| format!("bind: {e}"))?;
    let addr = listener.local_addr().map_err(|e| format!("addr: {e}"))?;
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let task = runtime.spawn(isoray_server::serve(listener, state, async move {
        let _ = stopped.await;
    }));
    Ok(InProcess { addr, stop, task })
}
