//! The counters of every kind, side by side: what a tile or a frame of mixed queries adds up.

use crate::geom::counters::{KindCounters, RayTotals};
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::surfels::counters::SurfelCounters;
use crate::kinds::tets::counters::TetCounters;

/// Each kind's own counters. A new kind adds its field here (and to the two sums below).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SceneCounters {
    pub metaballs: MetaballCounters,
    pub tets: TetCounters,
    pub surfels: SurfelCounters,
}

impl SceneCounters {
    pub fn add(&mut self, o: &SceneCounters) {
        self.metaballs.add(&o.metaballs);
        self.tets.add(&o.tets);
        self.surfels.add(&o.surfels);
    }

    /// The frame summary: every kind's totals added.
    pub fn totals(&self) -> RayTotals {
        let mut t = self.metaballs.totals();
        t.add(&self.tets.totals());
        t.add(&self.surfels.totals());
        t
    }
}
