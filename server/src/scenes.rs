//! The scenes a server holds — built-in animated demos and pushed scenes from the store — and
//! the caches of prepared states, so every session watching the same state shares one
//! acceleration structure.
//!
//! A demo is a pure function of time, cached per scene for the last few times. A stored scene
//! is a sequence of pushed steps: a live viewer sees the newest step, a viewer who pins a time
//! sees the step with the largest time not after it. Prepared stored steps share one cache
//! bounded in bytes across all scenes (`--cache-bytes`), least recently used first out.

use crate::kind::SceneSetup;
use crate::store::{Retention, Store, StoredScene, StoredStep};
use isoray_protocol::api::{SceneInfo, SceneKind};
use isoray_protocol::SceneSummary;
use isoray_render::scenes::DemoScene;
use isoray_render::{Camera, Lighting, PreparedScene, Scene};
use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Instant;

/// Prepared states kept per demo scene: the live step plus a few pinned ones.
const CACHED_STATES: usize = 4;

/// Isovalues a viewer of a pushed scene may choose: the field's maximum changes per step, so
/// the bound is generous and the slider carries the useful range.
const STORED_ISOVALUE_RANGE: (f32, f32) = (0.0, 1.0e6);

/// Every scene this server can stream.
pub struct SceneRegistry {
    demos: Vec<Arc<SceneEntry>>,
    stored: RwLock<BTreeMap<String, Arc<SceneEntry>>>,
    store: Option<Arc<Store>>,
    cache: Arc<PreparedCache>,
    started: Instant,
}

impl SceneRegistry {
    /// The built-in demo scenes only.
    pub fn with_demos() -> SceneRegistry {
        SceneRegistry::new(None, 0)
    }

    /// The demos plus every scene in `store`, with a prepared-step cache of `cache_bytes`.
    pub fn new(store: Option<Arc<Store>>, cache_bytes: u64) -> SceneRegistry {
        let cache = Arc::new(PreparedCache::new(cache_bytes));
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
                .map(|&demo| Arc::new(SceneEntry::demo_entry(demo)))
                .collect(),
            stored: RwLock::new(stored),
            store,
            cache,
            started: Instant::now(),
        }
    }

    /// The demos, plus the store the configuration names. A store that cannot be opened is
    /// logged and the server runs with its demos only.
    pub fn from_config(config: &crate::Config) -> SceneRegistry {
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
        SceneRegistry::new(store, config.cache_bytes)
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
    /// For a stored scene, the time of the step this state shows (0 before its first step);
    /// `None` for demos, whose states are functions of the requested time.
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
}

enum Source {
    Demo {
        demo: DemoScene,
        primitives: usize,
        isovalue_range: (f32, f32),
        lighting: Lighting,
        cache: Mutex<Vec<(u64, PreparedState)>>,
    },
    Stored {
        scene: Arc<StoredScene>,
        setup: SceneSetup,
        cache: Arc<PreparedCache>,
    },
}

impl SceneEntry {
    fn demo_entry(demo: DemoScene) -> SceneEntry {
        let first = demo.state_at(0.0);
        SceneEntry {
            id: demo.id().to_string(),
            source: Source::Demo {
                demo,
                primitives: first.primitive_count(),
                isovalue_range: first.isovalue_range(),
                lighting: first.lighting.clone(),
                cache: Mutex::new(Vec::with_capacity(CACHED_STATES)),
            },
        }
    }

    fn stored(scene: Arc<StoredScene>, cache: Arc<PreparedCache>) -> SceneEntry {
        SceneEntry {
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
            Source::Stored { .. } => STORED_ISOVALUE_RANGE,
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
                kind: match demo {
                    DemoScene::TetGyroid => SceneKind::Tets,
                    _ => SceneKind::Metaballs,
                },
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
                    primitives: steps.last().map_or(0, |s| s.header.rows),
                    steps: steps.len() as u64,
                    first_step: steps.first().map(|s| s.header.index),
                    last_step: steps.last().map(|s| s.header.index),
                    stored_bytes: steps.iter().map(|s| s.file_bytes).sum(),
                }
            }
        }
    }

    /// The state at `time`, prepared for tracing; built on first use and then shared. A live
    /// view of a stored scene sees its newest step. Blocking: call it on the render pool. A
    /// cache hit reports zero update and build time.
    pub fn prepared_at(&self, time: f64, live: bool) -> PreparedState {
        match &self.source {
            Source::Demo { demo, cache, .. } => demo_prepared_at(*demo, cache, time),
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
            return self.prepared_at(0.0, false);
        };
        let build = |step: Option<&StoredStep>| {
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

fn demo_prepared_at(
    demo: DemoScene,
    cache: &Mutex<Vec<(u64, PreparedState)>>,
    time: f64,
) -> PreparedState {
    let key = time.to_bits();
    // A poisoned lock only means another render panicked; the cache holds plain values.
    let mut cache = cache.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, hit)) = cache.iter().find(|(k, _)| *k == key) {
        return PreparedState {
            update_us: 0,
            build_us: 0,
            ..hit.clone()
        };
    }
    let t0 = Instant::now();
    let scene: Scene = demo.state_at(time);
    let t1 = Instant::now();
    let prepared = Arc::new(scene).prepare();
    let state = PreparedState {
        prepared,
        update_us: micros(t1 - t0),
        build_us: micros(t1.elapsed()),
        step_time: None,
    };
    if cache.len() == CACHED_STATES {
        cache.remove(0);
    }
    cache.push((key, state.clone()));
    state
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
