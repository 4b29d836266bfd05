//! Built-in demo scenes: a pure function of time, built on a build pool of their own and
//! pipelined for live views (fitted-bvh-metaballs.txt Fig. 7; see [`DemoPipeline`]).

use crate::scenes::prepared::{micros, PreparedState};
use isoray_render::scenes::DemoScene;
use isoray_render::Scene;
use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Instant;

/// Prepared states kept per demo scene: the live step plus a few pinned ones.
pub const CACHED_STATES: usize = 4;

/// Live requests this many seconds apart are a pause (nobody watched), not their spacing.
const PAUSE_SECS: f64 = 1.0;

/// A live view shows no state older than its clock by this many build periods (nor by
/// [`PAUSE_SECS`], whichever is longer): one built before a pause is stale.
const STALE_PERIODS: f64 = 4.0;

/// The pool demo states are built on: apart from the render pool, so that a render thread
/// waiting for a build never waits for work queued behind itself, and sized to every core,
/// so a build (which forks on rayon) uses both cores while a frame renders.
pub struct Builder {
    pool: Option<rayon::ThreadPool>,
}

impl Builder {
    pub(crate) fn new(threads: usize) -> Builder {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("isoray-build-{i}"))
            .build();
        if let Err(e) = &pool {
            tracing::warn!(error = %e, "no build pool: demo states are built where they are needed");
        }
        Builder { pool: pool.ok() }
    }

    /// Runs `job` on the pool without waiting.
    fn spawn(&self, job: impl FnOnce() + Send + 'static) {
        match &self.pool {
            Some(pool) => pool.spawn(job),
            None => job(),
        }
    }
}

/// One demo state being built: waiters block on it (they are render threads; the build runs
/// on the build pool, so it always makes progress).
struct Pending {
    slot: Mutex<PendingSlot>,
    done: Condvar,
}

enum PendingSlot {
    Building,
    Ready(PreparedState),
    /// The build panicked; waiters build for themselves.
    Failed,
}

impl Pending {
    fn wait(&self) -> Option<PreparedState> {
        let mut slot = self.slot.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            match &*slot {
                PendingSlot::Building => {
                    slot = self.done.wait(slot).unwrap_or_else(|e| e.into_inner())
                }
                PendingSlot::Ready(state) => return Some(state.clone()),
                PendingSlot::Failed => return None,
            }
        }
    }

    fn finish(&self, outcome: PendingSlot) {
        *self.slot.lock().unwrap_or_else(|e| e.into_inner()) = outcome;
        self.done.notify_all();
    }
}

/// Marks a build failed if it unwinds before finishing.
struct FailOnDrop(Option<Arc<Pending>>);

impl Drop for FailOnDrop {
    fn drop(&mut self) {
        if let Some(pending) = self.0.take() {
            pending.finish(PendingSlot::Failed);
        }
    }
}

/// A demo's prepared states and its live pipeline (fitted-bvh-metaballs.txt Fig. 7).
///
/// A live request takes the newest live state built that is newer than the state the same
/// viewer showed last (so each of many viewers shows every new state without waiting for the
/// next build); if there is none it waits for the build in flight (or, at the very start,
/// builds its own time). Then, if no build is in flight, it starts building the state one frame period
/// ahead on the build pool and returns without waiting: that build runs while this frame
/// renders, and the next live request shows it. The frame period is the spacing of recent
/// live requests, at least the frame interval. A live view thus shows states up to a frame
/// away from its clock, and the frame header carries the time of the state shown. A pinned
/// request gets exactly its time, built then if not cached.
pub struct DemoPipeline {
    demo: DemoScene,
    builder: Arc<Builder>,
    frame_interval_secs: f64,
    inner: Arc<Mutex<PipelineState>>,
    /// States built (live and pinned), for [`SceneEntry::states_built`].
    built: Arc<std::sync::atomic::AtomicU64>,
}

