//! One step of a deforming surfel object: the shared undeformed model, the step's node
//! displacements and Jacobians, how to update the hierarchy, and the state kept from frame
//! to frame (the per-pixel sphere-node cache of deforming-point-sampled-surfaces.txt §4.2.2
//! and the statistics the lazy-or-refit heuristic reads).

use crate::geom::frame::LocalFrame;
use crate::kinds::surfels::deform::{check_step, deform_surfel};
use crate::kinds::surfels::model::{SurfelError, SurfelModel};
use crate::ray::Ray;
use glam::{Mat3, Vec3};
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::Arc;

/// How a step's hierarchy follows the deformation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum UpdateMode {
    /// Spheres and surfels updated when a ray first touches them (§4.1.2, §4.4).
    Lazy,
    /// Every surfel and sphere updated before tracing (eqs. 4, 9, 11 bottom-up).
    Eager,
    /// A new hierarchy built from the deformed surfels (the paper's baseline).
    Rebuild,
    /// Lazy or eager per step, by the share of surfels the previous step touched (§6).
    Auto,
}

impl UpdateMode {
    pub fn name(self) -> &'static str {
        match self {
            UpdateMode::Lazy => "lazy",
            UpdateMode::Eager => "eager",
            UpdateMode::Rebuild => "rebuild",
            UpdateMode::Auto => "auto",
        }
    }
}

/// Tracing options of a surfel scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfelOptions {
    pub mode: UpdateMode,
    /// Test each primary ray's cached sphere node first (§4.2.2).
    pub cache: bool,
    /// MLS iterations (§4.2.1) before a leaf gives up (counted as capped).
    pub mls_iterations: u32,
    /// Convergence: `|f(x)| < mls_epsilon · h`.
    pub mls_epsilon: f32,
}

impl SurfelOptions {
    /// `mode` and `cache` with the default MLS settings.
    pub fn new(mode: UpdateMode, cache: bool) -> SurfelOptions {
        SurfelOptions {
            mode,
            cache,
            ..SurfelOptions::default()
        }
    }
}

impl Default for SurfelOptions {
    fn default() -> Self {
        SurfelOptions {
            mode: UpdateMode::Auto,
            // Off unless asked for (`isoray-bench surfels` measures it): the traversal
            // already visits the nearer child first, so the bound a cached hit gives saves
            // under 2% of tests even as an oracle, and side by side it saves no time
            // either (`surfel-impact` at 512×384, one thread: lazy 191.5 ms a frame, lazy
            // + cache 191.8).
            cache: false,
            mls_iterations: MLS_ITERATIONS,
            mls_epsilon: MLS_EPSILON,
        }
    }
}

/// MLS iterations before a leaf gives up, by default (the accuracy study: docs/accuracy.md).
pub const MLS_ITERATIONS: u32 = 12;
/// Default convergence threshold, relative to the support radius `h`.
pub const MLS_EPSILON: f32 = 1e-4;

/// Pixels the cache distinguishes: `(y · CACHE_ROW + x) mod CACHE_SLOTS` (other sizes alias,
/// which costs work, never correctness: a cached node is only a first guess).
const CACHE_ROW: u32 = 2048;
const CACHE_SLOTS: usize = 1 << 21;
/// Slots of the per-ray cache (rays without a pixel: the effects integrator's camera rays).
const RAY_SLOTS: usize = 1 << 19;

/// What a surfel scene keeps between steps; shared by all steps of one object.
pub struct SurfelRuntime {
    /// Per pixel: 1 + the surfel whose leaf held the last nearest hit, or 0.
    cache: Vec<AtomicU32>,
    /// Per ray (keyed by a hash of its origin and direction bits): the hash's upper 32 bits
    /// as a tag, and 1 + the surfel of its last nearest hit, or 0. The effects integrator
    /// asks for a camera ray's nearest hit without its pixel; the same camera sends the very
    /// same ray through a pixel every frame, so its hash finds last frame's surfel (§4.2.2
    /// "for each ray we store the sphere node..."). A moving camera finds no tags: no hint.
    rays: Vec<AtomicU64>,
    /// Share of surfels the last lazy step touched, as `f32` bits.
    touched: AtomicU32,
}

