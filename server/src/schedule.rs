//! Fair scheduling of the render pool across sessions.
//!
//! Every frame a session wants is a job; a session has at most one job queued or running (its
//! renderer waits for the result before it asks again). Up to `slots` jobs run at once on the
//! rayon pool (one per pool thread, so encoding, which is single-threaded, overlaps with
//! another frame's tracing); the rest wait here, not in rayon's queue, so that the next job to
//! start can be chosen fairly.
//!
//! How it works: start-time fair queueing over pool time, with a bounded lead.
//! - A virtual clock advances at the rate each running job is served when the pool is shared
//!   equally among the `k` running jobs (`dt / k`, processor sharing), so a job's *cost* is
//!   the pool time it took — the same for a frame whether it ran alone or beside others.
//! - Each session accumulates the cost of its jobs (`vtime`); the waiting job of the session
//!   with the smallest `vtime` starts next.
//! - A session may not start a job while it is more than [`MAX_LEAD`] of pool time ahead of
//!   another *contending* session: one with a job queued or running, or whose last job ended
//!   less than [`RESUBMIT_GRACE`] ago (its renderer is about to ask again; without the grace a
//!   session would lose its turn to whoever is queued at the instant its job ends, and a
//!   large-frame session would get one frame per small frame of the others: round robin, not
//!   fairness). A timer thread starts held-back jobs once the grace runs out.
//! - A session that asks after a pause starts at most [`MAX_LEAD`] behind the busy sessions:
//!   no banked credit, no starving the others.
//!
//! So a 4K session gets the same share of the pool as a thumbnail session, not nine times
//! more. The scheduler also tells each session how many sessions compete for the pool
//! ([`RenderScheduler::active_sessions`]), which the adaptive controller divides its budget by.

use isoray_render::Backend;
use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex, Weak};
use std::time::{Duration, Instant};
use tokio::sync::oneshot;

/// A session that asked for no frame for this long no longer counts as competing.
const ACTIVE_WINDOW: Duration = Duration::from_secs(1);

/// How far (pool seconds) a session may run ahead of a contending session.
pub const MAX_LEAD: f64 = 0.010;

/// How long a session whose job just ended still counts as contending.
pub const RESUBMIT_GRACE: Duration = Duration::from_millis(20);

/// What a job cost, for the session's adaptive controller.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JobCost {
    /// Pool time the job received, seconds: wall time divided by the jobs sharing the pool.
    pub pool_s: f64,
    /// Time the job waited for its turn.
    pub queued: Duration,
    /// Time from start to end on the pool.
    pub run: Duration,
}

type Job = Box<dyn FnOnce() + Send + 'static>;

struct Waiting {
    session: u64,
    job: Job,
}

#[derive(Clone, Copy)]
struct Share {
    vtime: f64,
    last_request: Instant,
    last_end: Option<Instant>,
    busy: bool,
}

impl Share {
    fn contending(&self, now: Instant) -> bool {
        self.busy || self.last_end.is_some_and(|t| now - t < RESUBMIT_GRACE)
    }
}

struct State {
    slots: usize,
    running: usize,
    waiting: Vec<Waiting>,
    /// Virtual pool time: advances by `dt / running` while jobs run.
    clock: f64,
    clock_at: Instant,
    shares: HashMap<u64, Share>,
    /// When held-back jobs may become eligible (the timer thread's next wake-up).
    recheck_at: Option<Instant>,
}

impl State {
    fn advance_clock(&mut self, now: Instant) {
        if self.running > 0 {
            self.clock += (now - self.clock_at).as_secs_f64() / self.running as f64;
        }
        self.clock_at = now;
    }

    fn vtime(&self, session: u64) -> f64 {
        self.shares.get(&session).map_or(0.0, |s| s.vtime)
    }
}

/// The render pool's gatekeeper, shared behind an `Arc`.
pub struct RenderScheduler {
    backend: Arc<Backend>,
    state: Mutex<State>,
    /// Wakes the timer thread when `recheck_at` moves earlier.
    timer: Condvar,
}

