//! A packet leaf's balls as structure-of-arrays, for rays that share one origin.
//!
//! Every primary ray of a tile starts at the eye, so each sphere's `e = (o − p) / R` (the
//! origin in the ball's unit frame) is the same for all of them and is computed once per leaf
//! and packet. Per ray, the quantities [`RayBall::along`] derives (`a = |g|²`,
//! `tc = −e·g / a`, `s_min = |e + tc g|²` with `g = d / R`) are computed for all the leaf's balls
//! in one branch-free loop over the arrays, which the compiler turns into vector code (checked
//! in the release assembly: `mulps`/`divps` over 4 lanes at the portable `x86-64` level);
//! only the balls whose support the ray crosses go on to the scalar tail. The operations and
//! their order are those of [`PreparedMetaballs::gather`] with `along`, in IEEE `f32` without
//! contraction, so the gathered balls are bit for bit the single ray's.

use super::PreparedMetaballs;
use crate::kinds::metaballs::roots::RayBall;
use glam::Vec3;

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
    pub(super) fn load(&mut self, m: &PreparedMetaballs, origin: Vec3, balls: &[u32]) -> bool {
        self.ids.clear();
        self.ex.clear();
        self.ey.clear();
        self.ez.clear();
        self.inv_r.clear();
        for &i in balls {
            let b = &m.balls[i as usize];
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
    /// [`PreparedMetaballs::gather`] appends for each of them.
    pub(super) fn gather(
        &mut self,
        m: &PreparedMetaballs,
        dir: Vec3,
        lo: f32,
        hi: f32,
        out: &mut Vec<RayBall<f32>>,
    ) {
        let n = self.ids.len();
        let (ex, ey, ez, inv_r) = (
            &self.ex[..n],
            &self.ey[..n],
            &self.ez[..n],
            &self.inv_r[..n],
        );
        let (a_out, tc_out, s_out) = (&mut self.a[..n], &mut self.tc[..n], &mut self.s_min[..n]);
        for k in 0..n {
            let r = inv_r[k];
            let (gx, gy, gz) = (dir.x * r, dir.y * r, dir.z * r);
            let a = gx * gx + gy * gy + gz * gz;
            let tc = -(ex[k] * gx + ey[k] * gy + ez[k] * gz) / a;
            let (qx, qy, qz) = (ex[k] + tc * gx, ey[k] + tc * gy, ez[k] + tc * gz);
            a_out[k] = a;
            tc_out[k] = tc;
            s_out[k] = qx * qx + qy * qy + qz * qz;
        }
        for k in 0..n {
            let (a, s_min) = (self.a[k], self.s_min[k]);
            if !(a > 0.0) || !(s_min < 1.0) {
                continue;
            }
            let tc = self.tc[k];
            let half = ((1.0 - s_min) / a).sqrt();
            let (t0, t1) = (tc - half, tc + half);
            if t1 < lo || t0 > hi {
                continue;
            }
            let i = self.ids[k];
            out.push(m.balls[i as usize].seen(i, (t0, t1, a, tc, s_min), true));
        }
    }
}

/// The balls of one leaf (spheres only) for rays with origins of their own (shadow rays): per
/// ray, `e = (o − p) / R` is computed in the same branch-free loop as `a`, `tc`, `s_min`, with
/// [`PreparedMetaballs::gather`]'s operations in its order, so the gathered balls are bit for
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
    pub(super) fn load(&mut self, m: &PreparedMetaballs, balls: &[u32]) -> bool {
        self.ids.clear();
        self.cx.clear();
        self.cy.clear();
        self.cz.clear();
        self.inv_r.clear();
        for &i in balls {
            let b = &m.balls[i as usize];
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
    /// the loaded order: what [`PreparedMetaballs::gather`] appends for each of them.
    pub(super) fn gather(
        &mut self,
        m: &PreparedMetaballs,
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
            let (ex, ey, ez) = (
                (origin.x - cx[k]) * r,
                (origin.y - cy[k]) * r,
                (origin.z - cz[k]) * r,
            );
            let (gx, gy, gz) = (dir.x * r, dir.y * r, dir.z * r);
            let a = gx * gx + gy * gy + gz * gz;
            let tc = -(ex * gx + ey * gy + ez * gz) / a;
            let (qx, qy, qz) = (ex + tc * gx, ey + tc * gy, ez + tc * gz);
            a_out[k] = a;
            tc_out[k] = tc;
            s_out[k] = qx * qx + qy * qy + qz * qz;
        }
        for k in 0..n {
            let (a, s_min) = (self.a[k], self.s_min[k]);
            if !(a > 0.0) || !(s_min < 1.0) {
                continue;
            }
            let tc = self.tc[k];
            let half = ((1.0 - s_min) / a).sqrt();
            let (t0, t1) = (tc - half, tc + half);
            if t1 < lo || t0 > hi {
                continue;
            }
            let i = self.ids[k];
            out.push(m.balls[i as usize].seen(i, (t0, t1, a, tc, s_min), true));
        }
    }
}
