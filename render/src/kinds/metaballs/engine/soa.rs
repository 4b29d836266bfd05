//! A packet leaf's balls as structure-of-arrays, for rays that share one origin.
//!
//! Every primary ray of a tile starts at the eye, so each sphere's `e = (o − p) / R` (the
//! origin in the ball's unit frame) is the same for all of them and is computed once per leaf
//! and packet. Per ray, the quantities [`RayBall::along`] derives (`a = |g|²`,
//! `tc = −e·g / a`, `s_min = |e + tc g|²` with `g = d / R`) are computed for all the leaf's balls
//! in one branch-free loop over the arrays, which the compiler turns into vector code (checked
//! in the release assembly: `mulps`/`divps` over 4 lanes at the portable `x86-64` level);
//! only the balls whose support the ray crosses go on to the scalar tail. A leaf with fewer
//! than [`FUSED_BELOW`] balls left after the packet's culling (most on `scattered-1k`) takes
//! one scalar pass with the same operations instead. The operations and
//! their order are those of `PreparedMetaballs::gather` with `along`, in IEEE `f32` without
//! contraction, so the gathered balls are bit for bit the single ray's.

use crate::kinds::metaballs::roots::RayBall;
use crate::kinds::metaballs::tree::Tree;
use crate::ray::Ray;
use glam::Vec3;
use rayon::prelude::*;

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

/// Balls below which [`SharedOriginBalls::gather`] takes one scalar pass instead of a
/// vector pass and a filter pass (callgrind, ray cast at 320×240 on one thread: 8 saves
/// 2.1% of `scattered-1k`'s instructions and 1.0% of `blobs`', against 1.2% and 0.6% for 4;
/// 16 costs Molecule 1.5%).
const FUSED_BELOW: usize = 8;

/// The balls of one leaf for one shared origin (spheres only).
#[derive(Debug, Default)]
pub(super) struct SharedOriginBalls {
    ids: Vec<u32>,
    ex: Vec<f32>,
    ey: Vec<f32>,
    ez: Vec<f32>,
    inv_r: Vec<f32>,
    a: Vec<f32>,
    tc: Vec<f32>,
    s_min: Vec<f32>,
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
        for &i in balls {
            let b = &records[i as usize];
            if b.frame != u32::MAX {
                return false;
            }
            let e = (origin - b.center) * b.inv_r;
            self.ids.push(i);
            self.ex.push(e.x);
            self.ey.push(e.y);
            self.ez.push(e.z);
            self.inv_r.push(b.inv_r);
        }
        let n = self.ids.len();
        self.a.resize(n, 0.0);
        self.tc.resize(n, 0.0);
        self.s_min.resize(n, 0.0);
        true
    }

    /// The balls whose support the ray along `dir` from the shared origin crosses within
    /// `[lo, hi]`, appended to `out` in the loaded order: what
    /// `PreparedMetaballs::gather` appends for each of them.
    pub(super) fn gather(
        &mut self,
        records: &[Ball],
        dir: Vec3,
        lo: f32,
        hi: f32,
        out: &mut Vec<RayBall<f32>>,
    ) {
        let n = self.ids.len();
        if n < FUSED_BELOW {
            // Too few balls to fill a vector: one pass, the same operations ball by ball.
            for k in 0..n {
                let e = (self.ex[k], self.ey[k], self.ez[k]);
                let (a, tc, s_min) = along_shared(dir, self.inv_r[k], e);
                if let Some(span) = support_span(a, tc, s_min, lo, hi) {
                    let i = self.ids[k];
                    out.push(records[i as usize].seen(i, (span.0, span.1, a, tc, s_min), true));
                }
            }
            return;
        }
        let (ex, ey, ez, inv_r) = (
            &self.ex[..n],
            &self.ey[..n],
            &self.ez[..n],
            &self.inv_r[..n],
        );
        let (a_out, tc_out, s_out) = (&mut self.a[..n], &mut self.tc[..n], &mut self.s_min[..n]);
        for k in 0..n {
            (a_out[k], tc_out[k], s_out[k]) = along_shared(dir, inv_r[k], (ex[k], ey[k], ez[k]));
        }
        for k in 0..n {
            let (a, tc, s_min) = (self.a[k], self.tc[k], self.s_min[k]);
            if let Some(span) = support_span(a, tc, s_min, lo, hi) {
                let i = self.ids[k];
                out.push(records[i as usize].seen(i, (span.0, span.1, a, tc, s_min), true));
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

/// Where the ray crosses the ball's support, `(t0, t1)`, if it does and that meets `[lo, hi]`.
#[inline(always)]
fn support_span(a: f32, tc: f32, s_min: f32, lo: f32, hi: f32) -> Option<(f32, f32)> {
    if !(a > 0.0) || !(s_min < 1.0) {
        return None;
    }
    let half = ((1.0 - s_min) / a).sqrt();
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
            if let Some(span) = support_span(a, tc, s_min, lo, hi) {
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
    /// support `ray` crosses within `[lo, hi]`, appended to `out` in the leaf's order, the
    /// first `owned` of them owners (all of them unless `owners_only`): what
    /// `PreparedMetaballs::gather` appends for each, bit for bit.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn gather(
        &self,
        records: &[Ball],
        ids: &[u32],
        first: usize,
        (owned, owners_only): (usize, bool),
        ray: &Ray,
        (lo, hi): (f32, f32),
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
            for k in 0..len {
                let r = inv_r[k];
                let e = ((o.x - cx[k]) * r, (o.y - cy[k]) * r, (o.z - cz[k]) * r);
                (a_of[k], tc_of[k], s_of[k]) = along_shared(d, r, e);
            }
            for k in 0..len {
                let (a, tc, s_min) = (a_of[k], tc_of[k], s_of[k]);
                if let Some(span) = support_span(a, tc, s_min, lo, hi) {
                    let i = ids[start + k];
                    let owner = !owners_only || start + k < owned;
                    out.push(records[i as usize].seen(i, (span.0, span.1, a, tc, s_min), owner));
                }
            }
            start += len;
        }
    }
}
