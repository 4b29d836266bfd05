//! A packet leaf's balls as structure-of-arrays, for rays that share one origin.
//!
//! Every primary ray of a tile starts at the eye, so each sphere's `e = (o − p) / R` (the
//! origin in the ball's unit frame) is the same for all of them and is computed once per leaf
//! and packet. The quantities [`RayBall::along`] derives (`a = |g|²`, `tc = −e·g / a`,
//! `s_min = |e + tc g|²` with `g = d / R`) and the support's span are then computed for
//! [`RAY_LANES`] rays at once, ball by ball, in `wide`'s `f32x8`: across rays rather than
//! across balls, so that the leaves of few balls left after the packet's culling (most of
//! `scattered-1k`'s) fill the vector too. The operations and their order are those of
//! `PreparedMetaballs::gather` with `along`, in IEEE `f32` without contraction, so the
//! gathered balls are bit for bit the single ray's.

use crate::geom::tile::Frustum;
use crate::kinds::metaballs::kernel::KernelPoly;
use crate::kinds::metaballs::roots::RayBall;
use crate::kinds::metaballs::tree::Tree;
use crate::ray::Ray;
use glam::Vec3;
use rayon::prelude::*;
use wide::{f32x8, CmpGe, CmpGt, CmpLt};

/// The hot-path copy of one ball.
#[derive(Clone, Copy, Debug)]
pub(super) struct Ball {
    pub(super) center: Vec3,
    pub(super) inv_r: f32,
    pub(super) strength: f32,
    pub(super) lipschitz: f32,
    pub(super) min_radius: f32,
    /// Index into `frames` for an ellipsoid, `u32::MAX` for a sphere.
    pub(super) frame: u32,
}

impl Ball {
    /// This ball (index `i`) as a ray sees it, from what [`RayBall::along`] returns.
    #[inline]
    pub(super) fn seen(
        &self,
        i: u32,
        (t0, t1, a, tc, s_min): (f32, f32, f32, f32, f32),
        owner: bool,
    ) -> RayBall<f32> {
        RayBall {
            ball: i,
            t0,
            t1,
            a,
            tc,
            s_min,
            q: self.strength,
            lipschitz: self.lipschitz,
            min_radius: self.min_radius,
            owner,
        }
    }
}

/// The balls of one leaf for one shared origin (spheres only).
#[derive(Debug, Default)]
pub(super) struct SharedOriginBalls {
    ids: Vec<u32>,
    ex: Vec<f32>,
    ey: Vec<f32>,
    ez: Vec<f32>,
    inv_r: Vec<f32>,
    /// Strength `q` of each loaded ball.
    q: Vec<f32>,
    /// The lanes of the last [`SharedOriginBalls::gather_rays`] whose field may reach the
    /// isovalue on their range, as bits (all of them when no bound was asked), and (kept
    /// for the tests only) the bound of each lane.
    reach: u8,
    #[cfg(test)]
    bounds: [f32; RAY_LANES],
    /// The loaded balls some ray of the last [`SharedOriginBalls::gather_rays`] crosses
    /// within its range, in the loaded order: (ball's place in the load, its lanes as bits).
    lane_hits: Vec<(u32, u8)>,
    /// For each of `lane_hits`, `(t0, t1, a, tc, s_min)` of every lane.
    lane_spans: Vec<[[f32; RAY_LANES]; 5]>,
}

/// Rays [`SharedOriginBalls::gather_rays`] tests a leaf's balls against at once: `wide`'s
/// `f32x8`, one AVX register or two SSE ones in the portable build.
pub(super) const RAY_LANES: usize = 8;

/// One ball's span in every lane, as [`SharedOriginBalls::gather_rays`] computes it.
struct Span {
    t0: f32x8,
    t1: f32x8,
    a: f32x8,
    tc: f32x8,
    s_min: f32x8,
}