impl RenderScheduler {
    /// A scheduler running at most one job per pool thread, with its timer thread (which
    /// ends when the scheduler is dropped).
    pub fn new(backend: Arc<Backend>) -> Arc<RenderScheduler> {
        let slots = backend.threads().max(1);
        let scheduler = Arc::new(RenderScheduler {
            backend,
            state: Mutex::new(State {
                slots,
                running: 0,
                waiting: Vec::new(),
                clock: 0.0,
                clock_at: Instant::now(),
                shares: HashMap::new(),
                recheck_at: None,
            }),
            timer: Condvar::new(),
        });
        let weak = Arc::downgrade(&scheduler);
        let spawned = std::thread::Builder::new()
            .name("isoray-scheduler".into())
            .spawn(move || timer_thread(weak));
        if let Err(e) = spawned {
            // Without the timer, held-back jobs start at the next submission or job end.
            tracing::warn!(error = %e, "render scheduler timer thread did not start");
        }
        scheduler
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // The state holds plain values updated in one step each; a panic cannot leave it torn.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Queues `job` for `session` and returns its result with what it cost. The job runs on
    /// the render pool when the session's turn comes. If the receiver is dropped, the job
    /// still runs (it may already have started) and its result is discarded.
    pub fn submit<T: Send + 'static>(
        self: &Arc<Self>,
        session: u64,
        job: impl FnOnce() -> T + Send + 'static,
    ) -> oneshot::Receiver<(T, JobCost)> {
        let (tx, rx) = oneshot::channel();
        let queued_at = Instant::now();
        let scheduler = Arc::clone(self);
        let wrapped: Job = Box::new(move || {
            let started = Instant::now();
            let clock_start = scheduler.clock_now(started);
            let value = job();
            let ended = Instant::now();
            let pool_s = scheduler.finish(session, clock_start, ended);
            let cost = JobCost {
                pool_s,
                queued: started - queued_at,
                run: ended - started,
            };
            let _ = tx.send((value, cost));
        });
        let ready = {
            let mut state = self.lock();
            let now = Instant::now();
            let floor = busy_floor(&state, session);
            let share = state.shares.entry(session).or_insert(Share {
                vtime: floor,
                last_request: now,
                last_end: None,
                busy: false,
            });
            // No banked credit: a session that paused starts at most MAX_LEAD behind.
            if !share.busy {
                share.vtime = share.vtime.max(floor - MAX_LEAD);
            }
            share.last_request = now;
            share.busy = true;
            state.waiting.push(Waiting {
                session,
                job: wrapped,
            });
            self.take_ready(&mut state, now)
        };
        self.start(ready);
        rx
    }