impl std::fmt::Debug for SurfelRuntime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SurfelRuntime")
            .field("touched", &self.touched_share())
            .finish_non_exhaustive()
    }
}

impl Default for SurfelRuntime {
    fn default() -> Self {
        SurfelRuntime {
            cache: (0..CACHE_SLOTS).map(|_| AtomicU32::new(0)).collect(),
            rays: (0..RAY_SLOTS).map(|_| AtomicU64::new(0)).collect(),
            touched: AtomicU32::new(0f32.to_bits()),
        }
    }
}

impl SurfelRuntime {
    #[inline]
    fn slot(&self, x: u32, y: u32) -> &AtomicU32 {
        &self.cache[(y.wrapping_mul(CACHE_ROW).wrapping_add(x)) as usize % CACHE_SLOTS]
    }

    /// The surfel cached for pixel `(x, y)`.
    #[inline]
    pub fn cached(&self, x: u32, y: u32) -> Option<u32> {
        self.slot(x, y).load(Ordering::Relaxed).checked_sub(1)
    }

    #[inline]
    pub fn remember(&self, x: u32, y: u32, surfel: Option<u32>) {
        self.slot(x, y)
            .store(surfel.map_or(0, |s| s + 1), Ordering::Relaxed);
    }

    pub fn clear_cache(&self) {
        for c in &self.cache {
            c.store(0, Ordering::Relaxed);
        }
        for c in &self.rays {
            c.store(0, Ordering::Relaxed);
        }
    }

    /// The key of a ray without a pixel: its slot and tag.
    #[inline]
    pub fn ray_key(ray: &Ray) -> (usize, u32) {
        let mut h: u64 = 0;
        for v in [ray.origin, ray.dir] {
            for b in v.to_array() {
                h = (h.rotate_left(5) ^ b.to_bits() as u64).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
            }
        }
        ((h as usize) % RAY_SLOTS, (h >> 32) as u32)
    }

    /// The surfel cached for the ray of `key`, if its tag matches.
    #[inline]
    pub fn cached_ray(&self, (slot, tag): (usize, u32)) -> Option<u32> {
        let v = self.rays[slot].load(Ordering::Relaxed);
        if (v >> 32) as u32 != tag {
            return None;
        }
        (v as u32).checked_sub(1)
    }

    #[inline]
    pub fn remember_ray(&self, (slot, tag): (usize, u32), surfel: Option<u32>) {
        let v = ((tag as u64) << 32) | surfel.map_or(0, |s| s as u64 + 1);
        self.rays[slot].store(v, Ordering::Relaxed);
    }

    pub fn touched_share(&self) -> f32 {
        f32::from_bits(self.touched.load(Ordering::Relaxed))
    }

    pub fn set_touched_share(&self, share: f32) {
        self.touched.store(share.to_bits(), Ordering::Relaxed);
    }
}

/// One step of a surfel object.
#[derive(Clone, Debug)]
pub struct SurfelScene {
    pub model: Arc<SurfelModel>,
    /// Per simulation node: displacement `u_j`.
    pub displacement: Arc<[Vec3]>,
    /// Per simulation node: Jacobian `G_j = ∂u/∂x`.
    pub gradient: Arc<[Mat3]>,
    pub options: SurfelOptions,
    pub runtime: Arc<SurfelRuntime>,
}

impl PartialEq for SurfelScene {
    fn eq(&self, o: &Self) -> bool {
        Arc::ptr_eq(&self.model, &o.model)
            && self.displacement == o.displacement
            && self.gradient == o.gradient
            && self.options == o.options
    }
}

