//! One scene a server holds, a built-in demo or a pushed scene, and how a view of it gets
//! its prepared state.

use crate::kinds::SceneSetup;
use crate::scenes::cache::PreparedCache;
use crate::scenes::demo::DemoPipeline;
use crate::scenes::prepared::{micros, PreparedState};
use crate::store::{StoredScene, StoredStep};
use isoray_protocol::api::{SceneInfo, SceneKind};
use isoray_protocol::SceneSummary;
use isoray_render::scenes::DemoScene;
use isoray_render::{Camera, Lighting};
use std::sync::Arc;
use std::time::Instant;

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
    /// Pool seconds per pixel of this scene's latest interactive frames, as the frame's
    /// session estimated it (`f64` bits; 0: none yet): a new viewer's first frame starts from
    /// it instead of from the full size.
    pixel_cost: std::sync::atomic::AtomicU64,
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
    pub(crate) fn demo_entry(demo: DemoScene, pipeline: DemoPipeline) -> SceneEntry {
        // A surfel demo simulates and builds its object on first use (seconds for the large
        // one), so its entry is described without a state: surfels have no field, so every
        // isovalue shows the same surface.
        let (primitives, isovalue_range) = match crate::kinds::demo_kind(demo) {
            SceneKind::Surfels => (demo.ball_count(), (f32::MIN, f32::MAX)),
            SceneKind::Metaballs | SceneKind::Tets => {
                let first = demo.state_at(0.0);
                (first.primitive_count(), first.isovalue_range())
            }
        };
        SceneEntry {
            states_built: Default::default(),
            pixel_cost: Default::default(),
            id: demo.id().to_string(),
            source: Source::Demo {
                demo,
                primitives,
                isovalue_range,
                lighting: demo.lighting(),
                pipeline,
            },
        }
    }

    pub(crate) fn stored(scene: Arc<StoredScene>, cache: Arc<PreparedCache>) -> SceneEntry {
        SceneEntry {
            states_built: Default::default(),
            pixel_cost: Default::default(),
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

    /// The scene's primitive kind.
    pub fn kind(&self) -> SceneKind {
        match &self.source {
            Source::Demo { demo, .. } => crate::kinds::demo_kind(*demo),
            Source::Stored { scene, .. } => scene.meta.kind,
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
                kind: self.kind(),
                description: demo.description().to_string(),
                animated: true,
                source: "demo".into(),
                primitives: *primitives as u64,
                steps: 0,
                first_step: None,
                last_step: None,
                stored_bytes: 0,
                bounds: None,
            },
            Source::Stored { scene, .. } => {
                let steps = scene.steps();
                let spec = &scene.meta.spec;
                SceneInfo {
                    id: self.id.clone(),
                    name: spec.name.clone().unwrap_or_else(|| "pushed scene".into()),
                    kind: self.kind(),
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
                    bounds: None,
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

    /// Pool seconds per pixel of the scene's latest interactive frames (see the field).
    pub fn pixel_cost(&self) -> Option<f64> {
        let bits = self.pixel_cost.load(std::sync::atomic::Ordering::Relaxed);
        Some(f64::from_bits(bits)).filter(|c| *c > 0.0 && c.is_finite())
    }

    /// Records a session's estimate of the pool seconds a pixel of this scene costs.
    pub fn note_pixel_cost(&self, seconds: f64) {
        if seconds > 0.0 && seconds.is_finite() {
            self.pixel_cost
                .store(seconds.to_bits(), std::sync::atomic::Ordering::Relaxed);
        }
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
        // Stored scenes count under one label: their ids are unbounded (one series per
        // scene ever pushed would grow without end); demos are a fixed set.
        metrics::counter!(crate::metrics::STATES_BUILT, "scene" => "stored").increment(1);
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
