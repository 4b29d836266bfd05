//! Packet traversal of the Fitted BVH for shadow rays towards one point light.
//!
//! How it works: the rays of a packet start at different surface points and end near one
//! light, so they share no origin; their segments lie in the cone from the light `L` through
//! the segments' start points `A_i`: `L + s·(A_i − L)`, `s ∈ [0, 1]`.
//! 1. Interval culling (Reshetov et al.'s interval arithmetic): per axis the range of
//!    `A_i − L` over the packet bounds the `s` for which a segment can lie in a box's slab;
//!    a node whose three ranges do not meet within `[0, 1]` is skipped for the whole packet.
//! 2. First and last active ray: as for primary packets ([`super::packet`]), rays are
//!    slab-tested in turn from the front until one meets the node (and enters it before the
//!    leaf of its best root), and from the back likewise; the rays outside the two are
//!    inactive below.
//! 3. Leaves: with at least [`CULL_FROM_RAYS`] rays to search, the leaf's balls whose box
//!    the packet's cone misses (the test of 1) are dropped once for all of them, since each
//!    ray would have gathered none of them; then each active ray's own slab range and the
//!    single-ray leaf search over the remaining balls, in the leaf's order. A ray's answer
//!    is the root of the leaf it enters first among the leaves with a root — what the
//!    single-ray walk returns, since a ray crosses disjoint leaves in the order of their
//!    entries — so a ray stays active after a root, but only for boxes it enters before that leaf.

use super::{Accel, PreparedMetaballs, SCRATCH};
use crate::geom::aabb::Aabb;
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::ray::Ray;
use glam::Vec3;

/// Rays of a packet that must search a leaf before its balls are culled against the packet's
/// cone (fewer pay more for the culling than it saves them).
const CULL_FROM_RAYS: usize = 4;

/// The per-axis ranges of `A_i − L` of a packet.
struct Cone {
    light: [f32; 3],
    lo: [f32; 3],
    hi: [f32; 3],
    /// `1 / lo` and `1 / hi` (a product is within an ulp of the quotient; the slack of
    /// [`Cone::misses`] is far wider).
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
}

impl Cone {
    /// Whether no segment `L + s·(A_i − L)`, `s ∈ [0, 1]`, can meet `b` (conservative).
    #[inline]
    fn misses(&self, b: &Aabb) -> bool {
        let (bmin, bmax) = (b.min.to_array(), b.max.to_array());
        let (mut s_lo, mut s_hi) = (0.0f32, 1.0f32);
        for k in 0..3 {
            let (a, c) = (bmin[k] - self.light[k], bmax[k] - self.light[k]);
            let (dlo, dhi) = (self.lo[k], self.hi[k]);
            let (ilo, ihi) = (self.inv_lo[k], self.inv_hi[k]);
            if dlo > 0.0 {
                s_lo = s_lo.max((a * ilo).min(a * ihi));
                s_hi = s_hi.min((c * ilo).max(c * ihi));
            } else if dhi < 0.0 {
                s_lo = s_lo.max((c * ilo).min(c * ihi));
                s_hi = s_hi.min((a * ilo).max(a * ihi));
            } else if (a > 0.0 && dhi <= 0.0) || (c < 0.0 && dlo >= 0.0) {
                return true; // the slab lies on the side no direction goes to
            }
        }
        // Slack far beyond rounding.
        s_lo > s_hi + 1e-4
    }
}

