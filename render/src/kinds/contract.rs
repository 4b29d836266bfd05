//! The contract every primitive kind's prepared state meets: the queries the integrator and
//! the effects make of a scene, answered per kind with the kind's own counters.
//!
//! Dispatch is static: [`crate::kinds::dispatch`] matches the closed
//! [`PreparedGeometry`](crate::kinds::dispatch::PreparedGeometry) once per query and calls a
//! generic function instantiated per kind, so the per-ray path stays monomorphic (no `dyn`).

use crate::camera::PrimaryRays;
use crate::geom::counters::KindCounters;
use crate::kinds::counters::SceneCounters;
use crate::ray::{surface_offset, Hit, Ray, INSIDE_EPS};
use glam::Vec3;

thread_local! {
    /// The hits [`PreparedKind::crossing_count`]'s default counts.
    static COUNTED: std::cell::Cell<Vec<Hit>> = const { std::cell::Cell::new(Vec::new()) };
}

/// Where a shadow or occlusion ray starts, as far as its caller knows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RayStart {
    /// Leaving the surface of this primitive's hit outwards, the hit having faced the ray
    /// that found it (seen from outside) and no clip box cutting the surfaces open: outside
    /// the body the primitive belongs to, so that if that body is closed the ray's first
    /// crossing of it, if any, faces the ray. A kind may skip what of that body faces away
    /// (surfels: [`crate::kinds::surfels::cones`]); other bodies may hold the start.
    Leaving(u32),
    /// Anywhere else, or not known.
    #[default]
    Unknown,
}

/// A prepared state of one primitive kind, ready to trace.
pub trait PreparedKind {
    /// The kind's own work counters.
    type Counters: KindCounters;

    /// This kind's counters among every kind's.
    fn counters_in(all: &mut SceneCounters) -> &mut Self::Counters;

    /// Milliseconds spent building what tracing needs (acceleration structure, shading data).
    fn build_ms(&self) -> f64;

    /// The first crossing of the isosurface along `ray` within `[t_min, t_max]`.
    fn first_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut Self::Counters,
    ) -> Option<Hit>;

    /// [`PreparedKind::first_hit`] for a ray that leaves the surface outwards from a start
    /// lifted off it (a mirror ray from outside the solid), whose first crossing is one into
    /// the solid: a kind whose surface near the start has more than one definition (surfels:
    /// each leaf's own neighbourhood) may pass over a crossing out there. By default the
    /// same query.
    fn first_hit_leaving(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut Self::Counters,
    ) -> Option<Hit> {
        self.first_hit(ray, t_min, t_max, isovalue, counters)
    }

    /// Some root of the isosurface on `[t_min, t_max]`, stopping at the first one found (not
    /// necessarily the nearest). A root at `t_min` means the segment starts inside the solid.
    fn any_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut Self::Counters,
    ) -> Option<f32>;

    /// From a start inside the solid, where the ray leaves it within `[t_min, t_max]`.
    fn exit_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut Self::Counters,
    ) -> Option<Hit>;

    /// The successive crossings of the isosurface along `ray` within `[t_min, t_max]`, in
    /// order, at most `max`, appended to `out` (transparency's depth peeling and shadow rays
    /// through transparent surfaces). `inside`: the ray is known to start inside the solid,
    /// so its first crossing is the way out; otherwise a root within [`INSIDE_EPS`] of the
    /// start means the start was inside, and is not a crossing. After each crossing the
    /// search goes on [`surface_offset`] past it, inside the solid if the crossing's normal
    /// faces the ray. What this default does with one query per crossing, a kind may do in
    /// one traversal (metaballs: [`PreparedMetaballs::crossings_counted`]).
    ///
    /// [`PreparedMetaballs::crossings_counted`]: crate::kinds::metaballs::engine::PreparedMetaballs::crossings_counted
    #[allow(clippy::too_many_arguments)]
    fn crossings(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        out: &mut Vec<Hit>,
        counters: &mut Self::Counters,
    ) {
        crossings_one_by_one(
            self, ray, t_min, t_max, isovalue, inside, max, out, counters,
        )
    }

    /// How many crossings [`PreparedKind::crossings`] finds, at most `max`, for callers that
    /// need only their number (shadow rays through surfaces of one opacity). A kind may count
    /// without shading them, and may count two crossings closer together than
    /// [`surface_offset`] that the walk with hits steps over as none. This default counts
    /// [`PreparedKind::crossings`]'s hits (in a per-thread list kept between calls).
    #[allow(clippy::too_many_arguments)]
    fn crossing_count(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        counters: &mut Self::Counters,
    ) -> usize {
        COUNTED.with(|cell| {
            // `take`: a kind's `crossings` that asked for a count itself would find it empty.
            let mut hits = cell.take();
            hits.clear();
            self.crossings(
                ray, t_min, t_max, isovalue, inside, max, &mut hits, counters,
            );
            let n = hits.len();
            cell.replace(hits);
            n
        })
    }

    /// Whether the isosurface blocks `[t_min, t_max]` of `ray`: [`settle`] of
    /// [`PreparedKind::any_hit`]'s root. `hint` is what this caller's earlier queries left
    /// (a tile's shadow rays, in order); a kind may search first where the last blocked ray
    /// was blocked, taking only a root that is a genuine crossing from outside the solid
    /// into it within the segment, where the full query answers "blocked" too. `start` is
    /// what the caller knows of where the ray starts ([`RayStart`]). This default ignores
    /// both.
    fn occluded(
        &self,
        ray: &Ray,
        (t_min, t_max): (f32, f32),
        isovalue: f32,
        start: RayStart,
        hint: &mut OcclusionHint,
        counters: &mut Self::Counters,
    ) -> bool {
        let _ = (hint, start);
        let root = self.any_hit(ray, t_min, t_max, isovalue, counters);
        settle(self, ray, (t_min, t_max), isovalue, root, counters)
    }

    /// `∫ density dt` over `[t_min, t_max]` (0 for a kind with no density).
    fn optical_depth(&self, ray: &Ray, t_min: f32, t_max: f32) -> f32;

    /// Each primary ray through pixels `x0..x1 × y0..y1` of `rays` (row by row) and its first
    /// hit in `[0, t_max]`, exactly as [`PreparedKind::first_hit`] finds it ray by ray; a kind
    /// may trace the tile as one packet.
    fn primary_tile(
        &self,
        rays: &PrimaryRays,
        rect: (u32, u32, u32, u32),
        isovalue: f32,
        t_max: f32,
        counters: &mut Self::Counters,
    ) -> Vec<(Ray, Option<Hit>)>;

    /// Shadow rays from surface points (unit directions towards `light`, a point light's
    /// position, or `None` for a directional light; `t_max[i]` at most the distance to it),
    /// traced together: for each ray, `Some` root on `[t_min, t_max[i]]` exactly when
    /// [`PreparedKind::any_hit`] finds one; a kind whose rays can start inside a solid (a root
    /// at `t_min`) returns `any_hit`'s own root, a kind of sheets (surfels, whose way out is
    /// any later hit) may return another, and a kind that shows a ray blocked by other means
    /// (a metaball witness, with the caller's `hint`) a point of its segment inside the
    /// solid, which [`settle`] answers as it answers the root. `starts[i]` is where ray `i`
    /// starts, as [`PreparedKind::occluded`] takes it (empty: not known for any). `None`
    /// where the kind has no packet for these rays (the caller asks ray by ray).
    #[allow(clippy::too_many_arguments)]
    fn any_hits_towards(
        &self,
        _rays: &[Ray],
        _t_min: f32,
        _t_max: &[f32],
        _light: Option<Vec3>,
        _isovalue: f32,
        _starts: &[RayStart],
        _hint: &mut OcclusionHint,
        _counters: &mut Self::Counters,
    ) -> Option<Vec<Option<f32>>> {
        None
    }
}