/// The root finder's whole-stretch bound (`roots`' `stretch_may_reach`) in lanes: the sum,
/// over a ray's gathered balls in their order, of the most each ball's term can be on the
/// part of the ray's range its support covers (a negative term only where it covers all of
/// it), with the scalar bound's operations in its order in every lane, so that a lane says
/// "cannot reach" exactly when the ray's search would.
#[derive(Clone, Copy, Debug)]
pub(super) struct StretchBound {
    kernel: KernelPoly<f32>,
    isovalue: f32,
    /// The kernel at `w = 1` (the centre): its sign says which way each ball's term points.
    peak: f32,
}

impl StretchBound {
    /// The bound for searches under `kernel` and `isovalue`.
    pub(super) fn new(kernel: KernelPoly<f32>, isovalue: f32) -> Self {
        let peak = kernel.at_w_of::<0>(1.0);
        StretchBound {
            kernel,
            isovalue,
            peak,
        }
    }

    /// A ball of strength `q` and span `span` in the lanes `met` (a mask): its term's bound on
    /// `[max(t0, lo), min(t1, hi)]` where it counts, 0 elsewhere.
    #[inline(always)]
    fn term(&self, q: f32, met: f32x8, span: &Span, lo: f32x8, hi: f32x8) -> f32x8 {
        let (zero, one) = (f32x8::ZERO, f32x8::ONE);
        let (a, b) = (span.t0.max(lo), span.t1.min(hi));
        let positive = q * self.peak > 0.0;
        let (t, counts) = if positive {
            (span.tc.max(a).min(b), a.cmp_lt(b))
        } else {
            let farther = (a - span.tc).abs().cmp_gt((b - span.tc).abs());
            let covers = !(a.cmp_gt(lo) | b.cmp_lt(hi));
            (farther.blend(a, b), a.cmp_lt(b) & covers)
        };
        let u = t - span.tc;
        let s = span.a * u * u + span.s_min;
        let w = one - s;
        let c = &self.kernel.c;
        let degree = self.kernel.degree;
        let mut acc = f32x8::splat(c[degree]);
        for &ck in c[..degree].iter().rev() {
            acc = acc * w + f32x8::splat(ck);
        }
        let term = s.cmp_ge(one).blend(zero, f32x8::splat(q) * acc);
        (counts & met).blend(term, zero)
    }
}

impl SharedOriginBalls {
    /// Loads `balls` (indices into `m`'s balls) as seen from `origin`; `false` when one of them
    /// is an ellipsoid (whose frame this layout does not hold), and the caller gathers as a
    /// single ray does.
    pub(super) fn load(&mut self, records: &[Ball], origin: Vec3, balls: &[u32]) -> bool {
        self.ids.clear();
        self.ex.clear();
        self.ey.clear();
        self.ez.clear();
        self.inv_r.clear();
        self.q.clear();
        for &i in balls {
            let b = &records[i as usize];
            if b.frame != u32::MAX {
                return false;
            }
            let e = (origin - b.center) * b.inv_r;
            self.q.push(b.strength);
            self.ids.push(i);
            self.ex.push(e.x);
            self.ey.push(e.y);
            self.ez.push(e.z);
            self.inv_r.push(b.inv_r);
        }
        true
    }

