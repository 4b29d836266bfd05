//! Command-line flags, each with an environment-variable fallback and a default that works
//! with no flags, files or network.

use clap::Parser;
use std::net::SocketAddr;

/// isoray: a remote ray tracer for dynamic implicit surfaces and isosurfaces.
#[derive(Clone, Debug, Parser)]
#[command(name = "isoray", version, about)]
pub struct Config {
    /// Address to listen on.
    #[arg(long, env = "ISORAY_LISTEN", default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,

    /// Render worker threads (0: one per core).
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
    #[arg(long, env = "ISORAY_MIN_SCALE", default_value_t = 0.25)]
    pub min_scale: f64,

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
}

impl Default for Config {
    fn default() -> Config {
        Config::parse_from(["isoray"])
    }
}

impl Config {
    /// Rejects settings the server cannot run with.
    pub fn validate(&self) -> Result<(), String> {
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
        if self.max_sessions == 0 {
            return Err("--max-sessions must be at least 1".into());
        }
        if !(1..=100).contains(&self.jpeg_quality) {
            return Err(format!(
                "--jpeg-quality {} must be in 1..=100",
                self.jpeg_quality
            ));
        }
        Ok(())
    }
}
