//! The scenes a server holds — built-in animated demos and pushed scenes from the store — and
//! the caches of prepared states, so every session watching the same state shares one
//! acceleration structure.
//!
//! A demo is a pure function of time, cached per scene for the last few times. Its states are
//! built on a build pool of their own, apart from the render pool, and live views are
//! pipelined as in fitted-bvh-metaballs.txt Fig. 7: a live request takes the newest state
//! already built and starts building the state at the current time, so the build of state
//! k+1 overlaps the rendering of state k (see [`DemoPipeline`]). A pinned time gets exactly
//! that state. A stored scene is a sequence of pushed steps: a live viewer sees the newest
//! step, a viewer who pins a time sees the step with the largest time not after it. Prepared
//! stored steps share one cache bounded in bytes across all scenes (`--cache-bytes`), least
//! recently used first out.

use crate::kinds::SceneSetup;
use crate::store::{Retention, Store, StoredScene, StoredStep};
use isoray_protocol::api::SceneInfo;
use isoray_protocol::SceneSummary;
use isoray_render::scenes::DemoScene;
use isoray_render::{Camera, Lighting, PreparedScene, Scene};
use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::Instant;

/// Prepared states kept per demo scene: the live step plus a few pinned ones.
const CACHED_STATES: usize = 4;

/// Every scene this server can stream.
pub struct SceneRegistry {
    demos: Vec<Arc<SceneEntry>>,
    stored: RwLock<BTreeMap<String, Arc<SceneEntry>>>,
    store: Option<Arc<Store>>,
    cache: Arc<PreparedCache>,
    started: Instant,
}

impl SceneRegistry {
    /// The built-in demo scenes only, built on a pool of one thread per core.
    pub fn with_demos() -> SceneRegistry {
        SceneRegistry::new(None, 0, 0, 1.0 / 30.0)
    }

    /// The demos plus every scene in `store`, with a prepared-step cache of `cache_bytes`;
    /// demo states are built on a pool of `build_threads` (0: one per core), live ones at
    /// least `frame_interval_secs` apart.
    pub fn new(
        store: Option<Arc<Store>>,
        cache_bytes: u64,
        build_threads: usize,
        frame_interval_secs: f64,
    ) -> SceneRegistry {
        let cache = Arc::new(PreparedCache::new(cache_bytes));
        let builder = Arc::new(Builder::new(build_threads));
        let stored = store
            .iter()
            .flat_map(|s| s.scenes())
            .map(|scene| {
                let entry = Arc::new(SceneEntry::stored(scene, Arc::clone(&cache)));
                (entry.id.clone(), entry)
            })
            .collect();
        SceneRegistry {
            demos: DemoScene::ALL
                .iter()
                .map(|&demo| {
                    let pipeline =
                        DemoPipeline::new(demo, Arc::clone(&builder), frame_interval_secs);
                    Arc::new(SceneEntry::demo_entry(demo, pipeline))
                })
                .collect(),
            stored: RwLock::new(stored),
            store,
            cache,
            started: Instant::now(),
        }
    }

    /// The demos, plus the store the configuration names. A store that cannot be opened is
    /// logged and the server runs with its demos only.
    pub fn from_config(config: &crate::config::Config) -> SceneRegistry {
        let dir = if config.demos_only {
            None
        } else {
            config
                .data_dir
                .clone()
                .or_else(crate::config::default_data_dir)
        };
        let store = dir.and_then(|dir| {
            let retention = Retention {
                max_steps_per_scene: config.max_steps_per_scene,
                max_bytes_per_scene: config.max_scene_bytes,
                max_total_bytes: config.max_store_bytes,
            };
            match Store::open(&dir, retention) {
                Ok(store) => Some(Arc::new(store)),
                Err(e) => {
                    tracing::warn!(error = %e, "no scene store: serving the demos only");
                    None
                }
            }
        });
        SceneRegistry::new(
            store,
            config.cache_bytes,
            config.threads,
            1.0 / config.max_fps,
        )
    }

    /// The store of pushed scenes, when the server has a data directory.
    pub fn store(&self) -> Option<&Arc<Store>> {
        self.store.as_ref()
    }

    pub fn get(&self, id: &str) -> Option<Arc<SceneEntry>> {
        self.demos
            .iter()
            .find(|e| e.id == id)
            .cloned()
            .or_else(|| self.read_stored().get(id).cloned())
    }

    /// Every scene: demos first, then stored scenes by id.
    pub fn entries(&self) -> Vec<Arc<SceneEntry>> {
        let mut all = self.demos.clone();
        all.extend(self.read_stored().values().cloned());
        all
    }

