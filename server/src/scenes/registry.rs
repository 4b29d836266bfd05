//! Every scene a server holds, by id: the built-in demos and the pushed scenes.

use crate::scenes::cache::PreparedCache;
use crate::scenes::demo::{Builder, DemoPipeline};
use crate::scenes::entry::SceneEntry;
use crate::store::{Retention, Store, StoredScene};
use isoray_protocol::SceneSummary;
use isoray_render::scenes::DemoScene;
use std::collections::BTreeMap;
use std::sync::{Arc, RwLock};
use std::time::Instant;

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
                (entry.id().to_string(), entry)
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
            .find(|e| e.id() == id)
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

    /// How many stored scenes there are.
    pub fn stored_count(&self) -> usize {
        self.read_stored().len()
    }

    /// Registers a scene just created in the store.
    pub fn add_stored(&self, scene: Arc<StoredScene>) -> Arc<SceneEntry> {
        let entry = Arc::new(SceneEntry::stored(scene, Arc::clone(&self.cache)));
        self.stored
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .insert(entry.id().to_string(), Arc::clone(&entry));
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
