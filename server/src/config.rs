//! Command-line flags, each with an environment-variable fallback and a default that works
//! with no flags, files or network.

use clap::Parser;
use std::net::SocketAddr;
use std::path::PathBuf;

/// isoray: a remote ray tracer for dynamic implicit surfaces and isosurfaces.
#[derive(Clone, Debug, Parser)]
#[command(
    name = "isoray",
    version,
    about,
    after_help = "Other commands: `isoray push --help` (push .npy, particle, VTK, molecule, point-cloud or mesh files to a server as a scene's steps), \
                  `isoray render --help` (one image of a scene, offline)."
)]
pub struct Config {
    /// Address to listen on.
    #[arg(long, env = "ISORAY_LISTEN", default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,

    /// Render worker threads (0: one per core), at most 1024.
    #[arg(long, env = "ISORAY_THREADS", default_value_t = 0)]
    pub threads: usize,

    /// Log filter, in tracing's EnvFilter syntax (e.g. `info`, `isoray_server=debug`).
    #[arg(long, env = "ISORAY_LOG", default_value = "info")]
    pub log: String,

    /// Largest frame width and height a client may ask for.
    #[arg(long, env = "ISORAY_MAX_SIZE", default_value_t = 4096)]
    pub max_size: u32,

    /// Frame size a session starts with, before the client's first `resize`.
    #[arg(long, env = "ISORAY_DEFAULT_WIDTH", default_value_t = 640)]
    pub default_width: u32,
    #[arg(long, env = "ISORAY_DEFAULT_HEIGHT", default_value_t = 360)]
    pub default_height: u32,

    /// Highest frame rate a session is streamed at while its scene animates.
    #[arg(long, env = "ISORAY_MAX_FPS", default_value_t = 30.0)]
    pub max_fps: f64,

    /// Smallest resolution scale of interactive frames (the still frame is always full size).
    #[arg(long, env = "ISORAY_MIN_SCALE", default_value_t = 0.125)]
    pub min_scale: f64,

    /// Share of the render pool that the interactive frames of all viewers together are
    /// sized to use, in (0, 1). Higher gives many viewers larger frames at the cost of their
    /// tail latency (docs/performance.md, "Load"); a lone viewer's frame takes at most 0.6 of
    /// its interval whatever this is.
    #[arg(long, env = "ISORAY_POOL_SHARE", default_value_t = 0.6)]
    pub pool_share: f64,

    /// Milliseconds without input after which a still view gets its lossless frame.
    #[arg(long, env = "ISORAY_STILL_AFTER_MS", default_value_t = 150)]
    pub still_after_ms: u64,

    /// Seconds between websocket pings to each client.
    #[arg(long, env = "ISORAY_PING_INTERVAL_SECS", default_value_t = 10)]
    pub ping_interval_secs: u64,

    /// Seconds without any message from a client (pongs included) before its session closes.
    #[arg(long, env = "ISORAY_IDLE_TIMEOUT_SECS", default_value_t = 30)]
    pub idle_timeout_secs: u64,

    /// Most concurrent viewer sessions; more are refused with a close reason.
    #[arg(long, env = "ISORAY_MAX_SESSIONS", default_value_t = 64)]
    pub max_sessions: usize,

    /// JPEG quality of streamed frames, 1–100.
    #[arg(long, env = "ISORAY_JPEG_QUALITY", default_value_t = 80)]
    pub jpeg_quality: u8,

    /// Most primitives a scene may hold.
    #[arg(long, env = "ISORAY_MAX_PRIMITIVES", default_value_t = 2_000_000)]
    pub max_primitives: usize,

    /// Directory of the scene store (pushed scenes and their steps). Default: `isoray` under
    /// the user's data directory (`$XDG_DATA_HOME`, else `~/.local/share`), created on demand;
    /// if it cannot be used the server logs a warning and serves its demos only.
    #[arg(long, env = "ISORAY_DATA_DIR")]
    pub data_dir: Option<PathBuf>,