    /// Jobs that may start now, taken from the waiting list: the smallest `vtime` first, and
    /// none that leads a contending session by more than `MAX_LEAD`.
    fn take_ready(&self, state: &mut State, now: Instant) -> Vec<Job> {
        let mut ready = Vec::new();
        while state.running < state.slots && !state.waiting.is_empty() {
            // The smallest vtime among contending sessions (the waiting ones included).
            let floor = state
                .shares
                .values()
                .filter(|s| s.contending(now))
                .map(|s| s.vtime)
                .min_by(f64::total_cmp)
                .unwrap_or(0.0);
            let pick = state
                .waiting
                .iter()
                .enumerate()
                .map(|(i, w)| (i, state.vtime(w.session)))
                .filter(|(_, v)| *v <= floor + MAX_LEAD)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i);
            let Some(pick) = pick else {
                // Held back until the sessions they lead ask again or their grace ends.
                let recheck = state
                    .shares
                    .values()
                    .filter(|s| !s.busy)
                    .filter_map(|s| s.last_end)
                    .map(|t| t + RESUBMIT_GRACE)
                    .filter(|t| *t > now)
                    .min();
                if let Some(at) = recheck {
                    if state.recheck_at.is_none_or(|r| at < r || r <= now) {
                        state.recheck_at = Some(at);
                        self.timer.notify_one();
                    }
                }
                break;
            };
            let next = state.waiting.swap_remove(pick);
            state.advance_clock(now);
            state.running += 1;
            ready.push(next.job);
        }
        metrics::gauge!(crate::metrics::RENDER_QUEUE).set(state.waiting.len() as f64);
        metrics::gauge!(crate::metrics::RENDER_RUNNING).set(state.running as f64);
        ready
    }

    fn start(&self, jobs: Vec<Job>) {
        for job in jobs {
            self.backend.spawn(job);
        }
    }

    fn clock_now(&self, now: Instant) -> f64 {
        let mut state = self.lock();
        state.advance_clock(now);
        state.clock
    }

    /// Books a finished job and starts whatever may start; returns the job's pool time.
    fn finish(&self, session: u64, clock_start: f64, ended: Instant) -> f64 {
        let (cost, ready) = {
            let mut state = self.lock();
            state.advance_clock(ended);
            let cost = (state.clock - clock_start).max(0.0);
            state.running = state.running.saturating_sub(1);
            if let Some(share) = state.shares.get_mut(&session) {
                share.vtime += cost;
                share.busy = false;
                share.last_end = Some(ended);
            }
            let ready = self.take_ready(&mut state, Instant::now());
            (cost, ready)
        };
        self.start(ready);
        cost
    }

    /// Starts held-back jobs whose time has come (the timer thread calls this).
    fn recheck(&self) {
        let ready = {
            let mut state = self.lock();
            state.recheck_at = None;
            self.take_ready(&mut state, Instant::now())
        };
        self.start(ready);
    }

    /// Sessions that asked for a frame within the last second (at least 1).
    pub fn active_sessions(&self) -> usize {
        let state = self.lock();
        let now = Instant::now();
        state
            .shares
            .values()
            .filter(|s| s.busy || now - s.last_request <= ACTIVE_WINDOW)
            .count()
            .max(1)
    }

    /// Forgets a session that ended. Its job, if one is still queued, is dropped unrun.
    pub fn forget(&self, session: u64) {
        let (dropped, ready) = {
            let mut state = self.lock();
            state.shares.remove(&session);
            let mut dropped = Vec::new();
            let mut i = 0;
            while i < state.waiting.len() {
                if state.waiting[i].session == session {
                    dropped.push(state.waiting.swap_remove(i));
                } else {
                    i += 1;
                }
            }
            // Jobs held back behind this session may start now.
            let ready = self.take_ready(&mut state, Instant::now());
            (dropped, ready)
        };
        self.start(ready);
        // Dropped outside the lock: a job's captures may be large.
        drop(dropped);
    }

    /// Sessions the scheduler keeps a share for, and jobs waiting: both return to zero when
    /// every session has ended (tests check this for leaks).
    pub fn tracked(&self) -> (usize, usize) {
        let state = self.lock();
        (state.shares.len(), state.waiting.len())
    }
}

/// Sleeps until the next recheck time (or a notification), then starts held-back jobs; ends
/// when the scheduler is gone.
fn timer_thread(scheduler: Weak<RenderScheduler>) {
    loop {
        let Some(s) = scheduler.upgrade() else {
            return;
        };
        let due = {
            let state = s.lock();
            let now = Instant::now();
            let wait = match state.recheck_at {
                Some(at) if at <= now => None,
                Some(at) => Some(at - now),
                // Nothing to wait for: wake now and then to notice the scheduler is gone.
                None => Some(Duration::from_millis(200)),
            };
            match wait {
                None => true,
                Some(wait) => {
                    let (state, _) = s
                        .timer
                        .wait_timeout(state, wait)
                        .unwrap_or_else(|e| e.into_inner());
                    state.recheck_at.is_some_and(|at| at <= Instant::now())
                }
            }
        };
        if due {
            s.recheck();
        }
    }
}

