//! The binned SAH of fitted-bvh-metaballs.txt §5.1: where to split a node, with the
//! leaf cost counting the split balls each child will get.

use crate::geom::aabb::Aabb;
use crate::kinds::metaballs::tree::ctx::{Ctx, Prim, MAX_BINS};
use crate::kinds::metaballs::tree::flat::TreeKind;
use glam::Vec3;

/// What one side of a split plane holds, gathered while binning.
#[derive(Clone, Copy, Debug)]
pub(super) struct Side {
    /// Box of the side's own balls (radii `min(R, r_max)` with the parent's `r_max`, which
    /// is at least the child's: safe).
    pub(super) bounds: Aabb,
    pub(super) positive: u32,
    pub(super) max_radius: f32,
}

/// The best split of a node.
#[derive(Clone, Copy, Debug)]
pub(super) struct Choice {
    pub(super) axis: usize,
    pub(super) plane: f32,
    pub(super) cost: f32,
    pub(super) sides: [Side; 2],
}

/// One SAH bin, and the difference-array entries of the plane at its left edge.
#[derive(Clone, Copy, Debug)]
pub(super) struct Bin {
    pub(super) count: u32,
    pub(super) side: Side,
    pub(super) cross_left: i32,
    pub(super) cross_right: i32,
    pub(super) split_left: i32,
    pub(super) split_right: i32,
}

pub(super) const EMPTY_SIDE: Side = Side {
    bounds: Aabb::EMPTY,
    positive: 0,
    max_radius: 0.0,
};

pub(super) const EMPTY_BIN: Bin = Bin {
    count: 0,
    side: EMPTY_SIDE,
    cross_left: 0,
    cross_right: 0,
    split_left: 0,
    split_right: 0,
};

/// The binned SAH's arrays; a node clears only the bins it uses (small nodes use few, and
/// clearing sixteen of everything for every two-ball node was much of the build).
pub(super) struct Bins {
    pub(super) bins: [Bin; MAX_BINS + 1],
    pub(super) right: [(u32, Side); MAX_BINS],
}

impl Default for Bins {
    fn default() -> Bins {
        Bins {
            bins: [EMPTY_BIN; MAX_BINS + 1],
            right: [(0, EMPTY_SIDE); MAX_BINS],
        }
    }
}