impl PreparedMetaballs {
    /// For each `rays[i]` (unit directions towards `light`, `t_max[i]` at most the distance
    /// to it) what [`PreparedMetaballs::any_hit_counted`] returns on `[t_min, t_max[i]]`,
    /// the rays traced as one packet; `None` where packets do not apply, and the caller
    /// traces single rays.
    pub fn any_hits_packet(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        light: Vec3,
        isovalue: f32,
        counters: &mut MetaballCounters,
    ) -> Option<Vec<Option<f32>>> {
        let n = rays.len();
        if !self.options.packets || !self.nested || n == 0 || t_max.len() != n {
            return None;
        }
        if !(isovalue > 0.0) || !isovalue.is_finite() || !t_min.is_finite() {
            return None;
        }
        let accel = self.accel_for(isovalue);
        if !std::ptr::eq(accel, &self.accel) {
            return None;
        }
        let tree = match accel {
            Accel::Tree(tree) => tree,
            Accel::BruteForce | Accel::ActiveList => return None,
        };
        let mut cone = Cone {
            light: light.to_array(),
            lo: [f32::INFINITY; 3],
            hi: [f32::NEG_INFINITY; 3],
            inv_lo: [0.0; 3],
            inv_hi: [0.0; 3],
        };
        for r in rays {
            let d = (r.at(t_min) - light).to_array();
            for (k, v) in d.into_iter().enumerate() {
                cone.lo[k] = cone.lo[k].min(v);
                cone.hi[k] = cone.hi[k].max(v);
            }
        }
        if !(cone.lo.iter().chain(&cone.hi).all(|v| v.is_finite())) {
            return None;
        }
        for k in 0..3 {
            cone.inv_lo[k] = 1.0 / cone.lo[k];
            cone.inv_hi[k] = 1.0 / cone.hi[k];
        }
        let inv: Vec<Vec3> = rays.iter().map(|r| r.dir.recip()).collect();
        let params = self.params(isovalue);
        let finder = self.options.finder;
        // Per ray: the entry of the leaf of its best root, and the root.
        let mut best: Vec<Option<(f32, f32)>> = vec![None; n];
        counters.rays += n as u64;
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (gathered, scratch, _) = &mut *guard;
            // The ray's range in a box, if the box starts before the leaf of its best root.
            let range = |b: &Aabb, r: usize, best: &[Option<(f32, f32)>]| {
                if !(t_min < t_max[r]) {
                    return None;
                }
                let (near, far) = b.ray_range(rays[r].origin, inv[r], t_min, t_max[r])?;
                match best[r] {
                    Some((entry, _)) if near >= entry => None,
                    _ => Some((near, far)),
                }
            };
            let mut stack: Vec<(u32, u32, u32)> = vec![(0, 0, n as u32)];
            let mut culled: Vec<u32> = Vec::new();
            let mut searching: Vec<(usize, (f32, f32))> = Vec::new();
            while let Some((i, from, to)) = stack.pop() {
                let (from, to) = (from as usize, to as usize);
                let node = &tree.nodes[i as usize];
                if (node.is_leaf() && node.count == 0) || cone.misses(&node.bounds) {
                    continue;
                }
                counters.node_traversals += 1;
                if node.is_leaf() {
                    searching.clear();
                    searching.extend(
                        (from..to).filter_map(|r| Some((r, range(&node.bounds, r, &best)?))),
                    );
                    // With several rays to search, the leaf's balls less those whose box no
                    // segment of the packet meets (the list single rays gather from, less
                    // balls each of them misses).
                    let leaf = tree.leaf_balls(node);
                    let balls = if searching.len() >= CULL_FROM_RAYS {
                        culled.clear();
                        culled.extend(leaf.iter().copied().filter(|&b| {
                            let ball = &self.balls[b as usize];
                            let r = Vec3::splat(1.0 / ball.inv_r);
                            !cone.misses(&Aabb {
                                min: ball.center - r,
                                max: ball.center + r,
                            })
                        }));
                        &culled[..]
                    } else {
                        leaf
                    };
                    for &(r, (near, far)) in searching.iter() {
                        let found = self.search_leaf(
                            balls,
                            balls.len(),
                            &rays[r],
                            near,
                            far,
                            &params,
                            finder,
                            gathered,
                            scratch,
                            counters,
                        );
                        if let Some(t) = found {
                            best[r] = Some((near, t));
                        }
                    }
                    continue;
                }
                // The first and the last active ray: the rays outside them miss the box.
                let active = |r: &usize| range(&node.bounds, *r, &best).is_some();
                let Some(fa) = (from..to).find(active) else {
                    continue;
                };
                let la = (fa..to).rfind(active).unwrap_or(fa);
                let c = node.first;
                let span = (fa as u32, la as u32 + 1);
                stack.push((c + 1, span.0, span.1));
                stack.push((c, span.0, span.1));
            }
        });
        let hits: Vec<Option<f32>> = best.into_iter().map(|b| b.map(|(_, t)| t)).collect();
        counters.hits += hits.iter().filter(|h| h.is_some()).count() as u64;
        Some(hits)
    }
}
