//! The closed set of primitive kinds, and the one place that matches on it.
//!
//! Every query a scene answers is one `match` here that hands the kind's prepared state to a
//! generic function of the [`PreparedKind`] contract, so each arm is monomorphic. Adding a
//! kind adds a variant to [`Geometry`] and [`PreparedGeometry`], an arm to each `match` below
//! (the compiler lists them: no arm is a wildcard) and a field to
//! [`SceneCounters`].

use crate::camera::PrimaryRays;
use crate::geom::frame::LocalFrame;
use crate::kinds::contract::{settle, OcclusionHint, PreparedKind, RayStart};
use crate::kinds::counters::SceneCounters;
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::engine::{PrepareOptions, PreparedMetaballs};
use crate::kinds::metaballs::scene::{MetaballError, MetaballScene};
use crate::kinds::surfels::model::SurfelError;
use crate::kinds::surfels::prepared::PreparedSurfels;
use crate::kinds::surfels::scene::SurfelScene;
use crate::kinds::tets::mesh::{TetError, TetScene};
use crate::kinds::tets::prepared::{PreparedTets, TetOptions};
use crate::ray::{Hit, Ray};
use glam::Vec3;
use std::sync::Arc;

/// The primitive kinds isoray traces. New kinds are new variants, matched in this file.
#[derive(Clone, Debug, PartialEq)]
pub enum Geometry {
    Metaballs(MetaballScene),
    /// A tetrahedral mesh with one scalar field (one time step).
    Tets(TetScene),
    /// A deforming surfel object (one step).
    Surfels(SurfelScene),
}

/// The prepared form of each primitive kind.
#[derive(Clone, Debug)]
pub enum PreparedGeometry {
    Metaballs(Arc<PreparedMetaballs>),
    Tets(Arc<PreparedTets>),
    Surfels(Arc<PreparedSurfels>),
}