    /// Every loaded ball against up to [`RAY_LANES`] rays from the shared origin at once:
    /// `rays[l] = (ray, near, far)` in lane `l`, directions from `dirs`. What
    /// `PreparedMetaballs::gather` computes for one ray, the same IEEE operations in the same
    /// order in every lane (so bit for bit; the negation flips the sign bit, as `-x` does on
    /// a scalar), with the rays in the vector instead of the balls: a leaf of few balls (most
    /// of `scattered-1k`'s after culling) fills the lanes too, and a ball no ray's line meets
    /// (most of them) skips the span's division and square root. Read a lane's balls with
    /// [`SharedOriginBalls::lane_gathered`].
    pub(super) fn gather_rays(
        &mut self,
        rays: &[(u32, f32, f32)],
        dirs: &[Ray],
        bound: Option<&StretchBound>,
    ) {
        let m = rays.len();
        debug_assert!((1..=RAY_LANES).contains(&m));
        // Lanes past the last ray repeat it; their bits are cleared.
        let mut lanes = [[0f32; RAY_LANES]; 5];
        for l in 0..RAY_LANES {
            let (i, near, far) = rays[l.min(m - 1)];
            let dir = dirs[i as usize].dir;
            (lanes[0][l], lanes[1][l], lanes[2][l]) = (dir.x, dir.y, dir.z);
            (lanes[3][l], lanes[4][l]) = (near, far);
        }
        let [dx, dy, dz, lo, hi] = lanes.map(f32x8::from);
        let live = ((1u32 << m) - 1) as i32;
        let (zero, one, sign) = (f32x8::ZERO, f32x8::ONE, f32x8::splat(-0.0));
        let live_lanes = f32x8::from(std::array::from_fn::<f32, RAY_LANES, _>(|l| {
            f32::from_bits(if l < m { u32::MAX } else { 0 })
        }));
        let mut sum = zero;
        self.lane_hits.clear();
        self.lane_spans.clear();
        for k in 0..self.ids.len() {
            let r = f32x8::splat(self.inv_r[k]);
            let (ex, ey, ez) = (
                f32x8::splat(self.ex[k]),
                f32x8::splat(self.ey[k]),
                f32x8::splat(self.ez[k]),
            );
            let (gx, gy, gz) = (dx * r, dy * r, dz * r);
            let a = gx * gx + gy * gy + gz * gz;
            let tc = ((ex * gx + ey * gy + ez * gz) ^ sign) / a;
            let (qx, qy, qz) = (ex + tc * gx, ey + tc * gy, ez + tc * gz);
            let s_min = qx * qx + qy * qy + qz * qz;
            let inside = (a.cmp_gt(zero) & s_min.cmp_lt(one)).move_mask() & live;
            if inside == 0 {
                continue; // no ray meets the support: its span is not needed
            }
            let half = ((one - s_min) / a).sqrt();
            let (t0, t1) = (tc - half, tc + half);
            let apart = t1.cmp_lt(lo) | t0.cmp_gt(hi);
            let hits = inside & !apart.move_mask();
            if hits == 0 {
                continue;
            }
            if let Some(bound) = bound {
                let met = a.cmp_gt(zero) & s_min.cmp_lt(one) & !apart & live_lanes;
                let span = Span {
                    t0,
                    t1,
                    a,
                    tc,
                    s_min,
                };
                sum += bound.term(self.q[k], met, &span, lo, hi);
            }
            self.lane_hits.push((k as u32, hits as u8));
            self.lane_spans.push([
                t0.to_array(),
                t1.to_array(),
                a.to_array(),
                tc.to_array(),
                s_min.to_array(),
            ]);
        }
        #[cfg(test)]
        {
            self.bounds = sum.to_array();
        }
        self.reach = match bound {
            Some(bound) => (!sum.cmp_lt(f32x8::splat(bound.isovalue))).move_mask() as u8,
            None => u8::MAX,
        };
    }

    /// Whether lane `lane`'s field may reach the isovalue on its range, by the bound the last
    /// [`SharedOriginBalls::gather_rays`] was given (`true` without one): where it says no,
    /// the search of the lane's balls would have said so before anything else.
    pub(super) fn may_reach(&self, lane: usize) -> bool {
        self.reach & (1 << lane) != 0
    }

    /// Lane `lane`'s bound of the last [`SharedOriginBalls::gather_rays`] (0 without one).
    #[cfg(test)]
    pub(super) fn lane_bound(&self, lane: usize) -> f32 {
        self.bounds[lane]
    }

    /// How many balls lane `lane`'s ray of the last [`SharedOriginBalls::gather_rays`]
    /// gathered.
    pub(super) fn lane_count(&self, lane: usize) -> usize {
        let bit = 1u8 << lane;
        self.lane_hits
            .iter()
            .filter(|&&(_, h)| h & bit != 0)
            .count()
    }

