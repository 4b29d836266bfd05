//! The metaball kind's own ray counters.

use crate::geom::counters::{KindCounters, RayTotals};

/// The metaball kind's ray counters (fitted-bvh-metaballs.txt Table 3, plus root-finder
/// iterations).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MetaballCounters {
    pub rays: u64,
    pub hits: u64,
    pub node_traversals: u64,
    pub leaf_tests: u64,
    pub metaballs_considered: u64,
    pub iterations: u64,
    /// Iterations of the searches that produced the hits.
    pub hit_iterations: u64,
    /// Searches that stopped at their iteration cap (`roots::ITERATION_CAP`, or the secant
    /// method's 200): a miss or a hit that may be wrong rather than a silent one.
    pub capped: u64,
}

impl MetaballCounters {
    pub fn add(&mut self, o: &MetaballCounters) {
        self.rays += o.rays;
        self.hits += o.hits;
        self.node_traversals += o.node_traversals;
        self.leaf_tests += o.leaf_tests;
        self.metaballs_considered += o.metaballs_considered;
        self.iterations += o.iterations;
        self.hit_iterations += o.hit_iterations;
        self.capped += o.capped;
    }
}

impl KindCounters for MetaballCounters {
    fn add(&mut self, o: &MetaballCounters) {
        MetaballCounters::add(self, o);
    }

    fn totals(&self) -> RayTotals {
        RayTotals {
            rays: self.rays,
            hits: self.hits,
            iterations: self.iterations,
        }
    }
}
