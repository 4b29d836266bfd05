//! What every kind's ray counters have in common: the frame's summary of its queries.
//!
//! Each kind counts its own work in its own type (fitted-bvh-metaballs.txt Table 3 for
//! metaballs, tetrahedral-isosurface-ray-tracing.txt Table 4 for tets); [`KindCounters`] is
//! what the frame asks of all of them.

/// The summary of one frame's queries, whatever the kinds: rays asked, rays that hit, and
/// root-finder iterations (0 for kinds without an iterative root finder).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayTotals {
    pub rays: u64,
    pub hits: u64,
    pub iterations: u64,
}

impl RayTotals {
    pub fn add(&mut self, o: &RayTotals) {
        self.rays += o.rays;
        self.hits += o.hits;
        self.iterations += o.iterations;
    }
}

/// A kind's own work counters.
pub trait KindCounters: Copy + Default {
    /// Adds `o` to these counters.
    fn add(&mut self, o: &Self);
    /// The frame summary of these counters.
    fn totals(&self) -> RayTotals;
}