    pub fn summaries(&self) -> Vec<SceneSummary> {
        self.entries().iter().map(|e| e.summary()).collect()
    }

    /// Registers a scene just created in the store.
    pub fn add_stored(&self, scene: Arc<StoredScene>) -> Arc<SceneEntry> {
        let entry = Arc::new(SceneEntry::stored(scene, Arc::clone(&self.cache)));
        self.stored
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .insert(entry.id.clone(), Arc::clone(&entry));
        entry
    }

    /// Forgets a deleted scene; sessions still watching keep their last state.
    pub fn remove_stored(&self, id: &str) {
        self.stored
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .remove(id);
        self.cache.forget_scene(id);
    }

    /// Seconds since the server started: the time of every live (unpinned) view.
    pub fn live_time(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    fn read_stored(&self) -> std::sync::RwLockReadGuard<'_, BTreeMap<String, Arc<SceneEntry>>> {
        self.stored.read().unwrap_or_else(|e| e.into_inner())
    }
}

/// One prepared state and what it cost.
#[derive(Clone)]
pub struct PreparedState {
    pub prepared: PreparedScene,
    /// Time to produce the scene state (simulation step or generator), microseconds.
    pub update_us: u32,
    /// Time to build the acceleration structure, microseconds.
    pub build_us: u32,
    /// The time of the state shown, when it is not simply the requested time: a stored
    /// scene's step (0 before its first step), or the demo state a live view shows (the
    /// newest built, up to a frame away from the view's clock).
    pub step_time: Option<f64>,
}

/// What a viewer starts with: camera, isovalue and slider range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneLook {
    camera: Camera,
    isovalue: f32,
    slider: (f32, f32),
}

impl SceneLook {
    pub fn default_camera(&self) -> Camera {
        self.camera
    }

    pub fn default_isovalue(&self) -> f32 {
        self.isovalue
    }

    pub fn isovalue_slider(&self) -> (f32, f32) {
        self.slider
    }
}

/// A scene and where its states come from.
pub struct SceneEntry {
    id: String,
    source: Source,
    /// Stored steps prepared for this scene so far (cache misses); demos count in their
    /// pipeline. A scene nobody watches builds nothing.
    states_built: std::sync::atomic::AtomicU64,
}

enum Source {
    Demo {
        demo: DemoScene,
        primitives: usize,
        isovalue_range: (f32, f32),
        lighting: Lighting,
        pipeline: DemoPipeline,
    },
    Stored {
        scene: Arc<StoredScene>,
        setup: SceneSetup,
        cache: Arc<PreparedCache>,
    },
}

impl SceneEntry {
    fn demo_entry(demo: DemoScene, pipeline: DemoPipeline) -> SceneEntry {
        let first = demo.state_at(0.0);
        SceneEntry {
            states_built: Default::default(),
            id: demo.id().to_string(),
            source: Source::Demo {
                demo,
                primitives: first.primitive_count(),
                isovalue_range: first.isovalue_range(),
                lighting: first.lighting.clone(),
                pipeline,
            },
        }
    }

    fn stored(scene: Arc<StoredScene>, cache: Arc<PreparedCache>) -> SceneEntry {
        SceneEntry {
            states_built: Default::default(),
            id: scene.meta.id.clone(),
            source: Source::Stored {
                setup: scene.setup.clone(),
                scene,
                cache,
            },
        }
    }

    pub fn id(&self) -> &str {
        &self.id
    }

    /// What a viewer starts with (named for the demos, which had it first).
    pub fn demo(&self) -> SceneLook {
        match &self.source {
            Source::Demo { demo, .. } => SceneLook {
                camera: demo.default_camera(),
                isovalue: demo.default_isovalue(),
                slider: demo.isovalue_slider(),
            },
            Source::Stored { setup, .. } => SceneLook {
                camera: setup.camera,
                isovalue: setup.isovalue,
                slider: setup.slider,
            },
        }
    }

    /// The pushed scene behind this entry, if it is one.
    pub fn stored_scene(&self) -> Option<&Arc<StoredScene>> {
        match &self.source {
            Source::Demo { .. } => None,
            Source::Stored { scene, .. } => Some(scene),
        }
    }

    /// How the scene is lit and shaded (demo scenes keep one look for all their states).
    pub fn lighting(&self) -> &Lighting {
        match &self.source {
            Source::Demo { lighting, .. } => lighting,
            Source::Stored { setup, .. } => &setup.lighting,
        }
    }

    /// Primitives a state may hold, for the effects a scene can use: a demo's count, or any
    /// number for a pushed scene (a later step may fill every group).
    pub fn effect_primitives(&self) -> usize {
        match &self.source {
            Source::Demo { primitives, .. } => *primitives,
            Source::Stored { .. } => u32::MAX as usize,
        }
    }

