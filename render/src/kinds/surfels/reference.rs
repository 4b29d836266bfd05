//! A brute-force `f64` reference for the surfel kind's ray–surface intersections, sharing no
//! code with `intersect` (the accuracy study and tests compare against it).
//!
//! How it works: the surface of deforming-point-sampled-surfaces.txt §4.2.1 is the zero set of
//! `f(x) = n(x)ᵀ(x − a(x))`, with `a(x)` and `n(x)` the weighted averages of eq. 12 over
//! **every** surfel (eq. 2's weight `1 − 6r² + 8r³ − 3r⁴`, `r = |x − c_i| / h_i`, written out
//! again here), not a leaf's fixed neighbourhood. Along a ray, `f` is sampled where some
//! surfel's support covers it, at a step of 1/32 of the smallest support crossed; the first
//! sign change from outside (`f > 0`, normals point out) to inside is bisected to `1e-13`
//! relative, and kept if the point lies on a surfel's disc (within its reach of its centre,
//! the paper's surfels being ellipses); otherwise the march goes on. No tree, no iteration
//! from an ellipse, no convergence threshold, no clipping (§4.3) of its own: on objects that
//! clip, a caller passes its own cut ([`trace_kept`]), for example the side of each clipping
//! surface's MLS surface ([`field`]), not the engine's nearest-surfel tangent planes.

use glam::DVec3;

/// One surfel as the reference sees it.
#[derive(Clone, Copy, Debug)]
pub struct MlsSurfel {
    pub centre: DVec3,
    /// Unit outward normal.
    pub normal: DVec3,
    /// Support radius `h` of its weight.
    pub support: f64,
    /// How far from its centre its disc reaches (a hit must lie within one surfel's reach).
    pub reach: f64,
}

/// A first hit: distance along the ray (in units of `|d|`) and the MLS normal there.
#[derive(Clone, Copy, Debug)]
pub struct MlsHit {
    pub t: f64,
    pub normal: DVec3,
}

/// Eq. 2's weight.
fn w(r: f64) -> f64 {
    if r >= 1.0 {
        0.0
    } else {
        1.0 + r * r * (-6.0 + r * (8.0 - 3.0 * r))
    }
}

/// `f(x)` and `n(x)` over `set`, or `None` where no support covers `x` or the normals cancel.
fn implicit<'a>(set: impl IntoIterator<Item = &'a MlsSurfel>, x: DVec3) -> Option<(f64, DVec3)> {
    let (mut sw, mut sp, mut sn) = (0.0, DVec3::ZERO, DVec3::ZERO);
    for s in set {
        let k = w(x.distance(s.centre) / s.support);
        sw += k;
        sp += k * s.centre;
        sn += k * s.normal;
    }
    if !(sw > 0.0) || !(sn.length() > 1e-12 * sw) {
        return None;
    }
    let n = sn.normalize();
    Some((n.dot(x - sp / sw), n))
}

/// `f(x) = n(x)ᵀ(x − a(x))` over `surfels` (positive outside), or `None` where no support
/// covers `x` or the normals cancel.
pub fn field(surfels: &[MlsSurfel], x: DVec3) -> Option<f64> {
    implicit(surfels, x).map(|(f, _)| f)
}

/// The first point of `o + t d`, `t ∈ [t_min, t_max]`, where the MLS surface of `surfels` is
/// crossed from outside.
pub fn first_hit(
    surfels: &[MlsSurfel],
    o: DVec3,
    d: DVec3,
    t_min: f64,
    t_max: f64,
) -> Option<MlsHit> {
    trace(surfels, o, d, t_min, t_max, 0.0).hit
}

/// [`first_hit`], and how near the ray came to the surface before it.
#[derive(Clone, Copy, Debug)]
pub struct MlsTrace {
    pub hit: Option<MlsHit>,
    /// The first sample before the hit (or on the whole ray, for a miss) where the ray ran
    /// within `near` of the surface (`|f| < near`) on a surfel's disc: where a definition of
    /// the surface that differs by `near` may already be hit (a graze, or the crossing's
    /// approach).
    pub near_from: Option<f64>,
}

/// [`first_hit`] with [`MlsTrace::near_from`] for the distance `near`.
pub fn trace(
    surfels: &[MlsSurfel],
    o: DVec3,
    d: DVec3,
    t_min: f64,
    t_max: f64,
    near: f64,
) -> MlsTrace {
    trace_kept(surfels, o, d, (t_min, t_max), near, Keep::ALL)
}

