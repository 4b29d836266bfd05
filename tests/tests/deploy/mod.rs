//! What deploy/ ships, run for real: nginx with deploy/nginx/isoray.conf in front of
//! several `isoray` processes on loopback (placement by shard, failure of one process), and
//! the Kubernetes manifests checked against the Kubernetes schemas.

mod kill_cycles;
mod manifests;
mod nginx;
mod nginx_restart;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A child process killed and reaped when dropped, so a failing test leaves nothing
/// running. With `terminate`, it first gets SIGTERM (nginx's master then stops its workers,
/// which a SIGKILL of the master would orphan) and a few seconds to exit.
pub struct Killed {
    pub child: Child,
    pub terminate: bool,
}

impl Drop for Killed {
    fn drop(&mut self) {
        if self.terminate {
            let _ = Command::new("kill")
                .args(["-TERM", &self.child.id().to_string()])
                .status();
            let deadline = Instant::now() + Duration::from_secs(5);
            while Instant::now() < deadline {
                if let Ok(Some(_)) = self.child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An `isoray` server process on an ephemeral loopback port.
pub struct Backend {
    pub base: String,
    pub addr: String,
    process: Killed,
}

impl Backend {
    /// Starts `isoray --listen 127.0.0.1:0 ARGS` and waits for the address it prints.
    pub fn start(args: &[&str]) -> Backend {
        Backend::start_on("127.0.0.1:0", args)
    }

    /// Starts `isoray --listen LISTEN ARGS` (a fixed address: a process restarted where its
    /// balancer and its viewers expect it) and waits for the address it prints.
    pub fn start_on(listen: &str, args: &[&str]) -> Backend {
        let mut child = Command::new(crate::api::isoray_binary())
            .args(["--listen", listen, "--log", "warn"])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("isoray starts");
        let stdout = child.stdout.take().expect("piped stdout");
        let process = Killed {
            child,
            terminate: false,
        };
        let base = crate::api::served_address(stdout);
        let addr = base.trim_start_matches("http://").to_string();
        Backend {
            base,
            addr,
            process,
        }
    }

    /// SIGKILL, as a crashed or lost machine: no shutdown code runs.
    pub fn kill(mut self) {
        self.process.child.kill().expect("SIGKILL");
        self.process.child.wait().expect("reaped");
    }
}

/// The nginx binary: `$ISORAY_NGINX`, Debian's `/usr/sbin/nginx`, or `nginx` on the path.
/// There is no skipping: `bash .ci/run` installs Debian's nginx.
pub fn nginx_binary() -> PathBuf {
    if let Some(p) = std::env::var_os("ISORAY_NGINX") {
        return PathBuf::from(p);
    }
    let debian = Path::new("/usr/sbin/nginx");
    if debian.exists() {
        return debian.to_path_buf();
    }
    let on_path = std::env::var_os("PATH")
        .into_iter()
        .flat_map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .map(|d| d.join("nginx"))
        .find(|p| p.exists());
    on_path.expect(
        "nginx is not installed: `bash .ci/run` installs Debian's nginx (or set ISORAY_NGINX)",
    )
}

/// nginx run as the current user from a temporary prefix: its own config, pid file, logs
/// and temporary paths, no root needed.
pub struct Nginx {
    pub base: String,
    pub dir: tempfile::TempDir,
    _process: Killed,
}

impl Nginx {
    /// Serves `http_conf` (an http-context file such as deploy/nginx/isoray.conf, with its
    /// `listen` already on `port`) and waits until it accepts connections.
    pub fn start(http_conf: &str, port: u16) -> Nginx {
        let dir = tempfile::tempdir().expect("temp dir");
        // Workers run as `nobody` when the test runs as root: let them into the prefix.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755))
                .expect("chmod the nginx prefix");
        }
        let d = dir.path().display().to_string();
        std::fs::write(dir.path().join("isoray.conf"), http_conf).expect("write isoray.conf");
        let main = format!(
            "daemon off;\nworker_processes 1;\npid {d}/nginx.pid;\nerror_log {d}/error.log info;\n\
             events {{ worker_connections 1024; }}\n\
             http {{\n  client_body_temp_path {d}/client_body;\n\
             \x20 proxy_temp_path {d}/proxy;\n  fastcgi_temp_path {d}/fastcgi;\n\
             \x20 uwsgi_temp_path {d}/uwsgi;\n  scgi_temp_path {d}/scgi;\n  include {d}/isoray.conf;\n\
             \x20 access_log {d}/access.log isoray;\n}}\n"
        );
        let conf = dir.path().join("nginx.conf");
        std::fs::write(&conf, main).expect("write nginx.conf");
        let mut child = Command::new(nginx_binary())
            .arg("-p")
            .arg(dir.path())
            .arg("-c")
            .arg(&conf)
            .arg("-e")
            .arg(dir.path().join("error.log"))
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("nginx starts");
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            if let Some(status) = child.try_wait().expect("nginx status") {
                let mut stderr = String::new();
                if let Some(mut e) = child.stderr.take() {
                    let _ = std::io::Read::read_to_string(&mut e, &mut stderr);
                }
                let log = std::fs::read_to_string(dir.path().join("error.log")).unwrap_or_default();
                panic!("nginx exited ({status}): {stderr}\n{log}");
            }
            if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
                break;
            }
            assert!(Instant::now() < deadline, "nginx never listened on {port}");
            std::thread::sleep(Duration::from_millis(20));
        }
        Nginx {
            base: format!("http://127.0.0.1:{port}"),
            dir,
            _process: Killed {
                child,
                terminate: true,
            },
        }
    }

    pub fn access_log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("access.log")).expect("access log")
    }
}

/// A loopback port nothing listens on right now.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("an ephemeral port")
        .port()
}