    pub fn isovalue_range(&self) -> (f32, f32) {
        match &self.source {
            Source::Demo { isovalue_range, .. } => *isovalue_range,
            Source::Stored { setup, .. } => setup.isovalue_range(),
        }
    }

    pub fn summary(&self) -> SceneSummary {
        let info = self.info();
        SceneSummary {
            id: info.id,
            name: info.name,
            kind: info.kind.as_str().to_string(),
            primitives: info.primitives,
            animated: true,
            description: info.description,
        }
    }

    /// The scene as the REST API describes it.
    pub fn info(&self) -> SceneInfo {
        match &self.source {
            Source::Demo {
                demo, primitives, ..
            } => SceneInfo {
                id: self.id.clone(),
                name: demo.name().to_string(),
                kind: crate::kinds::demo_kind(*demo),
                description: demo.description().to_string(),
                animated: true,
                source: "demo".into(),
                primitives: *primitives as u64,
                steps: 0,
                first_step: None,
                last_step: None,
                stored_bytes: 0,
            },
            Source::Stored { scene, .. } => {
                let steps = scene.steps();
                let spec = &scene.meta.spec;
                SceneInfo {
                    id: self.id.clone(),
                    name: spec.name.clone().unwrap_or_else(|| "pushed scene".into()),
                    kind: scene.meta.kind,
                    description: spec.description.clone().unwrap_or_default(),
                    animated: true,
                    source: "stored".into(),
                    primitives: scene
                        .setup
                        .primitives(steps.last().map_or(0, |s| s.header.rows)),
                    steps: steps.len() as u64,
                    first_step: steps.first().map(|s| s.header.index),
                    last_step: steps.last().map(|s| s.header.index),
                    stored_bytes: steps.iter().map(|s| s.file_bytes).sum(),
                }
            }
        }
    }

    /// Identifies the state a view at `time` shows (`live`: following the scene as it
    /// changes): equal keys, same state. For a demo, a pure function of time, it is the time;
    /// for a stored scene, the step (index and checksum), so a live view of a stored scene sees
    /// a new state only when a step is pushed. Cheap: the session asks on the async side.
    pub fn state_key(&self, time: f64, live: bool) -> u128 {
        match &self.source {
            Source::Demo { .. } => time.to_bits() as u128,
            Source::Stored { scene, .. } => {
                let step = if live {
                    scene.latest()
                } else {
                    scene.at_time(time)
                };
                step.map_or(0, |s| {
                    (s.header.index as u128) ^ s.header.checksum.rotate_left(64)
                })
            }
        }
    }

    /// Whether a live view of this scene changes with the clock (the demos do; a stored
    /// scene changes when a step is pushed).
    pub fn animates(&self) -> bool {
        matches!(self.source, Source::Demo { .. })
    }

    /// States prepared for this scene since the server started (cache misses).
    pub fn states_built(&self) -> u64 {
        match &self.source {
            Source::Demo { pipeline, .. } => pipeline.built(),
            Source::Stored { .. } => self.states_built.load(std::sync::atomic::Ordering::Relaxed),
        }
    }

    fn count_build(&self) {
        self.states_built
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        metrics::counter!(crate::metrics::STATES_BUILT, "scene" => self.id.clone()).increment(1);
    }

    /// The state at `time`, prepared for tracing; built on first use and then shared. A live
    /// view of a stored scene sees its newest step; a live view of a demo the newest state
    /// built that is newer than `seen` (the time of the state it showed last). Blocking: call
    /// it on the render pool. A cache hit reports zero update and build time.
    pub fn prepared_at(&self, time: f64, live: bool, seen: Option<f64>) -> PreparedState {
        match &self.source {
            Source::Demo { pipeline, .. } if live => pipeline.live(time, seen),
            Source::Demo { pipeline, .. } => pipeline.pinned(time),
            Source::Stored { scene, .. } => {
                let step = if live {
                    scene.latest()
                } else {
                    scene.at_time(time)
                };
                self.prepared_step(step.as_deref())
            }
        }
    }

