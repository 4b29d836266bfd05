//! The tet kind's own ray counters.

use crate::geom::counters::{KindCounters, RayTotals};

/// Work counters (tetrahedral-isosurface-ray-tracing.txt Table 4 counts the same things).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TetCounters {
    pub rays: u64,
    pub hits: u64,
    /// Nodes popped and examined.
    pub nodes: u64,
    /// Individual ray–box slab tests.
    pub ray_box_tests: u64,
    /// Interval-arithmetic packet–box tests (packets only).
    pub frustum_box_tests: u64,
    /// Isorange tests of nodes (one per packet).
    pub isorange_tests: u64,
    /// Isopolygons extracted (one per packet, tet and isovalue).
    pub extractions: u64,
    /// Individual ray–isopolygon tests (a packet's corner-ray test counts as four).
    pub polygon_tests: u64,
    /// Isopolygons a whole packet missed by the corner-ray test.
    pub polygons_culled: u64,
    /// Isopolygons a whole packet hit by the corner-ray test (distances only).
    pub polygons_full: u64,
    /// Subtrees skipped as wholly inside the clip box.
    pub clipped_subtrees: u64,
}

impl TetCounters {
    pub fn add(&mut self, o: &TetCounters) {
        self.rays += o.rays;
        self.hits += o.hits;
        self.nodes += o.nodes;
        self.ray_box_tests += o.ray_box_tests;
        self.frustum_box_tests += o.frustum_box_tests;
        self.isorange_tests += o.isorange_tests;
        self.extractions += o.extractions;
        self.polygon_tests += o.polygon_tests;
        self.polygons_culled += o.polygons_culled;
        self.polygons_full += o.polygons_full;
        self.clipped_subtrees += o.clipped_subtrees;
    }
}

impl KindCounters for TetCounters {
    fn add(&mut self, o: &TetCounters) {
        TetCounters::add(self, o);
    }

    /// Tets have no iterative root finder: no iterations.
    fn totals(&self) -> RayTotals {
        RayTotals {
            rays: self.rays,
            hits: self.hits,
            iterations: 0,
        }
    }
}