/// Which points on a surfel's disc [`trace_kept`] counts: the caller's own cut of the
/// surface (a test's clipping by the surfaces that clip this one, §4.3, written with its own
/// definition of the other surfaces).
#[derive(Clone, Copy)]
pub struct Keep<'a> {
    /// Where a crossing may be the hit (a crossing elsewhere is passed over).
    pub hit: &'a dyn Fn(DVec3) -> bool,
    /// Where running within `near` of the surface counts for [`MlsTrace::near_from`].
    pub near: &'a dyn Fn(DVec3) -> bool,
}

impl Keep<'_> {
    /// Every point.
    pub const ALL: Keep<'static> = Keep {
        hit: &|_| true,
        near: &|_| true,
    };
}

/// [`trace`] over `span = [t_min, t_max]`, counting only the points `keep` keeps: the first
/// crossing from outside on a disc that `keep.hit` keeps is the hit (the march goes on past
/// the others).
pub fn trace_kept(
    surfels: &[MlsSurfel],
    o: DVec3,
    d: DVec3,
    (t_min, t_max): (f64, f64),
    near: f64,
    keep: Keep,
) -> MlsTrace {
    let mut out = MlsTrace {
        hit: None,
        near_from: None,
    };
    let dd = d.length_squared();
    if !(dd > 0.0) {
        return out;
    }
    // The surfels whose support the ray crosses, and the stretches they cover.
    let mut crossed: Vec<&MlsSurfel> = Vec::new();
    let mut spans: Vec<(f64, f64)> = Vec::new();
    for s in surfels {
        let tc = (s.centre - o).dot(d) / dd;
        let miss2 = (o + tc * d).distance_squared(s.centre);
        let h2 = s.support * s.support;
        if miss2 >= h2 {
            continue;
        }
        let half = ((h2 - miss2) / dd).sqrt();
        let (a, b) = ((tc - half).max(t_min), (tc + half).min(t_max));
        if a < b {
            crossed.push(s);
            spans.push((a, b));
        }
    }
    if crossed.is_empty() {
        return out;
    }
    let step = crossed
        .iter()
        .map(|s| s.support)
        .fold(f64::INFINITY, f64::min)
        / 32.0
        / dd.sqrt();
    spans.sort_by(|x, y| x.0.total_cmp(&y.0));
    let on_disc = |x: DVec3| crossed.iter().any(|s| x.distance(s.centre) <= s.reach);
    let mut prev: Option<(f64, f64)> = None;
    let mut t = spans[0].0;
    let mut k = 0;
    while k < spans.len() {
        if t > spans[k].1 {
            k += 1;
            if k < spans.len() && t < spans[k].0 {
                t = spans[k].0;
                prev = None;
            }
            continue;
        }
        let here = implicit(crossed.iter().copied(), o + t * d).map(|(f, _)| f);
        if let Some(f) = here {
            let x = o + t * d;
            if out.near_from.is_none() && f.abs() < near && on_disc(x) && (keep.near)(x) {
                out.near_from = Some(t);
            }
        }
        if let (Some((tp, fp)), Some(f)) = (prev, here) {
            if fp > 0.0 && f <= 0.0 {
                let (mut lo, mut hi) = (tp, t);
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if hi - lo <= 1e-13 * hi.abs().max(1.0) || !(lo < mid && mid < hi) {
                        break;
                    }
                    match implicit(crossed.iter().copied(), o + mid * d) {
                        Some((fm, _)) if fm > 0.0 => lo = mid,
                        _ => hi = mid,
                    }
                }
                let x = o + hi * d;
                if on_disc(x) && (keep.hit)(x) {
                    if let Some((_, n)) = implicit(crossed.iter().copied(), x) {
                        out.hit = Some(MlsHit { t: hi, normal: n });
                        return out;
                    }
                }
            }
        }
        prev = here.map(|f| (t, f));
        t += step;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Surfels on a square grid of the plane `z = 0`, normals `+z`.
    fn plane(n: i32, spacing: f64) -> Vec<MlsSurfel> {
        let mut v = Vec::new();
        for i in -n..=n {
            for j in -n..=n {
                v.push(MlsSurfel {
                    centre: DVec3::new(i as f64 * spacing, j as f64 * spacing, 0.0),
                    normal: DVec3::Z,
                    support: 2.5 * spacing,
                    reach: 0.75 * spacing,
                });
            }
        }
        v
    }

    #[test]
    fn a_plane_of_surfels_is_hit_exactly() {
        let set = plane(10, 0.1);
        for (k, dir) in [
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::new(0.3, -0.2, -1.0),
            DVec3::new(-0.7, 0.5, -0.4),
        ]
        .into_iter()
        .enumerate()
        {
            let o = DVec3::new(0.013 * k as f64, -0.021, 0.4);
            let hit = first_hit(&set, o, dir, 0.0, 100.0).expect("the plane is hit");
            let exact = -o.z / dir.z;
            assert!(
                (hit.t - exact).abs() <= 1e-9 * exact,
                "ray {k}: t {} against {exact}",
                hit.t
            );
            assert!((hit.normal - DVec3::Z).length() < 1e-12, "{:?}", hit.normal);
        }
        // Beside the disc grid, the plane's continuation is not a surface.
        let outside = first_hit(&set, DVec3::new(5.0, 0.0, 1.0), -DVec3::Z, 0.0, 10.0);
        assert!(outside.is_none(), "{outside:?}");
    }

    #[test]
    fn a_cut_plane_is_hit_only_where_kept() {
        // Two planes of surfels, z = 0 and z = -0.5; the upper one cut away where x > 0.
        let mut lower = plane(10, 0.1);
        for s in &mut lower {
            s.centre.z = -0.5;
        }
        let upper = plane(10, 0.1);
        let cut = |x: DVec3| x.x <= 0.0;
        let keep = Keep {
            hit: &cut,
            near: &cut,
        };
        let down = DVec3::new(0.0, 0.0, -1.0);
        for (x, expect) in [(-0.3, Some(0.4)), (0.3, None), (-0.01, Some(0.4))] {
            let o = DVec3::new(x, 0.02, 0.4);
            let got = trace_kept(&upper, o, down, (0.0, 10.0), 2e-2, keep);
            assert_eq!(
                got.hit.map(|h| (h.t * 1e9).round() / 1e9),
                expect,
                "x = {x}"
            );
            assert_eq!(got.near_from.is_some(), expect.is_some(), "x = {x}");
        }
        // Past the cut the march goes on to the next surface (which the cut spares).
        let upper_only = |x: DVec3| x.x <= 0.0 || x.z < -0.25;
        let keep = Keep {
            hit: &upper_only,
            near: &upper_only,
        };
        let both: Vec<MlsSurfel> = upper.iter().chain(&lower).copied().collect();
        let beyond = trace_kept(
            &both,
            DVec3::new(0.3, 0.02, 0.4),
            down,
            (0.0, 10.0),
            0.0,
            keep,
        );
        let t = beyond.hit.map(|h| h.t).expect("the lower plane");
        assert!((t - 0.9).abs() < 1e-9, "{t}");
        assert!(field(&upper, DVec3::new(0.0, 0.0, 0.1)).is_some_and(|f| (f - 0.1).abs() < 1e-12));
        assert!(field(&upper, DVec3::new(9.0, 0.0, 0.0)).is_none());
    }

    #[test]
    fn a_sampled_sphere_is_hit_within_the_mls_offset() {
        // Fibonacci points on the unit sphere; the MLS surface of a sphere lies inside it by
        // about h²/(8R) (the weighted chord), so |t − t_exact| must stay below h²/R.
        let count = 3000;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let spacing = (4.0 * std::f64::consts::PI / count as f64).sqrt();
        let h = 2.5 * spacing;
        let set: Vec<MlsSurfel> = (0..count)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / count as f64;
                let r = (1.0 - y * y).sqrt();
                let p = DVec3::new(
                    r * (golden * i as f64).cos(),
                    y,
                    r * (golden * i as f64).sin(),
                );
                MlsSurfel {
                    centre: p,
                    normal: p,
                    support: h,
                    reach: spacing,
                }
            })
            .collect();
        for (k, impact) in [0.0, 0.3, 0.6, 0.9].into_iter().enumerate() {
            let o = DVec3::new(impact, 0.1 * k as f64, 3.0);
            let d = DVec3::new(0.0, 0.0, -1.0);
            // |o + t d| = 1: t = o.z − sqrt(1 − x² − y²).
            let (x, y) = (o.x, o.y);
            let exact = o.z - (1.0 - x * x - y * y).sqrt();
            let hit = first_hit(&set, o, d, 0.0, 10.0).expect("the sphere is hit");
            assert!(
                (hit.t - exact).abs() < h * h,
                "impact {impact}: t {} against {exact} (h = {h})",
                hit.t
            );
            let p = o + hit.t * d;
            let angle = hit.normal.angle_between(p.normalize()).to_degrees();
            assert!(
                angle < 2.0,
                "impact {impact}: normal {angle}° off the radius"
            );
        }
        assert!(first_hit(&set, DVec3::new(1.2, 0.0, 3.0), -DVec3::Z, 0.0, 10.0).is_none());
    }
}
