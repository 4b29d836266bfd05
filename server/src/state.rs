//! State shared by every request: configuration, the render pool and its fair scheduler,
//! the job pool, the scenes, the sessions, and the shutdown signal.

use crate::config::{BackendChoice, Config};
use crate::jobs::{self, JobPool};
use crate::scenes::registry::SceneRegistry;
use crate::schedule::RenderScheduler;
use crate::session::stats::SessionStats;
use isoray_render::Backend;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::watch;

/// Cheap to clone; everything lives behind one `Arc`.
#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    config: Config,
    backend: Arc<Backend>,
    jobs: JobPool,
    scheduler: Arc<RenderScheduler>,
    scenes: SceneRegistry,
    sessions: SessionTable,
    shutdown: watch::Sender<bool>,
}

impl AppState {
    /// Starts the render pool and loads the built-in scenes.
    pub fn new(config: Config) -> Result<AppState, String> {
        config.validate()?;
        crate::metrics::handle();
        let backend = Arc::new(backend_for(&config)?);
        let jobs = JobPool::new(jobs::threads_for(backend.threads()))?;
        let scheduler = RenderScheduler::new(Arc::clone(&backend));
        let scenes = SceneRegistry::from_config(&config);
        Ok(AppState {
            inner: Arc::new(Inner {
                scenes,
                config,
                backend,
                jobs,
                scheduler,
                sessions: SessionTable::default(),
                shutdown: watch::Sender::new(false),
            }),
        })
    }

    pub fn config(&self) -> &Config {
        &self.inner.config
    }

    pub fn backend(&self) -> &Backend {
        &self.inner.backend
    }

    /// The pool for one-shot renders and histograms (not sessions' frames).
    pub fn jobs(&self) -> &JobPool {
        &self.inner.jobs
    }

    /// The fair gatekeeper of the render pool: sessions submit their frames here.
    pub fn scheduler(&self) -> &Arc<RenderScheduler> {
        &self.inner.scheduler
    }

    pub fn scenes(&self) -> &SceneRegistry {
        &self.inner.scenes
    }

    pub fn sessions(&self) -> &SessionTable {
        &self.inner.sessions
    }

    /// Tells every session to close with a reason.
    pub fn begin_shutdown(&self) {
        self.inner.shutdown.send_replace(true);
    }

    pub fn shutdown_signal(&self) -> watch::Receiver<bool> {
        self.inner.shutdown.subscribe()
    }

    /// A place for one more session, or `None` when `--max-sessions` are open. The place is
    /// given back when the ticket drops, also if the websocket upgrade never completes.
    pub fn admit_session(&self) -> Option<SessionTicket> {
        let (id, stats) = self.sessions().try_register(self.config().max_sessions)?;
        Some(SessionTicket {
            app: self.clone(),
            id,
            stats,
        })
    }
}

/// One registered session; unregisters it on drop.
pub struct SessionTicket {
    app: AppState,
    pub id: u64,
    pub stats: Arc<SessionStats>,
}

impl Drop for SessionTicket {
    fn drop(&mut self) {
        self.app.sessions().unregister(self.id);
    }
}

/// The open sessions and their counters.
#[derive(Default)]
pub struct SessionTable {
    next_id: AtomicU64,
    open: Mutex<BTreeMap<u64, Arc<SessionStats>>>,
}

impl SessionTable {
    /// Registers a session unless `limit` are open already.
    fn try_register(&self, limit: usize) -> Option<(u64, Arc<SessionStats>)> {
        let mut open = self.lock();
        if open.len() >= limit {
            return None;
        }
        let id = self.next_id.fetch_add(1, Ordering::Relaxed) + 1;
        let stats = Arc::new(SessionStats::default());
        open.insert(id, Arc::clone(&stats));
        metrics::gauge!(crate::metrics::SESSIONS).increment(1.0);
        Some((id, stats))
    }

    fn unregister(&self, id: u64) {
        if self.lock().remove(&id).is_some() {
            metrics::gauge!(crate::metrics::SESSIONS).decrement(1.0);
        }
    }

    /// The counters of every open session, by id.
    pub fn snapshot(&self) -> Vec<(u64, Arc<SessionStats>)> {
        self.lock()
            .iter()
            .map(|(id, s)| (*id, Arc::clone(s)))
            .collect()
    }

    pub fn count(&self) -> usize {
        self.lock().len()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, BTreeMap<u64, Arc<SessionStats>>> {
        self.open.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The render backend `--backend` asks for; a GPU that cannot start leaves the CPU with a
/// warning (`gpu`) or an info line (`auto`, where no hardware GPU is the common case).
pub fn backend_for(config: &Config) -> Result<Backend, String> {
    let cpu = || Backend::cpu(config.threads).map_err(|e| e.to_string());
    let gpu_memory = config.gpu_memory_mib << 20;
    match config.backend {
        BackendChoice::Cpu => cpu(),
        BackendChoice::Auto => {
            let (backend, why) =
                Backend::auto(config.threads, gpu_memory).map_err(|e| e.to_string())?;
            if let Some(why) = why {
                tracing::info!(reason = %why, "tracing on the CPU");
            }
            Ok(backend)
        }
        #[cfg(feature = "gpu")]
        BackendChoice::Gpu => match Backend::gpu(config.threads, gpu_memory) {
            Ok(backend) => Ok(backend),
            Err(e) => {
                tracing::warn!(error = %e, "--backend gpu: no usable GPU; tracing on the CPU");
                cpu()
            }
        },
        #[cfg(not(feature = "gpu"))]
        BackendChoice::Gpu => {
            Err("--backend gpu: this isoray was built without the `gpu` feature".into())
        }
    }
}
