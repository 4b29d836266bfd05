//! The scenes a server holds, and a small per-scene cache of prepared states so that every
//! session watching the same scene at the same time step shares one acceleration structure.

use isoray_protocol::SceneSummary;
use isoray_render::scenes::DemoScene;
use isoray_render::{PreparedScene, Scene};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Prepared states kept per scene: the live step plus a few pinned ones.
const CACHED_STATES: usize = 4;

/// Every scene this server can stream.
pub struct SceneRegistry {
    entries: Vec<Arc<SceneEntry>>,
    started: Instant,
}

impl SceneRegistry {
    /// The built-in demo scenes.
    pub fn with_demos() -> SceneRegistry {
        SceneRegistry {
            entries: DemoScene::ALL
                .iter()
                .map(|&demo| Arc::new(SceneEntry::new(demo)))
                .collect(),
            started: Instant::now(),
        }
    }

    pub fn get(&self, id: &str) -> Option<Arc<SceneEntry>> {
        self.entries.iter().find(|e| e.id() == id).cloned()
    }

    pub fn summaries(&self) -> Vec<SceneSummary> {
        self.entries.iter().map(|e| e.summary()).collect()
    }

    /// Seconds since the server started: the time of every live (unpinned) view.
    pub fn live_time(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
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
}

/// A scene and its cache.
pub struct SceneEntry {
    demo: DemoScene,
    primitives: usize,
    isovalue_range: (f32, f32),
    cache: Mutex<Vec<(u64, PreparedState)>>,
}

impl SceneEntry {
    fn new(demo: DemoScene) -> SceneEntry {
        let first = demo.state_at(0.0);
        SceneEntry {
            demo,
            primitives: first.primitive_count(),
            isovalue_range: first.isovalue_range(),
            cache: Mutex::new(Vec::with_capacity(CACHED_STATES)),
        }
    }

    pub fn id(&self) -> &'static str {
        self.demo.id()
    }

    pub fn demo(&self) -> DemoScene {
        self.demo
    }

    pub fn isovalue_range(&self) -> (f32, f32) {
        self.isovalue_range
    }

    pub fn summary(&self) -> SceneSummary {
        SceneSummary {
            id: self.demo.id().to_string(),
            name: self.demo.name().to_string(),
            kind: "metaballs".to_string(),
            primitives: self.primitives as u64,
            animated: true,
            description: self.demo.description().to_string(),
        }
    }

    /// The state at `time`, prepared for tracing; built on first use and then shared.
    /// Blocking: call it on the render pool. A cache hit reports zero update and build time.
    pub fn prepared_at(&self, time: f64) -> PreparedState {
        let key = time.to_bits();
        // A poisoned lock only means another render panicked; the cache holds plain values.
        let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, hit)) = cache.iter().find(|(k, _)| *k == key) {
            return PreparedState {
                update_us: 0,
                build_us: 0,
                ..hit.clone()
            };
        }
        let t0 = Instant::now();
        let scene: Scene = self.demo.state_at(time);
        let t1 = Instant::now();
        let prepared = Arc::new(scene).prepare();
        let state = PreparedState {
            prepared,
            update_us: micros(t1 - t0),
            build_us: micros(t1.elapsed()),
        };
        if cache.len() == CACHED_STATES {
            cache.remove(0);
        }
        cache.push((key, state.clone()));
        state
    }
}

/// A duration in whole microseconds, saturating.
pub fn micros(d: std::time::Duration) -> u32 {
    u32::try_from(d.as_micros()).unwrap_or(u32::MAX)
}
