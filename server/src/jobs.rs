//! The job pool: a small rayon pool of the server's own for work that is not a session's
//! frame — one-shot renders (`POST .../render`) and histograms (`GET .../histogram`). These
//! used to be spawned on the render pool directly, beside the fair scheduler
//! (`schedule.rs`); now sessions' frames are the only work the scheduler's pool starts, and a
//! burst of API jobs waits here instead of taking the render pool's threads.
//!
//! A job's tracing still runs on the backend's pool (the backend's `render*` methods install
//! themselves there); the job thread prepares the state, waits for the trace and encodes.
//! Architecture invariant: nothing here runs on the async runtime, and the handler only
//! awaits the result.

/// Threads of the job pool for a render pool of `render_threads`: a quarter, at least two,
/// so that a long histogram does not hold up a one-shot render.
pub fn threads_for(render_threads: usize) -> usize {
    (render_threads / 4).max(2)
}

/// A pool for one-shot jobs.
pub struct JobPool {
    pool: rayon::ThreadPool,
}

/// The pool dropped a job without running it (the server is going down).
#[derive(Debug, thiserror::Error)]
#[error("the job pool dropped the job")]
pub struct JobDropped;

impl JobPool {
    /// A pool of `threads` workers.
    pub fn new(threads: usize) -> Result<JobPool, String> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("isoray-job-{i}"))
            .build()
            .map_err(|e| format!("could not start the job pool: {e}"))?;
        Ok(JobPool { pool })
    }

    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// Runs `job` on the pool; the answer comes back through a channel, so awaiting it does
    /// not block the async runtime.
    pub fn run<T: Send + 'static>(
        &self,
        job: impl FnOnce() -> T + Send + 'static,
    ) -> impl std::future::Future<Output = Result<T, JobDropped>> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.pool.spawn(move || {
            let _ = tx.send(job());
        });
        async move { rx.await.map_err(|_| JobDropped) }
    }
}
