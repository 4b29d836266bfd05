//! The metaball kind's own ray counters, and the outcome of one root search they count.

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

/// The outcome of one search.
#[derive(Clone, Copy, Debug, Default)]
pub struct Found<R> {
    pub t: Option<R>,
    /// Iterations spent in total.
    pub iterations: u32,
    /// Iterations spent on the section or bracket that produced the hit.
    pub hit_iterations: u32,
    /// Whether a search stopped at its iteration cap (a miss or a coarse hit that may be wrong).
    pub capped: bool,
}

impl Found<f32> {
    /// Adds this leaf search over `balls` balls to `counters` (a leaf test, its balls, its
    /// iterations, a capped search, and the hit's iterations when it hit); the hit distance.
    #[inline]
    pub fn counted(self, counters: &mut MetaballCounters, balls: usize) -> Option<f32> {
        counters.leaf_tests += 1;
        counters.metaballs_considered += balls as u64;
        counters.iterations += self.iterations as u64;
        counters.capped += self.capped as u64;
        if self.t.is_some() {
            counters.hit_iterations += self.hit_iterations as u64;
        }
        self.t
    }
}