/// The smallest `vtime` among busy sessions other than `session` (the largest of all when
/// none is busy; 0 when there are none).
fn busy_floor(state: &State, session: u64) -> f64 {
    let others = || state.shares.iter().filter(|(id, _)| **id != session);
    others()
        .filter(|(_, s)| s.busy)
        .map(|(_, s)| s.vtime)
        .min_by(f64::total_cmp)
        .unwrap_or_else(|| {
            others()
                .map(|(_, s)| s.vtime)
                .max_by(f64::total_cmp)
                .unwrap_or(0.0)
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};

    /// Spins for `d` of wall time (a stand-in for tracing).
    fn work(d: Duration) {
        let t = Instant::now();
        while t.elapsed() < d {
            std::hint::spin_loop();
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_heavy_session_gets_no_more_pool_time_than_light_ones() {
        // One pool thread, so the jobs strictly share it.
        let backend = Arc::new(Backend::cpu(1).expect("pool"));
        let scheduler = RenderScheduler::new(backend);
        // Session 1's frames cost 8 ms (a big frame), sessions 2 to 4 take 1 ms.
        let costs = [8u64, 1, 1, 1].map(Duration::from_millis);
        let frames: Vec<Arc<AtomicU64>> = costs.iter().map(|_| Arc::default()).collect();
        let until = Instant::now() + Duration::from_millis(800);
        let mut loops = Vec::new();
        for (i, (count, cost)) in frames.iter().zip(costs).enumerate() {
            let (scheduler, count) = (Arc::clone(&scheduler), Arc::clone(count));
            loops.push(tokio::spawn(async move {
                let mut pool_s = 0.0;
                while Instant::now() < until {
                    let (_, c) = scheduler
                        .submit(i as u64 + 1, move || work(cost))
                        .await
                        .expect("job ran");
                    pool_s += c.pool_s;
                    count.fetch_add(1, Ordering::Relaxed);
                }
                pool_s
            }));
        }
        let mut pool = Vec::new();
        for l in loops {
            pool.push(l.await.expect("loop"));
        }
        let counts: Vec<u64> = frames.iter().map(|f| f.load(Ordering::Relaxed)).collect();
        println!("frames {counts:?}; pool s {pool:?}");
        // Frame-fair (round robin) would give every session the same number of frames and
        // the heavy one 8/11 of the pool; pool-time-fair gives each about a quarter.
        let light = pool[1..].iter().sum::<f64>() / 3.0;
        let ratio = pool[0] / light;
        assert!(
            ratio < 2.0,
            "the heavy session got {ratio:.2} times a light one's pool time"
        );
        assert!(
            counts[1..].iter().all(|&c| c >= 3 * counts[0]),
            "{counts:?}"
        );
        assert_eq!(scheduler.tracked().1, 0, "nothing left waiting");
        for session in 1..=4 {
            scheduler.forget(session);
        }
        assert_eq!(scheduler.tracked(), (0, 0));
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn cost_is_pool_time_whether_a_job_runs_alone_or_shared() {
        let backend = Arc::new(Backend::cpu(2).expect("pool"));
        let scheduler = RenderScheduler::new(backend);
        let (_, alone) = scheduler
            .submit(1, || work(Duration::from_millis(20)))
            .await
            .expect("ran");
        // Two jobs at once on two slots: each runs 20 ms of wall time but gets half the pool.
        // The barrier makes both spin over the same 20 ms, however the OS schedules them.
        let barrier = Arc::new(std::sync::Barrier::new(2));
        let (ba, bb) = (Arc::clone(&barrier), barrier);
        let a = scheduler.submit(1, move || {
            ba.wait();
            work(Duration::from_millis(20))
        });
        let b = scheduler.submit(2, move || {
            bb.wait();
            work(Duration::from_millis(20))
        });
        let ((_, ca), (_, cb)) = (a.await.expect("a"), b.await.expect("b"));
        println!("alone {alone:?}; shared {ca:?} {cb:?}");
        // Alone, a job's pool time is its wall time.
        assert!(
            (alone.pool_s - alone.run.as_secs_f64()).abs() < 1e-3,
            "{alone:?}"
        );
        // Shared, both ran for at least the same 20 ms, which count half for each: pool
        // time is at least 10 ms less than wall time (whatever else the OS did meanwhile).
        for c in [ca, cb] {
            assert!(c.pool_s <= c.run.as_secs_f64() - 0.009, "{c:?}");
        }
        assert!(scheduler.active_sessions() == 2);
    }
}