    /// Serve the built-in demos only: no scene store, no pushes.
    #[arg(long, env = "ISORAY_DEMOS_ONLY")]
    pub demos_only: bool,

    /// Token that may push to and delete any scene (`Authorization: Bearer ...`), besides each
    /// scene's own write token. Unset: only per-scene tokens.
    #[arg(long, env = "ISORAY_ADMIN_TOKEN", hide_env_values = true)]
    pub admin_token: Option<String>,

    /// Token needed to view scenes, render, and list or fetch steps (header, or `?token=` on
    /// the websocket). Unset: viewing is open.
    #[arg(long, env = "ISORAY_VIEW_TOKEN", hide_env_values = true)]
    pub view_token: Option<String>,

    /// Largest binary step body (.npy or raw), in bytes.
    #[arg(long, env = "ISORAY_MAX_PUSH_BYTES", default_value_t = 512 << 20)]
    pub max_push_bytes: u64,

    /// Largest JSON body (scene creation, JSON steps, render requests), in bytes.
    #[arg(long, env = "ISORAY_MAX_JSON_BYTES", default_value_t = 32 << 20)]
    pub max_json_bytes: u64,

    /// Seconds a push may take to arrive before it is abandoned.
    #[arg(long, env = "ISORAY_PUSH_TIMEOUT_SECS", default_value_t = 300)]
    pub push_timeout_secs: u64,

    /// Highest step index a push may use.
    #[arg(long, env = "ISORAY_MAX_STEP_INDEX", default_value_t = 1_000_000)]
    pub max_step_index: u64,

    /// Retention: most steps kept per scene (the oldest go first).
    #[arg(long, env = "ISORAY_MAX_STEPS_PER_SCENE", default_value_t = 1000)]
    pub max_steps_per_scene: usize,

    /// Retention: most bytes of steps kept per scene.
    #[arg(long, env = "ISORAY_MAX_SCENE_BYTES", default_value_t = 8 << 30)]
    pub max_scene_bytes: u64,

    /// Retention: most bytes of steps in the whole store.
    #[arg(long, env = "ISORAY_MAX_STORE_BYTES", default_value_t = 32 << 30)]
    pub max_store_bytes: u64,

    /// Bytes of prepared stored steps kept in memory across all scenes.
    #[arg(long, env = "ISORAY_CACHE_BYTES", default_value_t = 1 << 30)]
    pub cache_bytes: u64,

    /// Writes (creates, pushes, deletes) per second each client address may make on average.
    #[arg(long, env = "ISORAY_WRITE_RATE", default_value_t = 50.0)]
    pub write_rate: f64,

    /// Writes a client may make in a burst above that rate.
    #[arg(long, env = "ISORAY_WRITE_BURST", default_value_t = 200)]
    pub write_burst: u32,

    /// Most reflection/refraction bounces and transparent layers a client or scene may ask for.
    #[arg(long, env = "ISORAY_MAX_RAY_DEPTH", default_value_t = 8)]
    pub max_ray_depth: u32,

    /// Most soft-shadow or occlusion samples per pixel and pass a client or scene may ask for.
    #[arg(long, env = "ISORAY_MAX_SAMPLES", default_value_t = 64)]
    pub max_samples: u32,

    /// Refinement passes a resting view accumulates at most before it stops rendering.
    #[arg(long, env = "ISORAY_MAX_REFINE_PASSES", default_value_t = 64)]
    pub max_refine_passes: u32,

    /// Sub-pixel positions a resting view averages (antialiasing: edges and fine detail
    /// smooth out over its first still frames); 0 or 1: pixel centres only. At most
    /// `--max-refine-passes` of them are traced.
    #[arg(long, env = "ISORAY_ANTIALIAS_PASSES", default_value_t = 8)]
    pub antialias_passes: u32,