impl Ctx {
    /// Binned SAH over the owned centroids along their longest axis (Wald 2007, as the
    /// paper). A child's ball count is its owned balls plus the split balls it will get: the
    /// parent's split balls that reach its side of the plane and the other side's owned balls
    /// whose spheres cross the plane (both counted along the axis only).
    pub(super) fn best_split(
        &self,
        owned: &[Prim],
        centroids: (Vec3, Vec3),
        split: &[u32],
        bounds: &Aabb,
        r_max: f32,
        scratch: &mut Bins,
    ) -> Option<Choice> {
        let (cmin, cmax) = centroids;
        let extent = cmax - cmin;
        let axis = extent.max_position();
        let (lo, hi) = (cmin[axis], cmax[axis]);
        if !(hi - lo > 1e-6 * (1.0 + hi.abs().max(lo.abs()))) {
            return None;
        }
        // Small nodes need few bins: two per ball separates every pair of centres' halves.
        let bins = self.opts.bins.min(2 * owned.len()).clamp(2, MAX_BINS);
        let scale = bins as f32 / (hi - lo);
        let top = (bins - 1) as f32;
        let bin = |x: f32| ((x - lo) * scale).max(0.0).min(top) as usize;
        let cap = self.radius_cap(r_max);
        let Bins { bins: table, right } = scratch;
        let table = &mut table[..=bins];
        table.fill(EMPTY_BIN);
        // `cross_*` and `split_*` are difference arrays over the plane index p (plane p lies
        // between bins p-1 and p).
        for p in owned {
            let c = p.center.to_array()[axis];
            let k = bin(c);
            let b = &mut table[k];
            b.count += 1;
            b.side.bounds = b
                .side
                .bounds
                .union(Aabb::around(p.center, p.radius.min(cap)));
            b.side.positive += (p.strength > 0.0) as u32;
            b.side.max_radius = b.side.max_radius.max(p.radius);
            // Reaches left of plane p for p in (bin(c - r), k]; right for p in (k, bin(c + r)].
            table[bin(c - p.radius) + 1].cross_left += 1;
            table[k + 1].cross_left -= 1;
            table[k + 1].cross_right += 1;
            table[bin(c + p.radius) + 1].cross_right -= 1;
        }
        for &i in split {
            let c = self.centers[i as usize].to_array()[axis];
            let r = self.radii[i as usize];
            // Goes left for p > bin(c - r), right for p ≤ bin(c + r).
            table[bin(c - r) + 1].split_left += 1;
            table[0].split_right += 1;
            table[bin(c + r) + 1].split_right -= 1;
        }
        let merge = |a: Side, b: Side| Side {
            bounds: a.bounds.union(b.bounds),
            positive: a.positive + b.positive,
            max_radius: a.max_radius.max(b.max_radius),
        };
        let mut acc = (0u32, EMPTY_SIDE);
        for k in (1..bins).rev() {
            acc = (acc.0 + table[k].count, merge(acc.1, table[k].side));
            right[k] = acc;
        }
        let parent_area = bounds.area().max(1e-20);
        let mut best: Option<Choice> = None;
        let mut left = (0u32, EMPTY_SIDE);
        let (mut xl, mut xr) = (0i32, 0i32);
        let (mut sl, mut sr) = (0i32, table[0].split_right);
        for p in 1..bins {
            left = (
                left.0 + table[p - 1].count,
                merge(left.1, table[p - 1].side),
            );
            xl += table[p].cross_left;
            xr += table[p].cross_right;
            sl += table[p].split_left;
            sr += table[p].split_right;
            let (nr_owned, rs) = right[p];
            if left.0 == 0 || nr_owned == 0 {
                continue;
            }
            let plane = lo + p as f32 / scale;
            let (al, ar) = match self.opts.kind {
                TreeKind::Bvh => (left.1.bounds.area(), rs.bounds.area()),
                TreeKind::Fitted => (
                    clipped_area(bounds, &left.1.bounds, axis, plane, true),
                    clipped_area(bounds, &rs.bounds, axis, plane, false),
                ),
            };
            let nl = (left.0 as i32 + xl + sl) as f32;
            let nr = (nr_owned as i32 + xr + sr) as f32;
            let cost = self.opts.traversal_cost
                + (al / parent_area) * self.leaf_cost(nl)
                + (ar / parent_area) * self.leaf_cost(nr);
            if best.is_none_or(|b| cost < b.cost) {
                best = Some(Choice {
                    axis,
                    plane,
                    cost,
                    sides: [left.1, rs],
                });
            }
        }
        best
    }

    /// Moves the balls with centres below `plane` to the front; returns how many there are
    /// and the bounds of each side's centres.
    pub(super) fn partition(
        owned: &mut [Prim],
        axis: usize,
        plane: f32,
    ) -> (usize, [(Vec3, Vec3); 2]) {
        let empty = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let mut sides = [empty; 2];
        let (mut i, mut j) = (0, owned.len());
        while i < j {
            let c = owned[i].center;
            let right = !(c.to_array()[axis] < plane);
            let s = &mut sides[usize::from(right)];
            s.0 = s.0.min(c);
            s.1 = s.1.max(c);
            if right {
                j -= 1;
                owned.swap(i, j);
            } else {
                i += 1;
            }
        }
        (i, sides)
    }
}

/// The area of `b ∩ half`, `half` the side of `parent` below (`left`) or above `plane`.
#[inline]
pub(super) fn clipped_area(parent: &Aabb, b: &Aabb, axis: usize, plane: f32, left: bool) -> f32 {
    let mut min = parent.min.max(b.min).to_array();
    let mut max = parent.max.min(b.max).to_array();
    if left {
        max[axis] = max[axis].min(plane);
    } else {
        min[axis] = min[axis].max(plane);
    }
    let d = [max[0] - min[0], max[1] - min[1], max[2] - min[2]];
    if d[0] < 0.0 || d[1] < 0.0 || d[2] < 0.0 {
        return 0.0;
    }
    2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
}

/// The box cut at `plane` along `axis`, the plane clamped into the box.
pub(super) fn split_box(b: &Aabb, axis: usize, plane: f32) -> (Aabb, Aabb) {
    let plane = plane.clamp(b.min[axis], b.max[axis]);
    let mut left = *b;
    let mut right = *b;
    left.max[axis] = plane;
    right.min[axis] = plane;
    (left, right)
}
