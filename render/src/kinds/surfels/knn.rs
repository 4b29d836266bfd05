//! The `k` nearest points of a fixed set, on a uniform grid: the fixed surfel neighbourhoods
//! of deforming-point-sampled-surfaces.txt §4.2.1, the surfel–node embedding of §3 and the
//! clipping neighbours of §4.3, all computed once in the undeformed system.
//!
//! How it works: points are bucketed into cubic cells (about four per cell); a query scans
//! shells of cells at growing Chebyshev distance until it holds `k` points and the next
//! shell cannot hold a nearer one. Ties go to the lower index, so results are deterministic.

use glam::Vec3;

/// A uniform grid over a point set.
pub struct Grid<'a> {
    points: &'a [Vec3],
    lo: Vec3,
    cell: f32,
    dims: [i32; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl<'a> Grid<'a> {
    pub fn new(points: &'a [Vec3]) -> Grid<'a> {
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for p in points {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        if points.is_empty() {
            lo = Vec3::ZERO;
            hi = Vec3::ONE;
        }
        let ext = (hi - lo).max(Vec3::splat(1e-6));
        let target = (points.len() as f64 / 4.0).max(1.0);
        // About four points a cell whether the set fills a volume, a surface or a line.
        let mut e = [ext.x as f64, ext.y as f64, ext.z as f64];
        e.sort_by(|a, b| b.total_cmp(a));
        let cell = (e[0] * e[1] * e[2] / target)
            .cbrt()
            .max((e[0] * e[1] / target).sqrt())
            .max(e[0] / target) as f32;
        let dims = [0, 1, 2].map(|a| ((ext[a] / cell) as i32 + 1).clamp(1, 1 << 10));
        let ncell = (dims[0] * dims[1] * dims[2]) as usize;
        let mut grid = Grid {
            points,
            lo,
            cell,
            dims,
            start: vec![0; ncell + 1],
            items: vec![0; points.len()],
        };
        let ids: Vec<usize> = points.iter().map(|p| grid.cell_index(*p)).collect();
        for &c in &ids {
            grid.start[c + 1] += 1;
        }
        for c in 0..ncell {
            grid.start[c + 1] += grid.start[c];
        }
        let mut fill = grid.start.clone();
        for (i, &c) in ids.iter().enumerate() {
            grid.items[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        grid
    }

    fn coords(&self, p: Vec3) -> [i32; 3] {
        let q = (p - self.lo) / self.cell;
        [0, 1, 2].map(|a| (q[a].floor() as i32).clamp(0, self.dims[a] - 1))
    }

    fn cell_index(&self, p: Vec3) -> usize {
        let c = self.coords(p);
        ((c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]) as usize
    }

    /// The `k` nearest points to `q` (fewer if the set is smaller), nearest first, as
    /// `(index, distance²)`; `skip` is left out (a point's own index).
    pub fn nearest(&self, q: Vec3, k: usize, skip: Option<u32>, out: &mut Vec<(u32, f32)>) {
        out.clear();
        if k == 0 {
            return;
        }
        let c = self.coords(q);
        // Past this ring every cell has been scanned.
        let max_ring = (0..3)
            .map(|a| c[a].max(self.dims[a] - 1 - c[a]))
            .max()
            .unwrap_or(0);
        let span = |a: usize, ring: i32| (c[a] - ring).max(0)..=(c[a] + ring).min(self.dims[a] - 1);
        for ring in 0..=max_ring {
            for z in span(2, ring) {
                for y in span(1, ring) {
                    let inner = (z - c[2]).abs() < ring && (y - c[1]).abs() < ring;
                    for x in span(0, ring) {
                        // Inside the shell's rows only its two end cells are new.
                        if inner && (x - c[0]).abs() < ring {
                            continue;
                        }
                        let id = ((z * self.dims[1] + y) * self.dims[0] + x) as usize;
                        let (s, e) = (self.start[id] as usize, self.start[id + 1] as usize);
                        for &i in &self.items[s..e] {
                            if Some(i) == skip {
                                continue;
                            }
                            let d2 = (self.points[i as usize] - q).length_squared();
                            insert(out, k, (i, d2));
                        }
                    }
                }
            }
            // Points of the next shell are at least `ring · cell` away (q is in its cell).
            let reach = ring as f32 * self.cell;
            if out.len() == k && out[k - 1].1 <= reach * reach {
                return;
            }
        }
    }
}

/// Inserts into the sorted list of the `k` best, ties to the lower index.
fn insert(out: &mut Vec<(u32, f32)>, k: usize, item: (u32, f32)) {
    let better = |a: &(u32, f32), b: &(u32, f32)| a.1 < b.1 || (a.1 == b.1 && a.0 < b.0);
    if out.len() == k && !better(&item, &out[k - 1]) {
        return;
    }
    let pos = out
        .iter()
        .position(|o| better(&item, o))
        .unwrap_or(out.len());
    out.insert(pos, item);
    out.truncate(k);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::rng::SplitMix64;

    #[test]
    fn matches_brute_force() {
        let mut rng = SplitMix64(3);
        let mut pts: Vec<Vec3> = (0..2000).map(|_| rng.in_unit_ball() * 5.0).collect();
        // A flat patch too.
        pts.extend((0..500).map(|i| Vec3::new((i % 25) as f32 * 0.1, (i / 25) as f32 * 0.1, 9.0)));
        let grid = Grid::new(&pts);
        let mut out = Vec::new();
        for qi in (0..pts.len()).step_by(37) {
            let q = pts[qi];
            grid.nearest(q, 16, Some(qi as u32), &mut out);
            let mut brute: Vec<(u32, f32)> = (0..pts.len() as u32)
                .filter(|&i| i as usize != qi)
                .map(|i| (i, (pts[i as usize] - q).length_squared()))
                .collect();
            brute.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            brute.truncate(16);
            assert_eq!(out, brute);
        }
    }
}
