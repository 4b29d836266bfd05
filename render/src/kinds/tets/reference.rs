//! The `f64` reference intersection: every tet by brute force, in double precision, with a
//! method independent of the hot path's. Tests compare the `f32` traversal against it.
//!
//! How it works: inside a tet the field is the linear interpolant of its corner values, so
//! its isosurface is the plane `f(o) + t g·d = v` (with `g` the tet's gradient); the hit at
//! that `t` counts if its barycentric coordinates in the tet are all non-negative. No
//! marching-tets table, no isopolygon, no BVH.

use glam::{DVec3, Vec3};

/// The nearest `(t, tet)` with `t` in `[t_min, t_max]` where the interpolated field along
/// `origin + t·dir` (`dir` normalised here) equals `isovalue`.
#[allow(clippy::too_many_arguments)]
pub fn reference_hit(
    positions: &[Vec3],
    scalars: &[f32],
    tets: &[[u32; 4]],
    origin: DVec3,
    dir: DVec3,
    t_min: f64,
    t_max: f64,
    isovalue: f64,
) -> Option<(f64, u32)> {
    let dir = dir.normalize();
    let mut best: Option<(f64, u32)> = None;
    for (index, ids) in tets.iter().enumerate() {
        let p = ids.map(|v| positions[v as usize].as_dvec3());
        let s = ids.map(|v| scalars[v as usize] as f64);
        let e = [p[1] - p[0], p[2] - p[0], p[3] - p[0]];
        let det = e[0].dot(e[1].cross(e[2]));
        if det == 0.0 {
            continue;
        }
        let g = (e[1].cross(e[2]) * (s[1] - s[0])
            + e[2].cross(e[0]) * (s[2] - s[0])
            + e[0].cross(e[1]) * (s[3] - s[0]))
            / det;
        let slope = g.dot(dir);
        if slope == 0.0 {
            continue;
        }
        let t = (isovalue - (s[0] + g.dot(origin - p[0]))) / slope;
        if !(t >= t_min && t <= t_max) {
            continue;
        }
        let h = origin + dir * t;
        if barycentric_min(p, h) < -1e-12 {
            continue;
        }
        if best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, index as u32));
        }
    }
    best
}

/// The smallest barycentric coordinate of `h` in the tet `p` (negative outside).
pub fn barycentric_min(p: [DVec3; 4], h: DVec3) -> f64 {
    let vol = |a: DVec3, b: DVec3, c: DVec3, d: DVec3| (b - a).cross(c - a).dot(d - a);
    let total = vol(p[0], p[1], p[2], p[3]);
    [
        vol(h, p[1], p[2], p[3]),
        vol(p[0], h, p[2], p[3]),
        vol(p[0], p[1], h, p[3]),
        vol(p[0], p[1], p[2], h),
    ]
    .into_iter()
    .map(|v| v / total)
    .fold(f64::INFINITY, f64::min)
}
