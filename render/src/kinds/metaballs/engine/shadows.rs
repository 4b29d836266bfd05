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

use super::queries::search_gathered;
use super::soa::LeafSpheres;
use super::{Accel, PreparedMetaballs, SCRATCH};
use crate::geom::aabb::Aabb;
use crate::kinds::contract::OcclusionHint;
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::tree::{Tree, TreeKind};
use crate::ray::Ray;
use glam::Vec3;

/// Rays of a packet that must search a leaf before its balls are culled against the packet's
/// cone (fewer pay more for the culling than it saves them).
const CULL_FROM_RAYS: usize = 4;

/// The widest spread of a shadow packet's start points, in mean ball radii, that is still
/// traced as a packet ([`PreparedMetaballs::shadow_packet_pays`]). Measured on the paper's
/// scenes at 1920×1080 (packets of one 16×16 tile's hits binned by spread, each bin traced
/// both ways): packets win below about 8 radii on every scene (Pool 1.5–1.7×, Scattered-30k
/// 1.3–1.6×, Tornado-128k 1.1×), are even at 8–16 (Tornado 0.93×, the others 1.1×) and lose
/// beyond 16 (Scattered-30k 0.84–1.0×, Tornado-128k 0.87–0.89×). Since single rays walk the
/// tree four boxes at a time ([`crate::kinds::metaballs::tree::Wide`]) they are 2–16% faster,
/// and the 8–16 bin went over to them: at 16 Tornado-128k's hard shadows at 1920×1080 took
/// 162–164 ms against 148–150 ms for single rays alone; at 8, 149–153 ms, with Pool and
/// Molecule's packets unchanged (2, 4, 6, 8 and 16 compared in two rounds).
const SPREAD_RADII: f32 = 8.0;

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

/// A packet of parallel segments `A_i + s·d`, `s ∈ [0, s_max]` (shadow rays towards a
/// directional light): the per-axis ranges of the starts `A_i`.
struct Parallel {
    dir: [f32; 3],
    inv_dir: [f32; 3],
    lo: [f32; 3],
    hi: [f32; 3],
    s_max: f32,
}

impl Parallel {
    /// Whether no segment can meet `b` (conservative): per axis, the `s` at which some start
    /// moved by `s·d` lies in the box's slab, intersected over the axes and `[0, s_max]`.
    #[inline]
    fn misses(&self, b: &Aabb) -> bool {
        let (bmin, bmax) = (b.min.to_array(), b.max.to_array());
        let (mut s_lo, mut s_hi) = (0.0f32, self.s_max);
        for k in 0..3 {
            let (d, inv) = (self.dir[k], self.inv_dir[k]);
            let (enter, leave) = (bmin[k] - self.hi[k], bmax[k] - self.lo[k]);
            if d > 0.0 {
                s_lo = s_lo.max(enter * inv);
                s_hi = s_hi.min(leave * inv);
            } else if d < 0.0 {
                s_lo = s_lo.max(leave * inv);
                s_hi = s_hi.min(enter * inv);
            } else if enter > 0.0 || leave < 0.0 {
                return true; // no start lies in the slab, and no segment moves along this axis
            }
        }
        // Slack far beyond rounding.
        s_lo > s_hi + 1e-4 * (1.0 + self.s_max)
    }
}

/// What a shadow packet culls by: the cone towards a point light, or parallel segments.
enum Beam {
    Cone(Cone),
    Parallel(Parallel),
}

impl Beam {
    #[inline]
    fn misses(&self, b: &Aabb) -> bool {
        match self {
            Beam::Cone(c) => c.misses(b),
            Beam::Parallel(p) => p.misses(b),
        }
    }

    /// The beam of `rays` from `t_min` to each `t_max`: the cone from `light`, or with no
    /// light the parallel segments (every ray must then share one direction); `None` when the
    /// rays give no finite beam.
    fn new(rays: &[Ray], t_min: f32, t_max: &[f32], light: Option<Vec3>) -> Option<Beam> {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        let from = |r: &Ray| match light {
            Some(l) => r.at(t_min) - l,
            None => r.at(t_min),
        };
        for r in rays {
            for (k, v) in from(r).to_array().into_iter().enumerate() {
                lo[k] = lo[k].min(v);
                hi[k] = hi[k].max(v);
            }
        }
        if !(lo.iter().chain(&hi).all(|v| v.is_finite())) {
            return None;
        }
        let recip = |v: [f32; 3]| v.map(|x| 1.0 / x);
        match light {
            Some(l) => Some(Beam::Cone(Cone {
                light: l.to_array(),
                lo,
                hi,
                inv_lo: recip(lo),
                inv_hi: recip(hi),
            })),
            None => {
                let dir = rays.first()?.dir;
                if rays.iter().any(|r| r.dir != dir) {
                    return None;
                }
                let s_max = t_max.iter().fold(0.0f32, |m, &t| m.max(t - t_min));
                if !s_max.is_finite() {
                    return None;
                }
                Some(Beam::Parallel(Parallel {
                    dir: dir.to_array(),
                    inv_dir: recip(dir.to_array()),
                    lo,
                    hi,
                    s_max,
                }))
            }
        }
    }
}