/// One prepared demo state in the cache.
struct Cached {
    time: f64,
    state: PreparedState,
    /// Built by the live pipeline (pinned states are not offered to live views).
    live: bool,
    /// Whether a frame has shown it yet.
    served: bool,
}

#[derive(Default)]
struct PipelineState {
    /// Built states, oldest first.
    ready: VecDeque<Cached>,
    /// The live build in flight.
    in_flight: Option<(f64, Arc<Pending>)>,
    /// The previous live request's time, and the smoothed spacing of live requests.
    last_request: Option<f64>,
    spacing_secs: f64,
    /// Pinned builds in flight, by time: a second viewer of the same time waits for the
    /// first one's build instead of building the same structure again.
    pinned_in_flight: Vec<(f64, Arc<Pending>)>,
}

impl PipelineState {
    fn newest_live(&mut self) -> Option<&mut Cached> {
        self.ready
            .iter_mut()
            .filter(|e| e.live)
            .max_by(|a, b| a.time.total_cmp(&b.time))
    }

    fn insert(&mut self, cached: Cached) {
        if self.ready.len() >= CACHED_STATES {
            self.ready.pop_front();
        }
        self.ready.push_back(cached);
    }

    /// Takes the cached state at `time` for a frame.
    fn take(&mut self, time: f64, live: bool) -> Option<PreparedState> {
        let entry = self
            .ready
            .iter_mut()
            .find(|e| e.time == time && (e.live || !live))?;
        let first_use = !std::mem::replace(&mut entry.served, true);
        Some(served(entry.state.clone(), first_use))
    }
}

