//! The contract every primitive kind's prepared state meets: the queries the integrator and
//! the effects make of a scene, answered per kind with the kind's own counters.
//!
//! Dispatch is static: [`crate::kinds::dispatch`] matches the closed
//! [`PreparedGeometry`](crate::kinds::dispatch::PreparedGeometry) once per query and calls a
//! generic function instantiated per kind, so the per-ray path stays monomorphic (no `dyn`).

use crate::camera::PrimaryRays;
use crate::geom::counters::KindCounters;
use crate::kinds::counters::SceneCounters;
use crate::ray::{Hit, Ray};

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
}