/// What one caller's occlusion queries leave for the next ([`PreparedKind::occluded`]):
/// where the latest blocked rays were blocked. Only the cost of a query depends on it, so a
/// tile's tracer owns one and the image does not depend on which thread traces the tile.
#[derive(Clone, Copy, Debug, Default)]
pub struct OcclusionHint {
    /// The prepared metaball state (its id) and the isovalue the leaves belong to.
    pub(crate) metaball_state: (u64, f32),
    /// The metaball leaves whose roots blocked the latest blocked rays, the latest first.
    pub(crate) metaball_leaves: [Option<crate::kinds::metaballs::tree::flat::Node>; HINT_LEAVES],
    /// Balls whose core (where the ball's term alone exceeds the isovalue) the latest blocked
    /// rays crossed, the latest first, each with the largest `s` inside its core.
    pub(crate) metaball_witnesses: [Option<(u32, f32)>; HINT_LEAVES],
    /// The last strength a witness was found for and the largest `s` inside its core.
    pub(crate) metaball_core: Option<(f32, Option<f32>)>,
}

/// How many leaves an [`OcclusionHint`] keeps. Single shadow rays at 1920×1080 answered by one
/// of the last 1, 2, 4, 8 or 16 blocking leaves: Scattered-30k 68, 73, 85, 91 and 92% of the
/// blocked ones, Tornado-128k 41, 44, 51, 72 and 80%; 8 was the fastest on both (performance
/// log).
pub const HINT_LEAVES: usize = 8;

/// Whether `[lo, hi]` of `ray` is blocked, given the any-hit query's `root` on it: a root past
/// the start blocks; one at the start means the ray starts inside the solid, and its boundary
/// blocks if the ray leaves it within the segment.
pub fn settle<K: PreparedKind + ?Sized>(
    kind: &K,
    ray: &Ray,
    (lo, hi): (f32, f32),
    isovalue: f32,
    root: Option<f32>,
    counters: &mut K::Counters,
) -> bool {
    match root {
        None => false,
        Some(t) if t > lo + INSIDE_EPS => true,
        Some(_) => kind.exit_hit(ray, lo, hi, isovalue, counters).is_some(),
    }
}

/// [`PreparedKind::crossings`] with one [`PreparedKind::first_hit`] or
/// [`PreparedKind::exit_hit`] query per crossing.
#[allow(clippy::too_many_arguments)]
pub fn crossings_one_by_one<K: PreparedKind + ?Sized>(
    kind: &K,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
    mut inside: bool,
    max: usize,
    out: &mut Vec<Hit>,
    counters: &mut K::Counters,
) {
    let mut t = t_min;
    let mut found = 0;
    while found < max && t < t_max {
        let hit = if inside {
            kind.exit_hit(ray, t, t_max, isovalue, counters)
        } else {
            match kind.first_hit(ray, t, t_max, isovalue, counters) {
                Some(h) if h.t > t + INSIDE_EPS => Some(h),
                Some(_) => kind.exit_hit(ray, t, t_max, isovalue, counters),
                None => None,
            }
        };
        let Some(hit) = hit else {
            return;
        };
        // A crossing against the outward normal enters the solid.
        inside = hit.normal.dot(ray.dir) < 0.0;
        t = hit.t + surface_offset(hit.position);
        out.push(hit);
        found += 1;
    }
}
