//! The REST API and the scene store over real sockets: wrong pushes, crash safety under
//! SIGKILL, the Python example watched live over a websocket, limits, and the OpenAPI document.

mod auth;
mod bad_balls;
mod cli;
mod cors;
mod crash;
mod deforming;
mod depth;
mod disk_full;
mod limits;
mod look;
mod molecules;
mod openapi;
mod particles;
mod passes;
mod peers;
mod push_errors;
mod python_client;
mod python_example;
mod restart;
mod schemathesis;
mod slow_body;
mod slow_headers;
mod step_time;
mod surfel_files;
mod surfels;
mod tets;
mod vtk_files;

use isoray_server::api::client::{npy_header_f32, Body, Client, Response};
use isoray_server::{AppState, Config};
use serde_json::Value;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::Duration;

/// A server in-process on an ephemeral port over a data directory.
pub struct Server {
    pub base: String,
    pub addr: std::net::SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    handle: Option<tokio::task::JoinHandle<std::io::Result<()>>>,
}

impl Server {
    /// Starts with `--data-dir data_dir` plus `extra` flags.
    pub async fn start(data_dir: &Path, extra: &[&str]) -> Server {
        let dir = data_dir.to_str().expect("utf-8 temp path").to_string();
        let mut argv = vec![
            "isoray",
            "--listen",
            "127.0.0.1:0",
            "--threads",
            "2",
            "--data-dir",
            &dir,
        ];
        argv.extend_from_slice(extra);
        let config = <Config as clap::Parser>::parse_from(argv);
        let state = AppState::new(config).expect("valid config");
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let addr = listener.local_addr().expect("addr");
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let handle = tokio::spawn(isoray_server::serve(listener, state, async move {
            let _ = rx.await;
        }));
        Server {
            base: format!("http://{addr}"),
            addr,
            stop: Some(tx),
            handle: Some(handle),
        }
    }

    pub async fn stop(mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if let Some(h) = self.handle.take() {
            h.await.expect("server task").expect("server ran");
        }
    }
}