/// Why scene data was rejected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    #[error(transparent)]
    Metaball(#[from] MetaballError),
    #[error(transparent)]
    Tet(#[from] TetError),
    #[error(transparent)]
    Surfel(#[from] SurfelError),
}

impl Geometry {
    /// Checks the data against the engine's limits.
    pub fn validate(&self, primitive_limit: usize) -> Result<(), SceneError> {
        match self {
            Geometry::Metaballs(m) => m.validate(primitive_limit)?,
            Geometry::Tets(t) => t.validate(primitive_limit)?,
            Geometry::Surfels(s) => s.validate(primitive_limit)?,
        }
        Ok(())
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        match self {
            Geometry::Metaballs(m) => m.balls.len(),
            Geometry::Tets(t) => t.tet_count(),
            Geometry::Surfels(s) => s.model.len(),
        }
    }

    /// Axis-aligned bounds of the primitives (metaballs: every ball's support; tets: the
    /// step's vertices), or `None` for an empty state.
    pub fn bounds(&self) -> Option<(glam::Vec3, glam::Vec3)> {
        match self {
            Geometry::Metaballs(m) => m.bounds(),
            Geometry::Tets(t) => t.bounds(),
            Geometry::Surfels(s) => s.bounds(),
        }
    }

    /// Isovalues for which the surface may exist, as an open interval.
    pub fn isovalue_range(&self) -> (f32, f32) {
        match self {
            Geometry::Metaballs(m) => m.isovalue_range(),
            Geometry::Tets(t) => t.isovalue_range(),
            Geometry::Surfels(s) => s.isovalue_range(),
        }
    }

    /// The metaball options a plain prepare uses: the Fitted BVH with every optimisation,
    /// for the state's lowest isovalue, and Bézier clipping.
    pub fn default_metaball_options(&self) -> PrepareOptions {
        match self {
            Geometry::Metaballs(m) => PrepareOptions::fitted(m.min_isovalue),
            Geometry::Tets(_) | Geometry::Surfels(_) => PrepareOptions::fitted(0.0),
        }
    }

    /// The frame this state is traced in ([`LocalFrame::for_bounds`] of its bounds; for
    /// surfels the deformed simulation nodes' bounds, which cost O(nodes), not O(surfels)).
    pub fn frame(&self) -> LocalFrame {
        let bounds = match self {
            Geometry::Metaballs(m) => m.bounds(),
            Geometry::Tets(t) => t.bounds(),
            Geometry::Surfels(s) => s.node_bounds(),
        };
        LocalFrame::for_bounds(bounds)
    }

    /// Builds what tracing needs in `frame` (the geometry moved there in `f64` before it
    /// becomes the kind's `f32` data); each kind takes its own options and ignores the others.
    pub fn prepare(
        &self,
        options: PrepareOptions,
        tet_options: TetOptions,
        frame: &LocalFrame,
    ) -> PreparedGeometry {
        match self {
            Geometry::Metaballs(m) => PreparedGeometry::Metaballs(Arc::new(
                PreparedMetaballs::new(m.in_frame(frame), options),
            )),
            Geometry::Tets(t) => PreparedGeometry::Tets(Arc::new(PreparedTets::new_in_frame(
                t.clone(),
                tet_options,
                frame,
            ))),
            Geometry::Surfels(s) => {
                PreparedGeometry::Surfels(Arc::new(PreparedSurfels::new(s.in_frame(frame))))
            }
        }
    }
}

/// Where a query's work is counted: every kind's counters, or (for the benches, which
/// count metaball scenes) the metaball counters alone.
pub trait Tally {
    /// Runs `f` on this tally's counters of kind `K`.
    fn count<K: PreparedKind, R>(&mut self, f: impl FnOnce(&mut K::Counters) -> R) -> R;
}

impl Tally for SceneCounters {
    #[inline]
    fn count<K: PreparedKind, R>(&mut self, f: impl FnOnce(&mut K::Counters) -> R) -> R {
        f(K::counters_in(self))
    }
}

/// The metaball counters as a tally: metaball queries count in full, other kinds add their
/// rays and hits only (as before kinds had counters of their own).
impl Tally for MetaballCounters {
    #[inline]
    fn count<K: PreparedKind, R>(&mut self, f: impl FnOnce(&mut K::Counters) -> R) -> R {
        let mut all = SceneCounters {
            metaballs: *self,
            ..SceneCounters::default()
        };
        let r = f(K::counters_in(&mut all));
        *self = all.metaballs;
        all.metaballs = MetaballCounters::default();
        let others = all.totals();
        self.rays += others.rays;
        self.hits += others.hits;
        r
    }
}

/// The queries, one `match` each, every arm the same generic call.
impl PreparedGeometry {
    pub fn build_ms(&self) -> f64 {
        match self {
            PreparedGeometry::Metaballs(m) => build_ms(m.as_ref()),
            PreparedGeometry::Tets(t) => build_ms(t.as_ref()),
            PreparedGeometry::Surfels(s) => build_ms(s.as_ref()),
        }
    }

    #[inline]
    pub fn first_hit<C: Tally>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut C,
    ) -> Option<Hit> {
        match self {
            PreparedGeometry::Metaballs(m) => {
                first_hit(m.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Tets(t) => {
                first_hit(t.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Surfels(s) => {
                first_hit(s.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
        }
    }

    /// [`PreparedKind::first_hit_leaving`] of the kind.
    #[inline]
    pub fn first_hit_leaving<C: Tally>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut C,
    ) -> Option<Hit> {
        match self {
            PreparedGeometry::Metaballs(m) => {
                first_hit_leaving(m.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Tets(t) => {
                first_hit_leaving(t.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Surfels(s) => {
                first_hit_leaving(s.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
        }
    }

    /// [`PreparedGeometry::first_hit`] with its work counted nowhere.
    #[inline]
    pub fn first_hit_uncounted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
    ) -> Option<Hit> {
        match self {
            PreparedGeometry::Metaballs(m) => uncounted(m.as_ref(), ray, t_min, t_max, isovalue),
            PreparedGeometry::Tets(t) => uncounted(t.as_ref(), ray, t_min, t_max, isovalue),
            PreparedGeometry::Surfels(s) => uncounted(s.as_ref(), ray, t_min, t_max, isovalue),
        }
    }

    #[inline]
    pub fn any_hit<C: Tally>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut C,
    ) -> Option<f32> {
        match self {
            PreparedGeometry::Metaballs(m) => {
                any_hit(m.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Tets(t) => any_hit(t.as_ref(), ray, t_min, t_max, isovalue, counters),
            PreparedGeometry::Surfels(s) => {
                any_hit(s.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
        }
    }

    #[inline]
    pub fn exit_hit<C: Tally>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut C,
    ) -> Option<Hit> {
        match self {
            PreparedGeometry::Metaballs(m) => {
                exit_hit(m.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Tets(t) => {
                exit_hit(t.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Surfels(s) => {
                exit_hit(s.as_ref(), ray, t_min, t_max, isovalue, counters)
            }
        }
    }

    /// [`PreparedKind::occluded`] of the kind.
    #[inline]
    pub fn occluded<C: Tally>(
        &self,
        ray: &Ray,
        span: (f32, f32),
        isovalue: f32,
        start: RayStart,
        hint: &mut OcclusionHint,
        counters: &mut C,
    ) -> bool {
        let ask = (span, isovalue, start);
        match self {
            PreparedGeometry::Metaballs(m) => occluded(m.as_ref(), ray, ask, hint, counters),
            PreparedGeometry::Tets(t) => occluded(t.as_ref(), ray, ask, hint, counters),
            PreparedGeometry::Surfels(s) => occluded(s.as_ref(), ray, ask, hint, counters),
        }
    }

    /// [`settle`] of the kind: whether `root`, an any-hit root on `span`, blocks it.
    #[inline]
    pub fn settle<C: Tally>(
        &self,
        ray: &Ray,
        span: (f32, f32),
        isovalue: f32,
        root: Option<f32>,
        counters: &mut C,
    ) -> bool {
        match self {
            PreparedGeometry::Metaballs(m) => {
                settle_in(m.as_ref(), ray, span, isovalue, root, counters)
            }
            PreparedGeometry::Tets(t) => settle_in(t.as_ref(), ray, span, isovalue, root, counters),
            PreparedGeometry::Surfels(s) => {
                settle_in(s.as_ref(), ray, span, isovalue, root, counters)
            }
        }
    }

    /// [`PreparedKind::crossings`] of the kind.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn crossings<C: Tally>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        out: &mut Vec<Hit>,
        counters: &mut C,
    ) {
        let span = (t_min, t_max, isovalue, inside, max);
        match self {
            PreparedGeometry::Metaballs(m) => crossings(m.as_ref(), ray, span, out, counters),
            PreparedGeometry::Tets(t) => crossings(t.as_ref(), ray, span, out, counters),
            PreparedGeometry::Surfels(s) => crossings(s.as_ref(), ray, span, out, counters),
        }
    }

    /// [`PreparedKind::crossing_count`] of the kind.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn crossing_count<C: Tally>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        counters: &mut C,
    ) -> usize {
        let span = (t_min, t_max, isovalue, inside, max);
        match self {
            PreparedGeometry::Metaballs(m) => crossing_count(m.as_ref(), ray, span, counters),
            PreparedGeometry::Tets(t) => crossing_count(t.as_ref(), ray, span, counters),
            PreparedGeometry::Surfels(s) => crossing_count(s.as_ref(), ray, span, counters),
        }
    }

    #[inline]
    pub fn optical_depth(&self, ray: &Ray, t_min: f32, t_max: f32) -> f32 {
        match self {
            PreparedGeometry::Metaballs(m) => optical_depth(m.as_ref(), ray, t_min, t_max),
            PreparedGeometry::Tets(t) => optical_depth(t.as_ref(), ray, t_min, t_max),
            PreparedGeometry::Surfels(s) => optical_depth(s.as_ref(), ray, t_min, t_max),
        }
    }

    pub fn primary_tile<C: Tally>(
        &self,
        rays: &PrimaryRays,
        rect: (u32, u32, u32, u32),
        isovalue: f32,
        t_max: f32,
        counters: &mut C,
    ) -> Vec<(Ray, Option<Hit>)> {
        match self {
            PreparedGeometry::Metaballs(m) => {
                primary_tile(m.as_ref(), rays, rect, isovalue, t_max, counters)
            }
            PreparedGeometry::Tets(t) => {
                primary_tile(t.as_ref(), rays, rect, isovalue, t_max, counters)
            }
            PreparedGeometry::Surfels(s) => {
                primary_tile(s.as_ref(), rays, rect, isovalue, t_max, counters)
            }
        }
    }

    /// [`PreparedKind::any_hits_towards`] of the kind.
    #[allow(clippy::too_many_arguments)]
    pub fn any_hits_towards<C: Tally>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        light: Option<Vec3>,
        isovalue: f32,
        starts: &[RayStart],
        hint: &mut OcclusionHint,
        counters: &mut C,
    ) -> Option<Vec<Option<f32>>> {
        let ask = (rays, t_min, t_max, light, isovalue, starts);
        match self {
            PreparedGeometry::Metaballs(m) => any_hits_towards(m.as_ref(), ask, hint, counters),
            PreparedGeometry::Tets(t) => any_hits_towards(t.as_ref(), ask, hint, counters),
            PreparedGeometry::Surfels(s) => any_hits_towards(s.as_ref(), ask, hint, counters),
        }
    }
}

fn build_ms<K: PreparedKind>(k: &K) -> f64 {
    k.build_ms()
}

#[inline]
fn optical_depth<K: PreparedKind>(k: &K, ray: &Ray, t_min: f32, t_max: f32) -> f32 {
    k.optical_depth(ray, t_min, t_max)
}

#[inline]
fn first_hit<K: PreparedKind, C: Tally>(
    k: &K,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
    counters: &mut C,
) -> Option<Hit> {
    counters.count::<K, _>(|c| k.first_hit(ray, t_min, t_max, isovalue, c))
}

#[inline]
fn first_hit_leaving<K: PreparedKind, C: Tally>(
    k: &K,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
    counters: &mut C,
) -> Option<Hit> {
    counters.count::<K, _>(|c| k.first_hit_leaving(ray, t_min, t_max, isovalue, c))
}

#[inline]
fn uncounted<K: PreparedKind>(
    k: &K,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
) -> Option<Hit> {
    let mut c = K::Counters::default();
    k.first_hit(ray, t_min, t_max, isovalue, &mut c)
}

#[inline]
fn any_hit<K: PreparedKind, C: Tally>(
    k: &K,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
    counters: &mut C,
) -> Option<f32> {
    counters.count::<K, _>(|c| k.any_hit(ray, t_min, t_max, isovalue, c))
}

#[inline]
fn occluded<K: PreparedKind, C: Tally>(
    k: &K,
    ray: &Ray,
    (span, isovalue, start): ((f32, f32), f32, RayStart),
    hint: &mut OcclusionHint,
    counters: &mut C,
) -> bool {
    counters.count::<K, _>(|c| k.occluded(ray, span, isovalue, start, hint, c))
}

#[inline]
fn settle_in<K: PreparedKind, C: Tally>(
    k: &K,
    ray: &Ray,
    span: (f32, f32),
    isovalue: f32,
    root: Option<f32>,
    counters: &mut C,
) -> bool {
    counters.count::<K, _>(|c| settle(k, ray, span, isovalue, root, c))
}

#[inline]
fn exit_hit<K: PreparedKind, C: Tally>(
    k: &K,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
    counters: &mut C,
) -> Option<Hit> {
    counters.count::<K, _>(|c| k.exit_hit(ray, t_min, t_max, isovalue, c))
}

#[inline]
fn crossings<K: PreparedKind, C: Tally>(
    k: &K,
    ray: &Ray,
    (t_min, t_max, isovalue, inside, max): (f32, f32, f32, bool, usize),
    out: &mut Vec<Hit>,
    counters: &mut C,
) {
    counters.count::<K, _>(|c| k.crossings(ray, t_min, t_max, isovalue, inside, max, out, c))
}

#[inline]
fn crossing_count<K: PreparedKind, C: Tally>(
    k: &K,
    ray: &Ray,
    (t_min, t_max, isovalue, inside, max): (f32, f32, f32, bool, usize),
    counters: &mut C,
) -> usize {
    counters.count::<K, _>(|c| k.crossing_count(ray, t_min, t_max, isovalue, inside, max, c))
}

fn primary_tile<K: PreparedKind, C: Tally>(
    k: &K,
    rays: &PrimaryRays,
    rect: (u32, u32, u32, u32),
    isovalue: f32,
    t_max: f32,
    counters: &mut C,
) -> Vec<(Ray, Option<Hit>)> {
    counters.count::<K, _>(|c| k.primary_tile(rays, rect, isovalue, t_max, c))
}

/// The shadow rays of [`PreparedGeometry::any_hits_towards`]: rays, `t_min`, each `t_max`,
/// the light, the isovalue and where each ray starts.
type ShadowPacket<'a> = (&'a [Ray], f32, &'a [f32], Option<Vec3>, f32, &'a [RayStart]);

fn any_hits_towards<K: PreparedKind, C: Tally>(
    k: &K,
    (rays, t_min, t_max, light, isovalue, starts): ShadowPacket<'_>,
    hint: &mut OcclusionHint,
    counters: &mut C,
) -> Option<Vec<Option<f32>>> {
    counters
        .count::<K, _>(|c| k.any_hits_towards(rays, t_min, t_max, light, isovalue, starts, hint, c))
}
