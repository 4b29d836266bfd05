//! The smallest enclosing sphere of a point set: Welzl's randomised algorithm (the miniball of
//! deforming-point-sampled-surfaces.txt §4.1.1, [Gar99]) on glam, in `f64`.
//!
//! How it works: points are visited in a fixed pseudo-random order (so the result is the
//! same on every run); a point outside the current ball restarts the scan of the points before
//! it with that point on the boundary, at most four levels deep. Degenerate support sets
//! (collinear or coplanar points, common on flat surfel patches) fall back to the smallest
//! ball through a subset that contains them all.

use crate::geom::rng::SplitMix64;
use glam::{DVec3, Vec3};

/// A sphere in `f64`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball {
    pub centre: DVec3,
    pub radius: f64,
}

impl Ball {
    const EMPTY: Ball = Ball {
        centre: DVec3::ZERO,
        radius: -1.0,
    };

    fn contains(&self, p: DVec3) -> bool {
        // A relative slack so round-off on the boundary does not restart the scan forever.
        let slack = 1e-9 * (1.0 + self.radius.abs() + self.centre.abs().max_element());
        self.radius >= 0.0 && (p - self.centre).length() <= self.radius + slack
    }
}

/// The smallest sphere containing every point (the empty set gives radius −1).
pub fn miniball(points: &[Vec3]) -> Ball {
    let mut pts: Vec<DVec3> = points.iter().map(|p| p.as_dvec3()).collect();
    // A fixed shuffle: expected linear time, the same ball every run.
    let mut rng = SplitMix64(0x5eed_ba11 ^ pts.len() as u64);
    for i in (1..pts.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        pts.swap(i, j);
    }
    let mut ball = Ball::EMPTY;
    for i in 0..pts.len() {
        if !ball.contains(pts[i]) {
            ball = with_support(&pts[..i], &[pts[i]]);
        }
    }
    ball
}

/// The smallest ball of `pts` with every point of `support` on its boundary.
fn with_support(pts: &[DVec3], support: &[DVec3]) -> Ball {
    let mut ball = ball_through(support);
    if support.len() == 4 {
        return ball;
    }
    for i in 0..pts.len() {
        if !ball.contains(pts[i]) {
            let mut s = [DVec3::ZERO; 4];
            s[..support.len()].copy_from_slice(support);
            s[support.len()] = pts[i];
            ball = with_support(&pts[..i], &s[..support.len() + 1]);
        }
    }
    ball
}

/// The smallest ball with 1–4 given points on its boundary, or, when the points are
/// degenerate, the smallest ball through a subset that still contains them all.
fn ball_through(s: &[DVec3]) -> Ball {
    match s.len() {
        0 => Ball::EMPTY,
        1 => Ball {
            centre: s[0],
            radius: 0.0,
        },
        2 => diameter(s[0], s[1]),
        3 => circum3(s[0], s[1], s[2]).unwrap_or_else(|| best_subset(s)),
        _ => circum4(s[0], s[1], s[2], s[3]).unwrap_or_else(|| best_subset(s)),
    }
}

fn diameter(a: DVec3, b: DVec3) -> Ball {
    Ball {
        centre: 0.5 * (a + b),
        radius: 0.5 * (a - b).length(),
    }
}

/// The circumcircle of a triangle (as a sphere), `None` when the points are collinear.
fn circum3(a: DVec3, b: DVec3, c: DVec3) -> Option<Ball> {
    let ab = b - a;
    let ac = c - a;
    let n = ab.cross(ac);
    let d = 2.0 * n.length_squared();
    if d <= 1e-24 * ab.length_squared().max(ac.length_squared()).powi(2) {
        return None;
    }
    let off = (ac.length_squared() * n.cross(ab) + ab.length_squared() * ac.cross(n)) / d;
    let centre = a + off;
    Some(Ball {
        centre,
        radius: off
            .length()
            .max((b - centre).length())
            .max((c - centre).length()),
    })
}

/// The circumsphere of a tetrahedron, `None` when the points are (nearly) coplanar.
fn circum4(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> Option<Ball> {
    let (u, v, w) = (b - a, c - a, d - a);
    let det = 2.0 * u.dot(v.cross(w));
    let scale = u.length() * v.length() * w.length();
    if det.abs() <= 1e-12 * scale {
        return None;
    }
    let off = (u.length_squared() * v.cross(w)
        + v.length_squared() * w.cross(u)
        + w.length_squared() * u.cross(v))
        / det;
    let centre = a + off;
    let radius = [a, b, c, d]
        .iter()
        .map(|p| (*p - centre).length())
        .fold(0.0, f64::max);
    Some(Ball { centre, radius })
}

/// The smallest of the balls through two or three of `s` that contains all of `s`.
fn best_subset(s: &[DVec3]) -> Ball {
    let mut best: Option<Ball> = None;
    let mut consider = |b: Ball| {
        if s.iter().all(|p| b.contains(*p)) && best.is_none_or(|x| b.radius < x.radius) {
            best = Some(b);
        }
    };
    for i in 0..s.len() {
        for j in i + 1..s.len() {
            consider(diameter(s[i], s[j]));
            for k in j + 1..s.len() {
                if let Some(b) = circum3(s[i], s[j], s[k]) {
                    consider(b);
                }
            }
        }
    }
    // Every point set is inside the ball about its centroid reaching its farthest point.
    best.unwrap_or_else(|| {
        let c = s.iter().copied().sum::<DVec3>() / s.len() as f64;
        Ball {
            centre: c,
            radius: s.iter().map(|p| (*p - c).length()).fold(0.0, f64::max),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contains_all_and_is_minimal_on_known_sets() {
        // The six axis points: the unit sphere.
        let pts = [
            Vec3::X,
            -Vec3::X,
            Vec3::Y,
            -Vec3::Y,
            Vec3::Z,
            -Vec3::Z,
            Vec3::splat(0.1),
        ];
        let b = miniball(&pts);
        assert!((b.radius - 1.0).abs() < 1e-9, "{b:?}");
        assert!(b.centre.length() < 1e-9);
        // A flat square grid (coplanar): the circumcircle of the corners.
        let mut grid = Vec::new();
        for i in 0..=10 {
            for j in 0..=10 {
                grid.push(Vec3::new(i as f32 * 0.2 - 1.0, j as f32 * 0.2 - 1.0, 3.0));
            }
        }
        let b = miniball(&grid);
        assert!((b.radius - 2f64.sqrt()).abs() < 1e-6, "{b:?}");
        // Random clouds: every point inside; no point-pair diameter ball is smaller.
        let mut rng = SplitMix64(7);
        for n in [1usize, 2, 3, 5, 50, 500] {
            let pts: Vec<Vec3> = (0..n).map(|_| rng.in_unit_ball() * 3.0).collect();
            let b = miniball(&pts);
            for p in &pts {
                assert!((p.as_dvec3() - b.centre).length() <= b.radius * (1.0 + 1e-6) + 1e-6);
            }
            let far = pts
                .iter()
                .flat_map(|a| pts.iter().map(move |c| (*a - *c).length()))
                .fold(0.0f32, f32::max);
            assert!(b.radius >= far as f64 / 2.0 - 1e-6);
            // Jung's theorem: at most diameter · sqrt(3/8).
            assert!(b.radius <= far as f64 * (3.0f64 / 8.0).sqrt() + 1e-6);
        }
    }
}