    /// The balls whose support lane `lane`'s ray of the last
    /// [`SharedOriginBalls::gather_rays`] crosses within its range, appended to `out` in
    /// the loaded order: what `PreparedMetaballs::gather` appends for that ray.
    pub(super) fn lane_gathered(&self, records: &[Ball], lane: usize, out: &mut Vec<RayBall<f32>>) {
        let bit = 1u8 << lane;
        for (&(k, hits), spans) in self.lane_hits.iter().zip(&self.lane_spans) {
            if hits & bit != 0 {
                let i = self.ids[k as usize];
                let [t0, t1, a, tc, s_min] = spans;
                let span = (t0[lane], t1[lane], a[lane], tc[lane], s_min[lane]);
                out.push(records[i as usize].seen(i, span, true));
            }
        }
    }
}

/// `a = |g|²`, `tc = −e·g / a` and `s_min = |e + tc g|²` for `g = dir / R` (`r = 1 / R`) and the
/// origin `e` in the ball's unit frame: [`RayBall::along`]'s operations in its order. Every
/// gather of this file runs it in its vector loop (the origin shared or per ray).
#[inline(always)]
fn along_shared(dir: Vec3, r: f32, (ex, ey, ez): (f32, f32, f32)) -> (f32, f32, f32) {
    let (gx, gy, gz) = (dir.x * r, dir.y * r, dir.z * r);
    let a = gx * gx + gy * gy + gz * gz;
    let tc = -(ex * gx + ey * gy + ez * gz) / a;
    let (qx, qy, qz) = (ex + tc * gx, ey + tc * gy, ez + tc * gz);
    (a, tc, qx * qx + qy * qy + qz * qz)
}

/// Half the length of the support's chord, `((1 − s_min) / a).sqrt()`: meaningful where
/// `a > 0` and `s_min < 1` (a NaN or garbage elsewhere, which [`support_span_of`] ignores).
/// Branch-free, so that the tree's gather forms it in its vector loop for every ball at once
/// instead of a division and a square root, one after the other, for each ball the ray
/// meets (Molecule's transparency frame 2–3% faster; the shadow packets' gather, tried the
/// same way, did not move).
#[inline(always)]
fn half_width(a: f32, s_min: f32) -> f32 {
    ((1.0 - s_min) / a).sqrt()
}

/// Where the ray crosses the ball's support, `(t0, t1)`, if it does and that meets `[lo, hi]`,
/// from the chord's [`half_width`].
#[inline(always)]
fn support_span_of(a: f32, tc: f32, s_min: f32, half: f32, lo: f32, hi: f32) -> Option<(f32, f32)> {
    if !(a > 0.0) || !(s_min < 1.0) {
        return None;
    }
    let (t0, t1) = (tc - half, tc + half);
    (!(t1 < lo || t0 > hi)).then_some((t0, t1))
}

/// The balls of one leaf (spheres only) for rays with origins of their own (shadow rays): per
/// ray, `e = (o − p) / R` is computed in the same branch-free loop as `a`, `tc`, `s_min`, with
/// `PreparedMetaballs::gather`'s operations in its order, so the gathered balls are bit for
/// bit the single ray's.
#[derive(Debug, Default)]
pub(super) struct LeafSpheres {
    ids: Vec<u32>,
    cx: Vec<f32>,
    cy: Vec<f32>,
    cz: Vec<f32>,
    inv_r: Vec<f32>,
    a: Vec<f32>,
    tc: Vec<f32>,
    s_min: Vec<f32>,
}

impl LeafSpheres {
    /// Loads `balls` (indices into `m`'s balls); `false` when one of them is an ellipsoid,
    /// and the caller gathers as a single ray does.
    pub(super) fn load(&mut self, records: &[Ball], balls: &[u32]) -> bool {
        self.ids.clear();
        self.cx.clear();
        self.cy.clear();
        self.cz.clear();
        self.inv_r.clear();
        for &i in balls {
            let b = &records[i as usize];
            if b.frame != u32::MAX {
                return false;
            }
            self.ids.push(i);
            self.cx.push(b.center.x);
            self.cy.push(b.center.y);
            self.cz.push(b.center.z);
            self.inv_r.push(b.inv_r);
        }
        let n = self.ids.len();
        self.a.resize(n, 0.0);
        self.tc.resize(n, 0.0);
        self.s_min.resize(n, 0.0);
        true
    }