impl SurfelScene {
    /// A step, checked against the model.
    pub fn new(
        model: Arc<SurfelModel>,
        displacement: Arc<[Vec3]>,
        gradient: Arc<[Mat3]>,
        options: SurfelOptions,
        runtime: Arc<SurfelRuntime>,
    ) -> Result<SurfelScene, SurfelError> {
        check_step(&model, &displacement, &gradient)?;
        Ok(SurfelScene {
            model,
            displacement,
            gradient,
            options,
            runtime,
        })
    }

    /// The undeformed object.
    pub fn rest(model: Arc<SurfelModel>, options: SurfelOptions) -> SurfelScene {
        let n = model.nodes.len();
        SurfelScene {
            model,
            displacement: vec![Vec3::ZERO; n].into(),
            gradient: vec![Mat3::ZERO; n].into(),
            options,
            runtime: Arc::new(SurfelRuntime::default()),
        }
    }

    pub fn validate(&self, primitive_limit: usize) -> Result<(), SurfelError> {
        if self.model.len() > primitive_limit {
            return Err(SurfelError::TooMany {
                count: self.model.len(),
                limit: primitive_limit,
            });
        }
        check_step(&self.model, &self.displacement, &self.gradient)
    }

    /// Axis-aligned bounds of the deformed surfel discs (each centre padded by its disc's
    /// largest deformed radius), or `None` for an empty object. O(surfels): for the scene
    /// description, not the hot path.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for s in 0..self.model.len() {
            let d = deform_surfel(&self.model, &self.displacement, &self.gradient, s);
            lo = lo.min(d.centre - Vec3::splat(d.leaf_radius));
            hi = hi.max(d.centre + Vec3::splat(d.leaf_radius));
        }
        (lo.cmple(hi).all()).then_some((lo, hi))
    }

    /// The world bounds of the deformed simulation nodes (rest position plus displacement):
    /// O(nodes), what the [`LocalFrame`] of a step is chosen from (the surfels follow the
    /// nodes they are embedded in).
    pub fn node_bounds(&self) -> Option<(Vec3, Vec3)> {
        let moved: Vec<Vec3> = (self.model.nodes.iter())
            .zip(self.displacement.iter())
            .map(|(p, u)| *p + *u)
            .collect();
        bounds_of(&moved)
    }

    /// This step moved into `frame`, the move split where the magnitude is: a rest model far
    /// from the origin is moved by its own frame (a new model, O(surfels)), the rest of the
    /// move is taken off the displacements (O(nodes)), each in `f64`. Jacobians are
    /// translation-invariant. A displacement that carries the object far away thus never
    /// meets a rest position of the opposite sign in `f32` (eq. 1 sums them).
    pub fn in_frame(&self, frame: &LocalFrame) -> SurfelScene {
        let mut s = self.clone();
        if frame.is_world() {
            return s;
        }
        let rest = LocalFrame::for_bounds(bounds_of(&self.model.nodes));
        if !rest.is_world() {
            s.model = Arc::new(self.model.in_frame(&rest));
        }
        let shift = LocalFrame {
            origin: frame.origin - rest.origin,
        };
        s.displacement = self
            .displacement
            .iter()
            .map(|&u| shift.local_from_world(u))
            .collect();
        s
    }

    /// Surfels have no scalar field: every isovalue shows the same surface.
    pub fn isovalue_range(&self) -> (f32, f32) {
        (f32::MIN, f32::MAX)
    }
}

/// Axis-aligned bounds of `points`, or `None` for none.
fn bounds_of(points: &[Vec3]) -> Option<(Vec3, Vec3)> {
    let lo = points
        .iter()
        .fold(Vec3::splat(f32::INFINITY), |a, p| a.min(*p));
    let hi = points
        .iter()
        .fold(Vec3::splat(f32::NEG_INFINITY), |a, p| a.max(*p));
    (lo.cmple(hi).all()).then_some((lo, hi))
}