    /// A stored step prepared for tracing (an empty scene before the first push).
    pub fn prepared_step(&self, step: Option<&StoredStep>) -> PreparedState {
        let Source::Stored { setup, cache, .. } = &self.source else {
            return self.prepared_at(0.0, false, None);
        };
        let build = |step: Option<&StoredStep>| {
            self.count_build();
            let t0 = Instant::now();
            let scene = setup.scene(step.map(|s| (s.header.columns, s.payload())));
            let t1 = Instant::now();
            let prepared = Arc::new(scene).prepare();
            PreparedState {
                prepared,
                update_us: micros(t1 - t0),
                build_us: micros(t1.elapsed()),
                step_time: Some(step.map_or(0.0, |s| s.header.time)),
            }
        };
        match step {
            None => build(None),
            Some(s) => {
                let key = (self.id.clone(), s.header.index, s.header.checksum);
                let bytes = setup.prepared_bytes(s.header.rows);
                cache.get_or_build(key, bytes, || build(Some(s)))
            }
        }
    }
}

/// The pool demo states are built on: apart from the render pool, so that a render thread
/// waiting for a build never waits for work queued behind itself, and sized to every core,
/// so a build (which forks on rayon) uses both cores while a frame renders.
pub struct Builder {
    pool: Option<rayon::ThreadPool>,
}

impl Builder {
    fn new(threads: usize) -> Builder {
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
    fn new(demo: DemoScene, builder: Arc<Builder>, frame_interval_secs: f64) -> DemoPipeline {
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
            // A viewer that paused does not stretch the estimate past a second.
            let gap = (time - previous).min(1.0);
            if gap > 0.0 {
                inner.spacing_secs = if inner.spacing_secs > 0.0 {
                    0.75 * inner.spacing_secs + 0.25 * gap
                } else {
                    gap
                };
            }
        }
        inner.last_request = Some(time);
        let fresh = inner
            .newest_live()
            .filter(|e| seen.is_none_or(|l| e.time > l))
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
        if inner.in_flight.is_none() {
            let next = time.max(shown_time) + inner.spacing_secs.max(self.frame_interval_secs);
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

type CacheKey = (String, u64, u128);

/// Prepared stored steps, bounded in bytes, least recently used evicted first.
pub struct PreparedCache {
    max_bytes: u64,
    inner: Mutex<CacheInner>,
}

#[derive(Default)]
struct CacheInner {
    entries: VecDeque<(CacheKey, PreparedState, u64)>,
    bytes: u64,
}

impl PreparedCache {
    fn new(max_bytes: u64) -> PreparedCache {
        PreparedCache {
            max_bytes,
            inner: Mutex::new(CacheInner::default()),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The cached state for `key`, or one built now (outside the lock) and cached if it fits.
    fn get_or_build(
        &self,
        key: CacheKey,
        bytes: u64,
        build: impl FnOnce() -> PreparedState,
    ) -> PreparedState {
        {
            let mut inner = self.lock();
            if let Some(pos) = inner.entries.iter().position(|(k, _, _)| *k == key) {
                let hit = inner.entries.remove(pos).expect("position is in range");
                let state = PreparedState {
                    update_us: 0,
                    build_us: 0,
                    ..hit.1.clone()
                };
                inner.entries.push_back(hit);
                return state;
            }
        }
        let state = build();
        if bytes <= self.max_bytes {
            let mut inner = self.lock();
            if !inner.entries.iter().any(|(k, _, _)| *k == key) {
                while inner.bytes + bytes > self.max_bytes {
                    let Some((_, _, b)) = inner.entries.pop_front() else {
                        break;
                    };
                    inner.bytes -= b;
                }
                inner.bytes += bytes;
                inner.entries.push_back((key, state.clone(), bytes));
            }
        }
        state
    }

    fn forget_scene(&self, id: &str) {
        let mut inner = self.lock();
        let mut freed = 0;
        inner.entries.retain(|(k, _, b)| {
            let keep = k.0 != id;
            if !keep {
                freed += b;
            }
            keep
        });
        inner.bytes -= freed;
    }

    /// Bytes held now.
    pub fn bytes(&self) -> u64 {
        self.lock().bytes
    }
}

/// A duration in whole microseconds, saturating.
pub fn micros(d: std::time::Duration) -> u32 {
    u32::try_from(d.as_micros()).unwrap_or(u32::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// Waits until the pipeline has no build in flight.
    fn settle(p: &DemoPipeline) {
        let deadline = Instant::now() + Duration::from_secs(60);
        while p.lock().in_flight.is_some() {
            assert!(Instant::now() < deadline, "the build finishes");
            std::thread::sleep(Duration::from_millis(5));
        }
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
        let release = Arc::clone(&stuck);
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_secs(10));
            release.finish(PendingSlot::Failed);
        });
        let start = Instant::now();
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
            start.elapsed() < Duration::from_secs(5),
            "no viewer waited for the build in flight: {:?}",
            start.elapsed()
        );
        // A viewer that has shown the newest state waits for the next one.
        stuck.finish(PendingSlot::Failed);
    }
}