/// Runs `isoray push --server base ARGS...` (options and files); returns whether it
/// succeeded and its stdout and stderr together.
pub fn push_files<S: AsRef<std::ffi::OsStr>>(base: &str, args: &[S]) -> (bool, String) {
    let out = Command::new(isoray_binary())
        .arg("push")
        .args(["--server", base])
        .args(args)
        .output()
        .expect("isoray push runs");
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

/// The id `isoray push` printed for the scene it created.
pub fn created_scene_id(text: &str) -> String {
    text.lines()
        .find_map(|l| l.strip_prefix("created scene "))
        .unwrap_or_else(|| panic!("the new scene's id is printed: {text}"))
        .trim()
        .to_string()
}

/// Runs a fixture script of `tests/fixtures` with `ISORAY_PYTHON`, writing into `dir`;
/// returns what it printed.
pub fn run_fixture(script: &str, dir: &Path) -> String {
    let out = Command::new(python())
        .arg(repo_root().join("tests/fixtures").join(script))
        .arg(dir)
        .output()
        .expect("python runs (CI installs numpy, meshio and vtk into ISORAY_PYTHON)");
    assert!(
        out.status.success(),
        "the fixture script {script} ran: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `POST .../render` of `step` at 48×36 with the scene's own camera and isovalue: the PNG.
pub fn render_png(base: &str, id: &str, step: u64) -> Vec<u8> {
    let r = Client::new(base)
        .expect("url")
        .request(
            "POST",
            &format!("/api/v1/scenes/{id}/render"),
            &[("Content-Type", "application/json")],
            Body::Bytes(format!(r#"{{"step":{step},"width":48,"height":36}}"#).as_bytes()),
        )
        .expect("answer");
    assert_eq!(r.status, 200, "{}", r.text());
    r.body
}

/// Runs blocking client calls off the runtime.
pub async fn call<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f).await.expect("client thread")
}

pub fn json(r: &Response) -> Value {
    serde_json::from_slice(&r.body).unwrap_or_else(|e| panic!("JSON body ({e}): {}", r.text()))
}

/// A `.npy` of little-endian f32 rows.
pub fn npy(values: &[f32], columns: u32) -> Vec<u8> {
    let mut out = npy_header_f32((values.len() / columns as usize) as u64, columns);
    out.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    out
}

/// Creates a metaball scene; returns its id and write token.
pub fn create(base: &str) -> (String, String) {
    let c = Client::new(base).expect("url");
    let r = c
        .request(
            "POST",
            "/api/v1/scenes",
            &[("Content-Type", "application/json")],
            Body::Bytes(br#"{"kind":"metaballs"}"#),
        )
        .expect("create");
    assert_eq!(r.status, 201, "{}", r.text());
    let v = json(&r);
    (
        v["scene"]["id"].as_str().expect("id").into(),
        v["write_token"].as_str().expect("token").into(),
    )
}

pub fn push(base: &str, id: &str, index: &str, token: &str, ct: &str, body: &[u8]) -> Response {
    let auth = format!("Bearer {token}");
    Client::new(base)
        .expect("url")
        .request(
            "PUT",
            &format!("/api/v1/scenes/{id}/steps/{index}"),
            &[("Content-Type", ct), ("Authorization", &auth)],
            Body::Bytes(body),
        )
        .expect("push answered")
}

pub fn get(base: &str, path: &str) -> Response {
    Client::new(base)
        .expect("url")
        .request("GET", path, &[], Body::Empty)
        .expect("answer")
}

pub fn steps(base: &str, id: &str) -> Value {
    json(&get(base, &format!("/api/v1/scenes/{id}/steps")))["steps"].clone()
}

/// Index → checksum of each step in a `steps` list as the API returns it.
pub fn step_checksums(steps: &Value) -> BTreeMap<u64, String> {
    steps
        .as_array()
        .expect("steps")
        .iter()
        .map(|s| {
            (
                s["index"].as_u64().expect("index"),
                s["checksum"].as_str().expect("checksum").to_string(),
            )
        })
        .collect()
}

pub const NPY: &str = "application/x-npy";

/// Every file under `root` (relative path → XXH3-128 of its bytes): what "nothing stored
/// changed" is checked against.
pub fn store_snapshot(root: &Path) -> BTreeMap<String, u128> {
    let mut out = BTreeMap::new();
    for path in walk(root) {
        if path.is_file() {
            let rel = path
                .strip_prefix(root)
                .expect("under root")
                .display()
                .to_string();
            let bytes = std::fs::read(&path).expect("read store file");
            out.insert(rel, xxhash_rust::xxh3::xxh3_128(&bytes));
        }
    }
    out
}

/// Every path under `p`, recursively.
pub fn walk(p: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(p) {
        for e in entries.flatten() {
            let path = e.path();
            out.push(path.clone());
            if path.is_dir() {
                out.extend(walk(&path));
            }
        }
    }
    out
}

/// Paths under `root` that are temporary files of an unfinished write.
pub fn temp_files(root: &Path) -> Vec<PathBuf> {
    walk(root)
        .into_iter()
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(".tmp-"))
        })
        .collect()
}

/// The `isoray` binary of this build profile, built (or brought up to date) on first use so
/// that `cargo test -p isoray-tests` alone also tests the current code. It is built with the
/// cargo features this test build linked the server with (`isoray_server::metrics::features`),
/// so under `cargo test --all-features` it is the very binary `.ci/run` built with
/// `--all-features` (cargo finds it fresh) rather than a default-features rebuild.
pub fn isoray_binary() -> &'static Path {
    static BINARY: OnceLock<PathBuf> = OnceLock::new();
    BINARY.get_or_init(|| {
        let exe = std::env::current_exe().expect("test executable path");
        // target/<profile>/deps/root-<hash>
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("test binary lives in target/<profile>/deps");
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = std::process::Command::new(cargo);
        cmd.args(["build", "-p", "isoray-server", "--bin", "isoray"]);
        if !isoray_server::metrics::default_features() {
            cmd.arg("--no-default-features");
        }
        let features = isoray_server::metrics::features();
        if !features.is_empty() {
            cmd.args(["--features", &features]);
        }
        if profile_dir.file_name().is_some_and(|n| n == "release") {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("cargo runs");
        assert!(status.success(), "building the isoray binary failed");
        let binary = profile_dir.join(format!("isoray{}", std::env::consts::EXE_SUFFIX));
        assert!(binary.exists(), "{} was built", binary.display());
        binary
    })
}

/// The Python interpreter the tests use: `$ISORAY_PYTHON` (CI points it at a virtual
/// environment with NumPy and openapi-spec-validator), else `python3`.
pub fn python() -> String {
    std::env::var("ISORAY_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// The repository root (for `examples/`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ is inside the repository")
        .to_path_buf()
}

/// The base URL (`http://HOST:PORT`) a starting `isoray` prints on `stdout`. The child's
/// output is drained for its whole life, so it never blocks on a full pipe.
pub fn served_address(stdout: std::process::ChildStdout) -> String {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(at) = line.find("http://") {
                let url: String = line[at..]
                    .chars()
                    .take_while(|c| !c.is_whitespace())
                    .collect();
                let _ = tx.send(url.trim_end_matches('/').to_string());
            }
        }
    });
    rx.recv_timeout(Duration::from_secs(60))
        .expect("isoray prints the address it serves on")
}

/// A running `isoray` child process and its base URL.
pub struct Process {
    child: Child,
    pub base: String,
}

impl Process {
    pub fn start(data_dir: &Path) -> Process {
        let dir = data_dir.to_str().expect("utf-8 path");
        Process::spawn(&["--data-dir", dir], &[])
    }

    /// Starts `isoray --listen 127.0.0.1:0 --threads 1 ARGS` with extra environment variables.
    pub fn spawn(args: &[&str], env: &[(&str, &std::ffi::OsStr)]) -> Process {
        let mut child = Command::new(isoray_binary())
            .args(["--listen", "127.0.0.1:0", "--threads", "1", "--log", "info"])
            .args(args)
            .envs(env.iter().copied())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("isoray starts");
        let stdout = child.stdout.take().expect("piped stdout");
        let base = served_address(stdout);
        Process { child, base }
    }

    /// SIGKILL: no shutdown code runs.
    pub fn kill(mut self) {
        self.child.kill().expect("SIGKILL");
        self.child.wait().expect("reaped");
    }
}