    /// This server's name among several behind a load balancer (a DNS label such as a
    /// Kubernetes pod name). New scene ids start with it (`NAME_<hex>`), so the balancer sends
    /// every request for a scene to the server that stores it (see deploy/). Unset: one server.
    #[arg(long, env = "ISORAY_SHARD")]
    pub shard: Option<String>,

    /// Seconds a client may take to send a request's headers, and that an idle keep-alive
    /// connection stays open, before the connection is closed.
    #[arg(long, env = "ISORAY_HEADER_TIMEOUT_SECS", default_value_t = 10)]
    pub header_timeout_secs: u64,

    // --- issue 15: keeping strangers out ---------------------------------------------------
    /// Origins (`scheme://host[:port]`, comma-separated) whose pages may call the API from a
    /// browser (CORS) and open websocket viewers. The server's own origin always may. Unset:
    /// same origin only.
    #[arg(long, env = "ISORAY_ALLOWED_ORIGINS", value_delimiter = ',')]
    pub allowed_origins: Vec<String>,

    /// Most stored scenes; creating one more is refused with 409 until one is deleted.
    #[arg(long, env = "ISORAY_MAX_SCENES", default_value_t = 1000)]
    pub max_scenes: usize,

    /// Token needed to read `/metrics` (`Authorization: Bearer ...`). Unset: open.
    #[arg(long, env = "ISORAY_METRICS_TOKEN", hide_env_values = true)]
    pub metrics_token: Option<String>,

    // --- issue 15: rate limits behind a balancer ---------------------------------------------
    /// Renders (`POST .../render`) per second each client may make on average.
    #[arg(long, env = "ISORAY_RENDER_RATE", default_value_t = 10.0)]
    pub render_rate: f64,

    /// Renders a client may make in a burst above that rate.
    #[arg(long, env = "ISORAY_RENDER_BURST", default_value_t = 40)]
    pub render_burst: u32,

    /// Addresses (`IP` or `IP/PREFIX`, comma-separated) of proxies whose `X-Forwarded-For` is
    /// believed: a request from one of them is rate limited as the client that header names
    /// (the nearest address that is not itself a trusted proxy). Requests from any other peer
    /// are limited by the peer's address, whatever they send. Unset: no proxy is trusted.
    #[arg(long, env = "ISORAY_TRUSTED_PROXY", value_delimiter = ',')]
    pub trusted_proxy: Vec<String>,

    // --- issue 15: every process lists every scene -------------------------------------------
    /// The other processes of this deployment, whose scenes `GET /api/v1/scenes` lists beside
    /// this one's (comma-separated): base URLs (`http://host:port`), or `dns://NAME:PORT` for
    /// every address NAME resolves to (a Kubernetes headless service). A peer that does not
    /// answer in time is named in the list's `unreachable_shards`. Unset: this process only.
    #[arg(long, env = "ISORAY_PEERS", value_delimiter = ',')]
    pub peers: Vec<String>,

    /// Milliseconds to wait for a peer's scene list (and for a `dns://` name to resolve).
    #[arg(long, env = "ISORAY_PEER_TIMEOUT_MS", default_value_t = 800)]
    pub peer_timeout_ms: u64,

    /// Where frames are traced: `cpu`; `gpu` (a wgpu device, software ones such as lavapipe
    /// included; the server needs the `gpu` feature); `auto`: a hardware GPU when there is
    /// one, else the CPU. A GPU that cannot start or fails later leaves the CPU tracing, with
    /// a warning.
    #[arg(long, env = "ISORAY_BACKEND", value_enum, default_value_t = BackendChoice::Auto)]
    pub backend: BackendChoice,

    /// GPU memory, in MiB, the GPU backend may fill with scene arrays and frame buffers (both
    /// of its double-buffered sets together). A scene or frame that needs more is traced on
    /// the CPU, with the reason logged.
    #[arg(long, env = "ISORAY_GPU_MEMORY_MIB", default_value_t = 2048)]
    pub gpu_memory_mib: u64,
}