    /// The balls whose support `o + t·dir` crosses within `[lo, hi]`, appended to `out` in
    /// the loaded order: what `PreparedMetaballs::gather` appends for each of them.
    pub(super) fn gather(
        &mut self,
        records: &[Ball],
        origin: Vec3,
        dir: Vec3,
        lo: f32,
        hi: f32,
        out: &mut Vec<RayBall<f32>>,
    ) {
        let n = self.ids.len();
        let (cx, cy, cz, inv_r) = (
            &self.cx[..n],
            &self.cy[..n],
            &self.cz[..n],
            &self.inv_r[..n],
        );
        let (a_out, tc_out, s_out) = (&mut self.a[..n], &mut self.tc[..n], &mut self.s_min[..n]);
        for k in 0..n {
            let r = inv_r[k];
            let e = (
                (origin.x - cx[k]) * r,
                (origin.y - cy[k]) * r,
                (origin.z - cz[k]) * r,
            );
            (a_out[k], tc_out[k], s_out[k]) = along_shared(dir, r, e);
        }
        for k in 0..n {
            let (a, tc, s_min) = (self.a[k], self.tc[k], self.s_min[k]);
            let half = half_width(a, s_min);
            if let Some(span) = support_span_of(a, tc, s_min, half, lo, hi) {
                let i = self.ids[k];
                out.push(records[i as usize].seen(i, (span.0, span.1, a, tc, s_min), true));
            }
        }
    }
}

/// The main tree's leaf lists as structure-of-arrays, built with the tree: entry `k` holds
/// the centre and `1/R` of ball `tree.balls[k]`, so a single ray's leaf gather reads a
/// contiguous stretch and runs the same branch-free loop (16 balls at a time) instead of
/// reaching into the ball records one by one. Only for scenes of spheres.
#[derive(Debug)]
pub(super) struct TreeSpheres {
    cx: Vec<f32>,
    cy: Vec<f32>,
    cz: Vec<f32>,
    inv_r: Vec<f32>,
}

/// Balls a gather works through at a time: fixed-size arrays the compiler vectorises.
const LANES: usize = 16;

impl TreeSpheres {
    /// `None` when the scene has an ellipsoid. `tree` is built over `records`.
    pub(super) fn build(records: &[Ball], tree: &Tree) -> Option<TreeSpheres> {
        if records.iter().any(|b| b.frame != u32::MAX) {
            return None;
        }
        // One parallel pass on the pool with the tree (a state's build time counts it): each
        // record is read once (the lists name balls in scene order, so the reads are random).
        type Columns = ((Vec<f32>, Vec<f32>), (Vec<f32>, Vec<f32>));
        let ((cx, cy), (cz, inv_r)): Columns = tree
            .balls
            .par_iter()
            .map(|&i| {
                let b = &records[i as usize];
                ((b.center.x, b.center.y), (b.center.z, b.inv_r))
            })
            .collect();
        Some(TreeSpheres { cx, cy, cz, inv_r })
    }

    /// The balls of `tree.balls[first..first + ids.len()]` (`ids`, a leaf's list) whose
    /// support sphere does not lie wholly outside `frustum`, appended to `out` in the leaf's
    /// order: [`Frustum::excludes_sphere`]'s operations (with the radius `1 / (1/R)` as the
    /// packet took it from the ball's record), eight balls at a time in `f32x8`.
    pub(super) fn cull(&self, frustum: &Frustum, ids: &[u32], first: usize, out: &mut Vec<u32>) {
        let eye = frustum.eye;
        let (ex, ey, ez) = (
            f32x8::splat(eye.x),
            f32x8::splat(eye.y),
            f32x8::splat(eye.z),
        );
        let mut start = 0;
        while start < ids.len() {
            let len = (ids.len() - start).min(RAY_LANES);
            let at = first + start;
            let lanes = |v: &[f32]| {
                let mut a = [0f32; RAY_LANES];
                a[..len].copy_from_slice(&v[at..at + len]);
                f32x8::from(a)
            };
            let (vx, vy, vz) = (
                lanes(&self.cx) - ex,
                lanes(&self.cy) - ey,
                lanes(&self.cz) - ez,
            );
            let radius = f32x8::ONE / lanes(&self.inv_r);
            let mut outside = f32x8::ZERO;
            for n in &frustum.normals {
                let dot = f32x8::splat(n.x) * vx + f32x8::splat(n.y) * vy + f32x8::splat(n.z) * vz;
                outside |= dot.cmp_lt(-radius);
            }
            let mut keep = !outside.move_mask() as u32 & ((1u32 << len) - 1);
            while keep != 0 {
                let k = keep.trailing_zeros() as usize;
                out.push(ids[start + k]);
                keep &= keep - 1;
            }
            start += len;
        }
    }