impl DemoPipeline {
    pub(crate) fn new(
        demo: DemoScene,
        builder: Arc<Builder>,
        frame_interval_secs: f64,
    ) -> DemoPipeline {
        DemoPipeline {
            demo,
            builder,
            frame_interval_secs,
            inner: Arc::new(Mutex::new(PipelineState::default())),
            built: Arc::default(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, PipelineState> {
        // A poisoned lock only means another thread panicked; the state holds plain values.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The state a live view whose clock reads `time` shows (see the type's documentation).
    /// `seen` is the time of the state this viewer showed last: a built state newer than it is
    /// shown at once, even if another viewer showed it already, so that many viewers of one
    /// demo never wait on the build in flight while a state they have not shown is ready.
    pub fn live(&self, time: f64, seen: Option<f64>) -> PreparedState {
        let mut inner = self.lock();
        if let Some(previous) = inner.last_request {
            // A gap over a second is a pause (no viewer for a while), not the spacing of
            // requests: counted, it made the next states a quarter of a second apart and the
            // first frames after it showed one state for as long.
            let gap = time - previous;
            if gap > 0.0 && gap <= PAUSE_SECS {
                inner.spacing_secs = if inner.spacing_secs > 0.0 {
                    0.75 * inner.spacing_secs + 0.25 * gap
                } else {
                    gap
                };
            }
        }
        inner.last_request = Some(time);
        // A state built before a pause is stale: a new viewer would see the animation jump
        // back to it (by as long as the scene had no viewer), then forward.
        let period = inner.spacing_secs.max(self.frame_interval_secs);
        let oldest_shown = time - (STALE_PERIODS * period).max(PAUSE_SECS);
        let fresh = inner
            .newest_live()
            .filter(|e| seen.is_none_or(|l| e.time > l) && e.time >= oldest_shown)
            .map(|e| e.time);
        let shown = match (fresh, inner.in_flight.clone()) {
            (Some(t), _) => inner.take(t, true).map(|s| (t, s)),
            (None, Some((t, pending))) => {
                drop(inner);
                let state = pending.wait();
                inner = self.lock();
                state.and_then(|_| inner.take(t, true)).map(|s| (t, s))
            }
            (None, None) => {
                let newest = inner.newest_live().map(|e| e.time);
                match newest.filter(|&n| n >= time) {
                    // Nothing newer is due (another viewer took it): show it again.
                    Some(t) => inner.take(t, true).map(|s| (t, s)),
                    None => {
                        let pending = self.start(time);
                        inner.in_flight = Some((time, Arc::clone(&pending)));
                        drop(inner);
                        let state = pending.wait();
                        inner = self.lock();
                        state
                            .and_then(|_| inner.take(time, true))
                            .map(|s| (time, s))
                    }
                }
            }
        };
        let Some((shown_time, state)) = shown else {
            // The build failed or was evicted at once: build here.
            drop(inner);
            return self.pinned(time);
        };
        // The next state, one period ahead of what was shown; but never more than two periods
        // ahead of the clock. Without that bound every request of many viewers at one clock
        // time would show the state built for the request before it and start the one after:
        // a build per frame instead of per period, and an animation that runs as many times
        // too fast as there are frames per period (8.4 times with sixteen viewers of
        // `scattered-1k`). Two periods, not one, so that a lone viewer whose two requests fall
        // in one step of the clock still finds the next state built when its clock skips one.
        if inner.in_flight.is_none() && shown_time - time < 1.99 * period {
            let next = time.max(shown_time) + period;
            let pending = self.start(next);
            inner.in_flight = Some((next, pending));
        }
        state
    }

    /// Exactly the state at `time`. Viewers asking for the same time at once share one build.
    pub fn pinned(&self, time: f64) -> PreparedState {
        let pending = {
            let mut inner = self.lock();
            if let Some(state) = inner.take(time, false) {
                return state;
            }
            match inner.pinned_in_flight.iter().find(|(t, _)| *t == time) {
                Some((_, pending)) => Err(Arc::clone(pending)),
                None => {
                    let pending = Arc::new(Pending {
                        slot: Mutex::new(PendingSlot::Building),
                        done: Condvar::new(),
                    });
                    inner.pinned_in_flight.push((time, Arc::clone(&pending)));
                    Ok(pending)
                }
            }
        };
        match pending {
            // Another render thread builds it (it is running, so this wait ends).
            Err(pending) => match pending.wait() {
                Some(state) => served(state, false),
                None => self.build_pinned_here(time, None),
            },
            Ok(pending) => self.build_pinned_here(time, Some(pending)),
        }
    }

    /// Builds the pinned state at `time` on this thread, caches it and wakes its waiters.
    fn build_pinned_here(&self, time: f64, pending: Option<Arc<Pending>>) -> PreparedState {
        let mut guard = FailOnDrop(pending.clone());
        self.built
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        metrics::counter!(crate::metrics::STATES_BUILT, "scene" => self.demo.id()).increment(1);
        let state = build_demo(self.demo, time);
        {
            let mut inner = self.lock();
            inner.insert(Cached {
                time,
                state: state.clone(),
                live: false,
                served: true,
            });
            if let Some(p) = &pending {
                inner.pinned_in_flight.retain(|(_, q)| !Arc::ptr_eq(p, q));
            }
        }
        guard.0 = None;
        if let Some(p) = pending {
            p.finish(PendingSlot::Ready(state.clone()));
        }
        state
    }

    /// States this demo has built since the server started.
    pub fn built(&self) -> u64 {
        self.built.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Starts building the live state at `time` on the build pool.
    fn start(&self, time: f64) -> Arc<Pending> {
        let pending = Arc::new(Pending {
            slot: Mutex::new(PendingSlot::Building),
            done: Condvar::new(),
        });
        let (demo, inner, job_pending) = (self.demo, Arc::clone(&self.inner), Arc::clone(&pending));
        let built = Arc::clone(&self.built);
        self.builder.spawn(move || {
            let mut guard = FailOnDrop(Some(Arc::clone(&job_pending)));
            built.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            metrics::counter!(crate::metrics::STATES_BUILT, "scene" => demo.id()).increment(1);
            let state = build_demo(demo, time);
            {
                let mut inner = inner.lock().unwrap_or_else(|e| e.into_inner());
                inner.insert(Cached {
                    time,
                    state: state.clone(),
                    live: true,
                    served: false,
                });
                inner.in_flight = None;
            }
            guard.0 = None;
            job_pending.finish(PendingSlot::Ready(state));
        });
        pending
    }
}

/// A cached state as a frame reports it: the first frame to show a state reports what it
/// cost to make (for a prefetched state, work that overlapped the previous frame); later
/// frames report zero.
fn served(state: PreparedState, first_use: bool) -> PreparedState {
    if first_use {
        state
    } else {
        PreparedState {
            update_us: 0,
            build_us: 0,
            ..state
        }
    }
}

/// Generates and prepares the demo's state at `time` (on the calling thread's pool).
fn build_demo(demo: DemoScene, time: f64) -> PreparedState {
    let t0 = Instant::now();
    let scene: Scene = demo.state_at(time);
    let t1 = Instant::now();
    let prepared = Arc::new(scene).prepare();
    PreparedState {
        prepared,
        update_us: micros(t1 - t0),
        build_us: micros(t1.elapsed()),
        step_time: Some(time),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::Duration;

    /// Waits, on the build's own condition, for the build in flight to finish while nothing
    /// asks the pipeline for a frame: as it runs while a frame traces (a build that only ran
    /// inside the next `live` call would never finish here).
    fn settle(p: &DemoPipeline) {
        let pending = p.lock().in_flight.as_ref().map(|(_, q)| Arc::clone(q));
        if let Some(pending) = pending {
            assert!(pending.wait().is_some(), "the build finishes");
        }
        assert!(p.lock().in_flight.is_none());
    }

    #[test]
    fn a_live_frame_starts_building_the_next_state_and_the_next_frame_shows_it() {
        let p = DemoPipeline::new(DemoScene::Tornado4k, Arc::new(Builder::new(2)), 0.1);
        // Cold start: the first state is built for the request itself.
        let first = p.live(1.0, None);
        assert_eq!(first.step_time, Some(1.0));
        assert!(first.build_us > 0);
        // Returning, it left the next state (one frame interval ahead) building on the pool,
        // to run while this frame renders (fitted-bvh-metaballs.txt Fig. 7).
        assert_eq!(p.lock().in_flight.as_ref().map(|f| f.0), Some(1.1));
        settle(&p);
        let second = p.live(1.05, first.step_time);
        assert_eq!(
            second.step_time,
            Some(1.1),
            "the prefetched state, not a new build"
        );
        assert!(second.build_us > 0, "its first frame reports its build");
        // The request spacing (0.05 s) is below the frame interval: the next is 0.1 ahead.
        let next = p.lock().in_flight.as_ref().map(|f| f.0);
        assert!(next.is_some_and(|t| (t - 1.2).abs() < 1e-9), "{next:?}");
        settle(&p);
        // A pinned view gets exactly its time, and the same state twice reports no build.
        let pinned = p.pinned(7.0);
        assert_eq!(pinned.step_time, Some(7.0));
        assert!(pinned.build_us > 0);
        let again = p.pinned(7.0);
        assert_eq!((again.step_time, again.build_us), (Some(7.0), 0));
        // Pinned states are never offered to live views.
        assert!(p
            .live(1.1, second.step_time)
            .step_time
            .is_some_and(|t| (t - 1.2).abs() < 1e-9));
    }

    #[test]
    fn after_a_pause_a_viewer_sees_the_clocks_state_and_then_every_interval() {
        let p = DemoPipeline::new(DemoScene::Tornado4k, Arc::new(Builder::new(2)), 0.1);
        let mut seen = None;
        for k in 0..4 {
            seen = p.live(1.0 + 0.1 * f64::from(k), seen).step_time;
            settle(&p);
        }
        // Nobody watches for 10 s; then a new viewer (and its frames one interval apart).
        let mut seen = None;
        let mut shown = Vec::new();
        for k in 0..6 {
            let clock = 11.3 + 0.1 * f64::from(k);
            seen = p.live(clock, seen).step_time;
            settle(&p);
            shown.push(seen.map(|t| t - clock));
        }
        // Each frame shows a state within two intervals of its clock: none from before the
        // pause (which the first frame showed), and no state shown for a quarter of a second
        // (the pause counted as the requests' spacing made the next states 0.33 s apart).
        for (k, lag) in shown.iter().enumerate() {
            assert!(
                lag.is_some_and(|d| d.abs() <= 0.2 + 1e-9),
                "frame {k}: state minus clock {lag:?} (all: {shown:?})"
            );
        }
    }

    #[test]
    fn many_viewers_at_one_clock_time_build_two_states_ahead_and_no_further() {
        let p = DemoPipeline::new(DemoScene::Tornado4k, Arc::new(Builder::new(2)), 0.1);
        let mut seen = vec![None; 16];
        for _ in 0..3 {
            for s in seen.iter_mut() {
                let state = p.live(1.0, *s);
                settle(&p);
                assert!(
                    state.step_time.is_some_and(|t| t < 1.2 + 1e-9),
                    "a state more than two intervals ahead of the clock: {:?}",
                    state.step_time
                );
                *s = state.step_time;
            }
        }
        assert_eq!(p.built(), 3, "the clock's state and the two after it");
        // When the clock moves on a step, one more state is built.
        let next = p.live(1.1, seen[0]);
        assert!(next.step_time.is_some_and(|t| (t - 1.2).abs() < 1e-9));
        settle(&p);
        assert_eq!(p.built(), 4);
        let newest = p.lock().newest_live().map(|e| e.time);
        assert!(newest.is_some_and(|t| (t - 1.3).abs() < 1e-9), "{newest:?}");
    }

    #[test]
    fn a_viewer_shows_a_state_it_has_not_shown_without_waiting_for_the_build_in_flight() {
        let p = DemoPipeline::new(DemoScene::Tornado4k, Arc::new(Builder::new(1)), 0.1);
        let a = p.live(1.0, None);
        settle(&p);
        let a = p.live(1.1, a.step_time);
        assert_eq!(a.step_time, Some(1.1));
        settle(&p);
        // 1.2 is ready; a build of 1.3 is in flight that ends (failed) only after 10 s.
        let stuck = Arc::new(Pending {
            slot: Mutex::new(PendingSlot::Building),
            done: Condvar::new(),
        });
        p.lock().in_flight = Some((1.3, Arc::clone(&stuck)));
        // It ends when the test says so; after a minute regardless, so that a viewer waiting
        // for it fails the test below rather than hanging it.
        let (release, released_late) = (Arc::clone(&stuck), Arc::new(AtomicBool::new(false)));
        let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
        let late = Arc::clone(&released_late);
        let releaser = std::thread::spawn(move || {
            if done_rx.recv_timeout(Duration::from_secs(60)).is_err() {
                late.store(true, Ordering::SeqCst);
            }
            release.finish(PendingSlot::Failed);
        });
        // Viewer A shows 1.2 (its first frame of it reports the build) ...
        let near = |t: Option<f64>, want: f64| t.is_some_and(|t| (t - want).abs() < 1e-9);
        let a = p.live(1.2, a.step_time);
        assert!(near(a.step_time, 1.2), "{:?}", a.step_time);
        assert!(a.build_us > 0);
        // ... and viewer B, which last showed 1.1, shows 1.2 too rather than waiting for 1.3.
        let b = p.live(1.21, Some(1.1));
        assert!(near(b.step_time, 1.2), "{:?}", b.step_time);
        assert_eq!(b.build_us, 0);
        assert!(
            !released_late.load(Ordering::SeqCst),
            "no viewer waited for the build in flight"
        );
        // A viewer that has shown the newest state waits for the next one.
        let _ = done_tx.send(());
        assert!(releaser.join().is_ok());
    }
}