/// `--backend`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    Cpu,
    Gpu,
    Auto,
}

/// `isoray` under the user's data directory: `$XDG_DATA_HOME/isoray`, else
/// `~/.local/share/isoray`.
pub fn default_data_dir() -> Option<PathBuf> {
    let from_env = |name: &str| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    from_env("XDG_DATA_HOME")
        .filter(|p| p.is_absolute())
        .or_else(|| from_env("HOME").map(|h| h.join(".local").join("share")))
        .map(|d| d.join("isoray"))
}

/// Checks that `origin` is `http(s)://host[:port]`, as browsers send it.
pub fn validate_origin(origin: &str) -> Result<(), String> {
    let bad = || format!("--allowed-origins `{origin}` is not http(s)://host[:port]");
    let (scheme, authority) = origin.split_once("://").ok_or_else(bad)?;
    if !matches!(scheme, "http" | "https")
        || authority.is_empty()
        || authority.contains(['/', '?', '#', '@', ' '])
        || axum::http::HeaderValue::from_str(origin).is_err()
    {
        return Err(bad());
    }
    Ok(())
}

impl Default for Config {
    fn default() -> Config {
        Config::parse_from(["isoray"])
    }
}

impl Config {
    /// Rejects settings the server cannot run with.
    pub fn validate(&self) -> Result<(), String> {
        let most = isoray_render::backend::MAX_THREADS;
        if self.threads > most {
            return Err(format!(
                "--threads {} must be at most {most} (0: one per core)",
                self.threads
            ));
        }
        if self.max_size == 0 || self.max_size > 16384 {
            return Err(format!("--max-size {} must be in 1..=16384", self.max_size));
        }
        if self.default_width == 0
            || self.default_height == 0
            || self.default_width > self.max_size
            || self.default_height > self.max_size
        {
            return Err("--default-width/--default-height must be in 1..=--max-size".into());
        }
        if !(self.max_fps.is_finite() && self.max_fps > 0.0 && self.max_fps <= 1000.0) {
            return Err(format!("--max-fps {} must be in (0, 1000]", self.max_fps));
        }
        if self.ping_interval_secs == 0 || self.idle_timeout_secs <= self.ping_interval_secs {
            return Err(format!(
                "--idle-timeout-secs {} must exceed --ping-interval-secs {} (> 0)",
                self.idle_timeout_secs, self.ping_interval_secs
            ));
        }
        if !(self.min_scale > 0.0 && self.min_scale <= 1.0) {
            return Err(format!("--min-scale {} must be in (0, 1]", self.min_scale));
        }
        if !(self.pool_share > 0.0 && self.pool_share < 1.0) {
            return Err(format!(
                "--pool-share {} must be in (0, 1): a pool planned full leaves inputs waiting",
                self.pool_share
            ));
        }
        if self.max_sessions == 0 {
            return Err("--max-sessions must be at least 1".into());
        }
        if !(1..=100).contains(&self.jpeg_quality) {
            return Err(format!(
                "--jpeg-quality {} must be in 1..=100",
                self.jpeg_quality
            ));
        }
        if !(self.write_rate.is_finite() && self.write_rate > 0.0) || self.write_burst == 0 {
            return Err("--write-rate must be positive and --write-burst at least 1".into());
        }
        if self.max_push_bytes == 0 || self.max_json_bytes == 0 || self.push_timeout_secs == 0 {
            return Err(
                "--max-push-bytes, --max-json-bytes and --push-timeout-secs must be positive"
                    .into(),
            );
        }
        if !(1..=1 << 20).contains(&self.gpu_memory_mib) {
            return Err(format!(
                "--gpu-memory-mib {} must be in 1..=1048576 (1 TiB)",
                self.gpu_memory_mib
            ));
        }
        if self.max_ray_depth > isoray_render::effects::MAX_DEPTH {
            return Err(format!(
                "--max-ray-depth {} exceeds the engine's {}",
                self.max_ray_depth,
                isoray_render::effects::MAX_DEPTH
            ));
        }
        if !(1..=isoray_render::effects::MAX_SAMPLES).contains(&self.max_samples) {
            return Err(format!(
                "--max-samples {} must be in 1..={}",
                self.max_samples,
                isoray_render::effects::MAX_SAMPLES
            ));
        }
        if !(1..=4096).contains(&self.max_refine_passes) {
            return Err("--max-refine-passes must be in 1..=4096".into());
        }
        if self.antialias_passes > 4096 {
            return Err("--antialias-passes must be in 0..=4096".into());
        }
        if let Some(shard) = &self.shard {
            crate::placement::validate_shard(shard)?;
        }
        if !(1..=3600).contains(&self.header_timeout_secs) {
            return Err("--header-timeout-secs must be in 1..=3600".into());
        }
        if self.max_steps_per_scene == 0 {
            return Err("--max-steps-per-scene must be at least 1".into());
        }
        if self.max_scenes == 0 {
            return Err("--max-scenes must be at least 1".into());
        }
        for origin in &self.allowed_origins {
            validate_origin(origin)?;
        }
        if !(self.render_rate.is_finite() && self.render_rate > 0.0) || self.render_burst == 0 {
            return Err("--render-rate must be positive and --render-burst at least 1".into());
        }
        for proxy in &self.trusted_proxy {
            crate::clients::Network::parse(proxy)?;
        }
        for peer in &self.peers {
            let ok = match (peer.strip_prefix("http://"), peer.strip_prefix("dns://")) {
                (Some(host), _) => !host.is_empty() && !host.contains('/'),
                (None, Some(name)) => name
                    .rsplit_once(':')
                    .is_some_and(|(n, p)| !n.is_empty() && p.parse::<u16>().is_ok()),
                (None, None) => false,
            };
            if !ok {
                return Err(format!(
                    "--peers `{peer}`: expected http://HOST:PORT or dns://NAME:PORT"
                ));
            }
        }
        if self.peer_timeout_ms == 0 {
            return Err("--peer-timeout-ms must be at least 1".into());
        }
        for (name, token) in [
            ("--admin-token", &self.admin_token),
            ("--view-token", &self.view_token),
            ("--metrics-token", &self.metrics_token),
        ] {
            if token.as_ref().is_some_and(|t| t.len() < 16) {
                return Err(format!("{name} must be at least 16 characters"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::{validate_origin, Config};
    use clap::Parser;

    #[test]
    fn the_pool_share_is_inside_zero_to_one() {
        let with =
            |v: &str| Config::parse_from(["isoray", &format!("--pool-share={v}")]).validate();
        assert!(Config::default().validate().is_ok());
        assert_eq!(Config::default().pool_share, 0.6);
        with("0.85").expect("0.85");
        for bad in ["0", "1", "1.5", "-0.2", "NaN", "inf"] {
            let err = with(bad).expect_err(bad);
            assert!(err.contains("--pool-share"), "{bad}: {err}");
        }
    }

    #[test]
    fn a_thread_count_past_the_limit_is_refused() {
        let with = |v: &str| Config::parse_from(["isoray", &format!("--threads={v}")]).validate();
        with("0").expect("one per core");
        with("1024").expect("the most");
        let err = with("100000").expect_err("a mistyped count");
        assert!(
            err.contains("--threads 100000 must be at most 1024"),
            "{err}"
        );
    }

    #[test]
    fn origins_are_scheme_host_and_port() {
        for good in ["https://viewer.example", "http://127.0.0.1:8080"] {
            validate_origin(good).expect(good);
        }
        for bad in [
            "viewer.example",
            "ftp://x",
            "https://",
            "https://a/b",
            "https://u@h",
        ] {
            validate_origin(bad).expect_err(bad);
        }
    }
}