    /// The balls of `tree.balls[first..first + ids.len()]` (`ids`, a leaf's list) whose
    /// support `ray` crosses within `[lo, hi]`, appended to `out` in the leaf's order, the
    /// first `owned` of them owners (all of them unless `owners_only`): what
    /// `PreparedMetaballs::gather` appends for each, bit for bit. `crowded` says the ray runs
    /// inside the solid, where most of the balls cover it; they are then listed without a
    /// branch per ball (whose outcome the predictor cannot guess there: Molecule's and Pool's
    /// transparency frames 5% faster), elsewhere with one (nearly always "missed", and
    /// cheaper: hard shadows 10–15% slower listed without).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn gather(
        &self,
        records: &[Ball],
        ids: &[u32],
        first: usize,
        (owned, owners_only): (usize, bool),
        ray: &Ray,
        ((lo, hi), crowded): ((f32, f32), bool),
        out: &mut Vec<RayBall<f32>>,
    ) {
        let (o, d) = (ray.origin, ray.dir);
        let mut start = 0;
        while start < ids.len() {
            let len = (ids.len() - start).min(LANES);
            let at = first + start;
            let (cx, cy, cz, inv_r) = (
                &self.cx[at..at + len],
                &self.cy[at..at + len],
                &self.cz[at..at + len],
                &self.inv_r[at..at + len],
            );
            let (mut a_of, mut tc_of, mut s_of) = ([0f32; LANES], [0f32; LANES], [0f32; LANES]);
            let mut half_of = [0f32; LANES];
            for k in 0..len {
                let r = inv_r[k];
                let e = ((o.x - cx[k]) * r, (o.y - cy[k]) * r, (o.z - cz[k]) * r);
                let (a, tc, s_min) = along_shared(d, r, e);
                (a_of[k], tc_of[k], s_of[k]) = (a, tc, s_min);
                half_of[k] = half_width(a, s_min);
            }
            if crowded {
                let (mut met, mut n_met) = ([0u8; LANES], 0);
                for k in 0..len {
                    let (tc, half) = (tc_of[k], half_of[k]);
                    let apart = (tc + half < lo) | (tc - half > hi);
                    met[n_met] = k as u8;
                    n_met += ((a_of[k] > 0.0) & (s_of[k] < 1.0) & !apart) as usize;
                }
                for &k in &met[..n_met] {
                    let k = k as usize;
                    let (a, tc, s_min, half) = (a_of[k], tc_of[k], s_of[k], half_of[k]);
                    let span = (tc - half, tc + half, a, tc, s_min);
                    let i = ids[start + k];
                    let owner = !owners_only || start + k < owned;
                    out.push(records[i as usize].seen(i, span, owner));
                }
            } else {
                for k in 0..len {
                    let (a, tc, s_min) = (a_of[k], tc_of[k], s_of[k]);
                    if let Some(span) = support_span_of(a, tc, s_min, half_of[k], lo, hi) {
                        let i = ids[start + k];
                        let owner = !owners_only || start + k < owned;
                        let span = (span.0, span.1, a, tc, s_min);
                        out.push(records[i as usize].seen(i, span, owner));
                    }
                }
            }
            start += len;
        }
    }
}
