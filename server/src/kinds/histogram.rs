//! What every kind's histogram of its scalar field gives back (`GET .../histogram`, drawn
//! behind the isovalue slider), and the binning they share. Each kind samples its own field:
//! `metaballs::histogram` on a grid, `tets::histogram` at the mesh's vertices.

/// The field's values, binned.
#[derive(Clone, Debug, PartialEq)]
pub struct Histogram {
    pub counts: Vec<u64>,
    pub below: u64,
    pub above: u64,
    pub samples: u64,
    pub grid: [u32; 3],
    /// Values computed: (ball, grid point) pairs for metaballs, vertices for tets.
    pub evaluations: u64,
}

impl Histogram {
    /// No samples yet, in `bins` bins.
    pub fn empty(bins: usize) -> Histogram {
        Histogram {
            counts: vec![0; bins],
            below: 0,
            above: 0,
            samples: 0,
            grid: [0; 3],
            evaluations: 0,
        }
    }

    /// Counts `values` into the bins over `[lo, hi)`, those outside into `below` and `above`.
    pub fn add(&mut self, values: impl Iterator<Item = f32>, lo: f32, hi: f32) {
        let bins = self.counts.len();
        let width = (hi - lo) / bins as f32;
        for v in values {
            self.samples += 1;
            if v < lo {
                self.below += 1;
            } else if v >= hi {
                self.above += 1;
            } else {
                let bin = (((v - lo) / width) as usize).min(bins - 1);
                self.counts[bin] += 1;
            }
        }
    }
}