impl PreparedMetaballs {
    /// Whether shadow rays starting at `t_min` along `rays` are coherent enough to gain from
    /// a packet: their start points lie within a box whose diagonal is at most
    /// [`SPREAD_RADII`] mean ball radii. Rays from far-apart surfaces (neighbouring pixels on
    /// different balls at different depths) share few nodes, and the packet's per-node tests
    /// cost more than they save; single rays give the same answers.
    pub fn shadow_packet_pays(&self, rays: &[Ray], t_min: f32) -> bool {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for r in rays {
            let p = r.at(t_min);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        (hi - lo).length() <= SPREAD_RADII * self.mean_radius
    }

    /// For each `rays[i]` (unit directions towards `light`, `t_max[i]` at most the distance
    /// to it; with no light, one direction shared by every ray, towards a directional light)
    /// what [`PreparedMetaballs::any_hit_counted`] returns on `[t_min, t_max[i]]`,
    /// the rays traced as one packet; `None` where packets do not apply, and the caller
    /// traces single rays.
    pub fn any_hits_packet(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        light: Option<Vec3>,
        isovalue: f32,
        counters: &mut MetaballCounters,
    ) -> Option<Vec<Option<f32>>> {
        let tree = self.shadow_packet_tree(rays.len(), t_min, t_max, isovalue)?;
        self.packet_roots(tree, (rays, t_min, t_max), light, isovalue, None, counters)
    }

    /// [`PreparedMetaballs::any_hits_packet`] with the caller's occlusion hint: a ray that
    /// one of the hint's witnesses (`occlusion`) shows blocked gets a point of its segment
    /// inside the solid instead of a root, which [`settle`](crate::kinds::contract::settle)
    /// answers as it answers the root (blocked: the segment ends outside the tree's box), and
    /// is left out of the packet; the packet's roots leave witnesses for the next rays.
    pub fn any_hits_packet_hinted(
        &self,
        (rays, t_min, t_max, light): (&[Ray], f32, &[f32], Option<Vec3>),
        isovalue: f32,
        hint: &mut OcclusionHint,
        counters: &mut MetaballCounters,
    ) -> Option<Vec<Option<f32>>> {
        let tree = self.shadow_packet_tree(rays.len(), t_min, t_max, isovalue)?;
        if tree.kind != TreeKind::Fitted || !self.terms_positive {
            return self.packet_roots(tree, (rays, t_min, t_max), light, isovalue, None, counters);
        }
        self.own_hint(hint, isovalue);
        let mut found: Vec<Option<f32>> = vec![None; rays.len()];
        let mut rest: Vec<usize> = Vec::with_capacity(rays.len());
        for (r, ray) in rays.iter().enumerate() {
            let span = (t_min, t_max[r]);
            match self.witness_point(tree, ray, span, hint) {
                Some(t) => found[r] = Some(t),
                None => rest.push(r),
            }
        }
        counters.rays += (rays.len() - rest.len()) as u64;
        counters.hits += (rays.len() - rest.len()) as u64;
        if rest.is_empty() {
            return Some(found);
        }
        let (rest_rays, rest_max): (Vec<Ray>, Vec<f32>) =
            rest.iter().map(|&r| (rays[r], t_max[r])).unzip();
        let packet = (&rest_rays[..], t_min, &rest_max[..]);
        let roots = self.packet_roots(tree, packet, light, isovalue, Some(hint), counters)?;
        for (&r, root) in rest.iter().zip(roots) {
            found[r] = root;
        }
        Some(found)
    }

    /// The tree a shadow packet of `n` rays walks, where packets apply (packets on, a nested
    /// tree, the main one for this isovalue, valid arguments).
    fn shadow_packet_tree(
        &self,
        n: usize,
        t_min: f32,
        t_max: &[f32],
        isovalue: f32,
    ) -> Option<&Tree> {
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
        match accel {
            Accel::Tree(tree) => Some(tree),
            Accel::BruteForce | Accel::ActiveList => None,
        }
    }

    /// The packet's roots ([`PreparedMetaballs::any_hits_packet`]), each root found leaving
    /// a witness in `learn` where there is one.
    #[allow(clippy::too_many_arguments)]
    fn packet_roots(
        &self,
        tree: &Tree,
        (rays, t_min, t_max): (&[Ray], f32, &[f32]),
        light: Option<Vec3>,
        isovalue: f32,
        mut learn: Option<&mut OcclusionHint>,
        counters: &mut MetaballCounters,
    ) -> Option<Vec<Option<f32>>> {
        let n = rays.len();
        let cone = Beam::new(rays, t_min, t_max, light)?;
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
            let mut soa = LeafSpheres::default();
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
                    // Several rays: the balls as structure-of-arrays, gathered in one vector loop.
                    let spheres = searching.len() >= 2 && soa.load(&self.balls, balls);
                    for &(r, (near, far)) in searching.iter() {
                        let ray = &rays[r];
                        let found = if spheres {
                            gathered.clear();
                            soa.gather(&self.balls, ray.origin, ray.dir, near, far, gathered);
                            search_gathered(&params, finder, near, far, gathered, scratch, counters)
                        } else {
                            self.search_leaf(
                                balls,
                                balls.len(),
                                ray,
                                near,
                                far,
                                &params,
                                finder,
                                gathered,
                                scratch,
                                counters,
                            )
                        };
                        if let Some(t) = found {
                            best[r] = Some((near, t));
                            if let Some(hint) = learn.as_deref_mut() {
                                let span = (t_min, t_max[r]);
                                self.learn_witness(tree, ray, span, gathered, isovalue, hint);
                            }
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
