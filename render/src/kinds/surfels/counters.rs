//! The surfel kind's own ray counters (what deforming-point-sampled-surfaces.txt §4.1.4,
//! §4.2.2 and §5 count: sphere tests, surface intersections, lazy updates).

use crate::geom::counters::{KindCounters, RayTotals};

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfelCounters {
    pub rays: u64,
    pub hits: u64,
    /// Ray–sphere tests of hierarchy nodes (leaves included).
    pub sphere_tests: u64,
    /// Ray–surfel intersections started (ellipse + MLS iteration of §4.2.1).
    pub surfel_tests: u64,
    /// MLS iterations.
    pub iterations: u64,
    /// Inner spheres updated by eqs. 4 and 9 during tracing (lazy only).
    pub node_updates: u64,
    /// Surfels deformed by eq. 1 during tracing (lazy only).
    pub surfel_updates: u64,
    /// Rays whose cached sphere node (§4.2.2) gave a hit.
    pub cache_hits: u64,
    /// Intersections rejected by a clipping surface (§4.3).
    pub clipped: u64,
    /// Intersections that ran out of MLS iterations without converging (a miss, counted).
    pub capped: u64,
    /// Camera rays whose nearest hit faced away from them, searched again for a crossing
    /// into the object before it (`PreparedSurfels::camera_nearest`).
    pub rescues: u64,
    /// Of `rays`, the any-hit (shadow and occlusion) queries, and their sphere + surfel
    /// tests: the rest are nearest-hit queries, the ones the cache of §4.2.2 serves.
    pub any_rays: u64,
    pub any_tests: u64,
}

impl KindCounters for SurfelCounters {
    fn add(&mut self, o: &SurfelCounters) {
        self.rays += o.rays;
        self.hits += o.hits;
        self.sphere_tests += o.sphere_tests;
        self.surfel_tests += o.surfel_tests;
        self.iterations += o.iterations;
        self.node_updates += o.node_updates;
        self.surfel_updates += o.surfel_updates;
        self.cache_hits += o.cache_hits;
        self.clipped += o.clipped;
        self.capped += o.capped;
        self.rescues += o.rescues;
        self.any_rays += o.any_rays;
        self.any_tests += o.any_tests;
    }

    fn totals(&self) -> RayTotals {
        RayTotals {
            rays: self.rays,
            hits: self.hits,
            iterations: self.iterations,
        }
    }
}
