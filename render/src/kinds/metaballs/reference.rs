//! The `f64` reference the tracer is checked against. It shares no code with the tracer: no
//! tree, no Bézier clipping, no pruning, nothing from `roots`, `bezier`, `tree` or `engine`;
//! only the scene's data (`scene`) and the kernels' defining formulas, written out here again.
//!
//! How it works (bezier-clipping-metaballs.txt §2–3 give the field; the method is textbook):
//! every kernel is a polynomial in `s = |M (p - c)|²` on `s < 1`, and along `o + t d` each
//! ball's `s` is a quadratic in `t`, so between consecutive ball entries and exits the field
//! is one exact polynomial in `t` (degree at most 8). On each such section, mapped to
//! `v ∈ [0, 1]`, the field minus the isovalue is built in power form; if it is `≥ 0` at the
//! section's start that is the answer, otherwise a certified interval search finds the first
//! point where it can reach 0: the Taylor form about an interval's midpoint bounds the
//! polynomial on the interval, intervals whose bound stays below 0 (rounding included) are
//! dropped, the others halved nearer half first, down to a few ulps of `t`. A root of even
//! multiplicity (a tangent ray) is never dropped, so the reference does not lose a grazing hit
//! the exact field has. (A Sturm sequence was tried first: in `f64` its remainders lose the
//! count for degree-8 kernels near tangencies and gave inconsistent levels; see the tests.)

use crate::kinds::metaballs::kernel::Kernel;
use crate::kinds::metaballs::scene::{MetaballScene, Shape};
use glam::{DMat3, DQuat, DVec3};

/// Highest degree of the field in `t` on one section (`(1 - s)^4`, `s` quadratic in `t`).
const MAX_DEGREE: usize = 8;

/// A polynomial in power form, lowest coefficient first, at most `MAX_DEGREE`.
#[derive(Clone, Copy, Debug)]
struct Poly {
    c: [f64; MAX_DEGREE + 1],
    /// Number of coefficients in use (degree + 1); 0 for the zero polynomial.
    len: usize,
}

impl Poly {
    const ZERO: Poly = Poly {
        c: [0.0; MAX_DEGREE + 1],
        len: 0,
    };

    fn eval(&self, x: f64) -> f64 {
        self.c[..self.len]
            .iter()
            .rev()
            .fold(0.0, |acc, &k| acc * x + k)
    }

    fn mul_quadratic(&self, q: [f64; 3]) -> Poly {
        let mut out = Poly::ZERO;
        if self.len == 0 {
            return out;
        }
        for i in 0..self.len {
            for (j, qj) in q.iter().enumerate() {
                out.c[i + j] += self.c[i] * qj;
            }
        }
        out.len = (self.len + 2).min(MAX_DEGREE + 1);
        out
    }
}

/// The kernel as `Σ k_j s^j` (the seeds' own forms; deliberately not `Kernel`'s `w` form).
fn kernel_in_s(kernel: Kernel) -> [f64; 5] {
    match kernel {
        // bezier-clipping-metaballs.txt eq. 4.
        Kernel::Wyvill => [1.0, -22.0 / 9.0, 17.0 / 9.0, -4.0 / 9.0, 0.0],
        // ibid. eq. 3: (1 - s)².
        Kernel::Quartic => [1.0, -2.0, 1.0, 0.0, 0.0],
        // metaballs-tutorial.txt §III, r_tut² = s/2: s²/4 - s/2 + 1/4.
        Kernel::Tutorial => [0.25, -0.5, 0.25, 0.0, 0.0],
        // (1 - s)^α by the binomial theorem.
        Kernel::Power { alpha } => {
            let mut k = [0.0; 5];
            let alpha = (alpha as usize).clamp(1, 4);
            let mut binom = 1.0;
            for (j, kj) in k.iter_mut().enumerate().take(alpha + 1) {
                *kj = if j % 2 == 0 { binom } else { -binom };
                binom = binom * (alpha - j) as f64 / (j + 1) as f64;
            }
            k
        }
    }
}

/// One ball the reference ray crosses.
#[derive(Clone, Copy, Debug)]
struct Crossed {
    index: u32,
    center: DVec3,
    /// Maps the support to the unit sphere.
    m: DMat3,
    strength: f64,
    t0: f64,
    t1: f64,
    /// Where `s` is smallest along the ray.
    t_closest: f64,
}

/// One ray through a scene in `f64`: the balls it crosses, ready for repeated queries.
#[derive(Debug)]
pub struct ReferenceRay {
    origin: DVec3,
    dir: DVec3,
    balls: Vec<Crossed>,
    kernel: [f64; 5],
    t_min: f64,
    t_max: f64,
}

impl ReferenceRay {
    /// The balls of `scene` that `origin + t·dir` (`dir` normalised here) crosses within
    /// `[t_min, t_max]`.
    pub fn new(
        scene: &MetaballScene,
        origin: DVec3,
        dir: DVec3,
        t_min: f64,
        t_max: f64,
    ) -> ReferenceRay {
        let dir = dir.normalize();
        let mut balls = Vec::new();
        for (i, b) in scene.balls.iter().enumerate() {
            let center = b.center.as_dvec3();
            let r = b.radius as f64;
            let m = match b.shape {
                Shape::Sphere => DMat3::from_diagonal(DVec3::splat(1.0 / r)),
                Shape::Ellipsoid { axes, rotation } => {
                    let q = DQuat::from_xyzw(
                        rotation.x as f64,
                        rotation.y as f64,
                        rotation.z as f64,
                        rotation.w as f64,
                    )
                    .normalize();
                    DMat3::from_diagonal((r * axes.as_dvec3()).recip())
                        * DMat3::from_quat(q).transpose()
                }
            };
            // |e + t g|² = 1 with e = M (o - c), g = M d: solved about the closest point.
            let (e, g) = (m * (origin - center), m * dir);
            let gg = g.length_squared();
            if !(gg > 0.0) {
                continue;
            }
            let t_closest = -e.dot(g) / gg;
            let closest = (e + t_closest * g).length_squared();
            if !(closest < 1.0) {
                continue;
            }
            let half = ((1.0 - closest) / gg).sqrt();
            let (t0, t1) = (t_closest - half, t_closest + half);
            if t1 < t_min || t0 > t_max {
                continue;
            }
            balls.push(Crossed {
                index: i as u32,
                center,
                m,
                strength: b.strength as f64,
                t0,
                t1,
                t_closest,
            });
        }
        ReferenceRay {
            origin,
            dir,
            balls,
            kernel: kernel_in_s(scene.kernel),
            t_min,
            t_max,
        }
    }

    fn s_of(&self, b: &Crossed, p: DVec3) -> f64 {
        (b.m * (p - b.center)).length_squared()
    }

    fn kernel_at(&self, s: f64) -> f64 {
        if s >= 1.0 {
            return 0.0;
        }
        self.kernel.iter().rev().fold(0.0, |acc, &k| acc * s + k)
    }

    /// The field at `t`.
    pub fn field(&self, t: f64) -> f64 {
        let p = self.origin + t * self.dir;
        self.balls
            .iter()
            .map(|b| b.strength * self.kernel_at(self.s_of(b, p)))
            .sum()
    }

    /// The outward unit normal (against the field's gradient) at `t`, or `None` where the
    /// gradient vanishes.
    pub fn normal(&self, t: f64) -> Option<DVec3> {
        let p = self.origin + t * self.dir;
        let mut gradient = DVec3::ZERO;
        for b in &self.balls {
            let md = b.m * (p - b.center);
            let s = md.length_squared();
            if s >= 1.0 {
                continue;
            }
            let dfds = (1..5)
                .rev()
                .fold(0.0, |acc, j| acc * s + j as f64 * self.kernel[j]);
            gradient += b.strength * dfds * 2.0 * (b.m.transpose() * md);
        }
        let n = -gradient;
        (n.length_squared() > 0.0).then(|| n.normalize())
    }

    /// Indices of the balls the ray crosses.
    pub fn crossed(&self) -> impl Iterator<Item = u32> + '_ {
        self.balls.iter().map(|b| b.index)
    }

    /// Where the centres of the crossed balls project onto the ray (where `s` is smallest).
    pub fn projections(&self) -> impl Iterator<Item = f64> + '_ {
        self.balls.iter().map(|b| b.t_closest)
    }

    /// The first `t` in `[from, t_max]` with `F(t) ≥ isovalue`.
    pub fn first_at_least(&self, isovalue: f64, from: f64) -> Option<f64> {
        self.first_where(1.0, isovalue, from.max(self.t_min))
    }

    /// The first `t` in `[from, t_max]` with `F(t) < isovalue` (to `1e-12` in the field), or
    /// `t_max` when there is none: the exit of a stretch that starts at `from`.
    pub fn first_below(&self, isovalue: f64, from: f64) -> f64 {
        // F < T  ⇔  -F ≥ -T + 1e-12.
        self.first_where(-1.0, -isovalue + 1e-12, from.max(self.t_min))
            .unwrap_or(self.t_max)
    }

    /// The first `t` in `[lo, t_max]` with `sign · F(t) ≥ level`.
    fn first_where(&self, sign: f64, level: f64, lo: f64) -> Option<f64> {
        let hi = self.t_max;
        if !(lo <= hi) {
            return None;
        }
        let mut cuts: Vec<f64> = vec![lo, hi];
        for b in &self.balls {
            cuts.extend([b.t0, b.t1].into_iter().filter(|&t| lo < t && t < hi));
        }
        cuts.sort_by(f64::total_cmp);
        cuts.dedup();
        for w in cuts.windows(2) {
            let (a, b) = (w[0], w[1]);
            let poly = self.section_poly(sign, level, a, b);
            if poly.eval(0.0) >= 0.0 {
                return Some(a);
            }
            let v_tol = (4.0 * f64::EPSILON * a.abs().max(b.abs()) / (b - a)).max(1e-15);
            if let Some(v) = first_root(&poly, v_tol) {
                return Some(a + (b - a) * v);
            }
        }
        // The end of the range itself (a zero-length range has no section).
        (sign * self.field(hi) >= level).then_some(hi)
    }

    /// `sign · F(a + (b - a) v) - level` on `v ∈ [0, 1]`, in power form.
    fn section_poly(&self, sign: f64, level: f64, a: f64, b: f64) -> Poly {
        let h = b - a;
        let mid = 0.5 * (a + b);
        let mut total = Poly::ZERO;
        total.len = 1;
        total.c[0] = -level;
        for ball in &self.balls {
            // Active on the whole section (sections lie between consecutive entries/exits).
            if !(ball.t0 <= mid && mid <= ball.t1) {
                continue;
            }
            let e = ball.m * (self.origin + a * self.dir - ball.center);
            let g = ball.m * (h * self.dir);
            let s = [e.length_squared(), 2.0 * e.dot(g), g.length_squared()];
            // Σ k_j s^j by Horner in polynomials.
            let mut acc = Poly::ZERO;
            for &kj in self.kernel.iter().rev() {
                acc = acc.mul_quadratic(s);
                acc.c[0] += kj;
                acc.len = acc.len.max(1);
            }
            let q = sign * ball.strength;
            for k in 0..acc.len {
                total.c[k] += q * acc.c[k];
            }
            total.len = total.len.max(acc.len);
        }
        total
    }
}

/// The first `v` in `(0, 1]` where `p` may reach 0 (with `p(0) < 0`), to `v_tol`: a certified
/// interval search. On `[x, y]` the Taylor form about the midpoint `m`,
/// `p(m + u) = Σ b_k u^k`, bounds `p` by `p(m) + Σ_{k≥1} |b_k| r^k` (`r` the half width); an
/// interval whose bound (plus the rounding of its evaluation) stays below 0 holds no point
/// with `p ≥ 0` and is dropped, the others are halved, nearer half first. The first interval
/// narrower than `v_tol` that cannot be dropped is the answer (its upper end).
fn first_root(p: &Poly, v_tol: f64) -> Option<f64> {
    let rounding = 64.0 * f64::EPSILON * p.c[..p.len].iter().map(|c| c.abs()).sum::<f64>();
    let mut stack = vec![(0.0f64, 1.0f64)];
    let mut steps = 0u32;
    while let Some((x, y)) = stack.pop() {
        steps += 1;
        if steps > MAX_INTERVALS {
            // Only a polynomial that stays within rounding of 0 over a long stretch gets here;
            // its first undecided interval is as good an answer as any.
            return Some(y);
        }
        let m = 0.5 * (x + y);
        let r = 0.5 * (y - x);
        let b = taylor_at(p, m);
        let spread: f64 = (1..p.len).rev().fold(0.0, |acc, k| (acc + b[k].abs()) * r);
        if b[0] + spread + rounding < 0.0 {
            continue;
        }
        if y - x <= v_tol || !(x < m && m < y) {
            return Some(y);
        }
        stack.push((m, y));
        stack.push((x, m));
    }
    None
}

/// Intervals one search may visit before it settles for its first undecided one.
const MAX_INTERVALS: u32 = 100_000;

/// `b_k` with `p(m + u) = Σ b_k u^k` (repeated synthetic division by `u - m`).
fn taylor_at(p: &Poly, m: f64) -> [f64; MAX_DEGREE + 1] {
    let mut b = p.c;
    let n = p.len;
    for k in 0..n {
        for j in (k..n - 1).rev() {
            b[j] += m * b[j + 1];
        }
    }
    b
}

/// The first `t` in `[t_min, t_max]` with `F ≥ T` along `origin + t·dir` (`dir` is
/// normalised here), in `f64`.
pub fn reference_hit(
    scene: &MetaballScene,
    origin: DVec3,
    dir: DVec3,
    t_min: f64,
    t_max: f64,
    isovalue: f64,
) -> Option<f64> {
    ReferenceRay::new(scene, origin, dir, t_min, t_max).first_at_least(isovalue, t_min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::metaballs::scene::Metaball;
    use glam::Vec3;

    fn close(got: f64, want: f64) -> bool {
        (got - want).abs() <= 1e-9 * want.abs().max(1.0)
    }

    fn one_ball(kernel: Kernel, radius: f32, strength: f32) -> MetaballScene {
        MetaballScene::new(
            kernel,
            vec![Metaball::sphere(Vec3::ZERO, radius, strength, Vec3::ONE)],
        )
    }

    /// A ray from `(0, b, 10)` along `-z` against a ball whose isosurface has radius `r`.
    fn check_sphere(scene: &MetaballScene, isovalue: f64, r: f64) {
        for b in [0.0, 0.3 * r, 0.9 * r] {
            let ray = ReferenceRay::new(scene, DVec3::new(0.0, b, 10.0), DVec3::NEG_Z, 0.0, 100.0);
            let half = (r * r - b * b).sqrt();
            let hit = ray.first_at_least(isovalue, 0.0).expect("the ray hits");
            assert!(
                close(hit, 10.0 - half),
                "{:?} b={b}: {hit} vs {}",
                scene.kernel,
                10.0 - half
            );
            let exit = ray.first_below(isovalue, hit + 1e-9);
            assert!((exit - (10.0 + half)).abs() < 1e-6, "exit {exit}");
            let n = ray.normal(hit).expect("a gradient");
            let want = DVec3::new(0.0, b, half) / r;
            assert!((n - want).length() < 1e-9, "normal {n} vs {want}");
        }
        let miss = ReferenceRay::new(
            scene,
            DVec3::new(0.0, 1.01 * r, 10.0),
            DVec3::NEG_Z,
            0.0,
            100.0,
        );
        assert_eq!(miss.first_at_least(isovalue, 0.0), None);
    }

    #[test]
    fn one_ball_of_every_kernel_is_its_analytic_sphere() {
        // Wyvill: f(R/2) = 1/2 (bezier-clipping-metaballs.txt eq. 4).
        check_sphere(&one_ball(Kernel::Wyvill, 2.0, 1.0), 0.5, 1.0);
        // Quartic: q (1 - s)² = T.
        let s = 1.0 - (0.7f64 / 2.0).sqrt();
        check_sphere(&one_ball(Kernel::Quartic, 3.0, 2.0), 0.7, 3.0 * s.sqrt());
        // Tutorial: (1 - s)² / 4 = T.
        let s = 1.0 - (4.0f64 * 0.1).sqrt();
        check_sphere(&one_ball(Kernel::Tutorial, 1.5, 1.0), 0.1, 1.5 * s.sqrt());
        for alpha in 1..=4u8 {
            let s = 1.0 - (0.3f64 / 1.5).powf(1.0 / alpha as f64);
            check_sphere(
                &one_ball(Kernel::Power { alpha }, 2.5, 1.5),
                0.3,
                2.5 * s.sqrt(),
            );
        }
    }

    #[test]
    fn two_equal_balls_on_a_line_meet_where_the_sum_says() {
        let pair = |kernel| {
            MetaballScene::new(
                kernel,
                vec![
                    Metaball::sphere(Vec3::new(-0.5, 0.0, 0.0), 2.0, 1.0, Vec3::ONE),
                    Metaball::sphere(Vec3::new(0.5, 0.0, 0.0), 2.0, 1.0, Vec3::ONE),
                ],
            )
        };
        // Along the line, (1 - s)¹ kernels: F = 2 - 2 (x² + c²) / R² in the overlap.
        let scene = pair(Kernel::Power { alpha: 1 });
        let ray = ReferenceRay::new(&scene, DVec3::new(-10.0, 0.0, 0.0), DVec3::X, 0.0, 100.0);
        let x = (4.0f64 * (1.0 - 1.2 / 2.0) - 0.25).sqrt();
        let hit = ray.first_at_least(1.2, 0.0).expect("a hit");
        assert!(close(hit, 10.0 - x), "{hit} vs {}", 10.0 - x);
        // Across the line through the middle, Wyvill: 2 f(s) = 1 at s = 1/4.
        let scene = pair(Kernel::Wyvill);
        let ray = ReferenceRay::new(&scene, DVec3::new(0.0, 10.0, 0.0), DVec3::NEG_Y, 0.0, 100.0);
        let y = (4.0f64 * 0.25 - 0.25).sqrt();
        let hit = ray.first_at_least(1.0, 0.0).expect("a hit");
        assert!(close(hit, 10.0 - y), "{hit} vs {}", 10.0 - y);
    }

    #[test]
    fn a_tangent_ray_is_a_double_root_that_still_counts() {
        // (1 - s)¹ at T = 0.75: the isosurface is the sphere of radius R/2 = 1.
        let scene = one_ball(Kernel::Power { alpha: 1 }, 2.0, 1.0);
        let inside = ReferenceRay::new(
            &scene,
            DVec3::new(0.0, 1.0 - 1e-12, 10.0),
            DVec3::NEG_Z,
            0.0,
            100.0,
        );
        let hit = inside.first_at_least(0.75, 0.0).expect("a grazing hit");
        assert!((hit - 10.0).abs() < 1e-5, "{hit}");
        let outside = ReferenceRay::new(
            &scene,
            DVec3::new(0.0, 1.0 + 1e-9, 10.0),
            DVec3::NEG_Z,
            0.0,
            100.0,
        );
        assert_eq!(outside.first_at_least(0.75, 0.0), None);
        // A degree-two kernel: F - T has a double root at the tangent point, and the Sturm
        // count sees it.
        let scene = one_ball(Kernel::Quartic, 2.0, 1.0);
        let t = 0.5625; // (1 - 1/4)²: the sphere of radius 1
        let ray = ReferenceRay::new(&scene, DVec3::new(0.0, 1.0, 10.0), DVec3::NEG_Z, 0.0, 100.0);
        let hit = ray.first_at_least(t - 1e-12, 0.0).expect("a grazing hit");
        assert!((hit - 10.0).abs() < 1e-4, "{hit}");
    }

    #[test]
    fn levels_are_reached_in_order_near_tangencies() {
        // What a Sturm count in f64 got wrong: on grazing rays through a degree-8 field, the
        // first point at a higher level came before the first point at a lower one.
        let mut rng = crate::geom::rng::SplitMix64(7);
        for alpha in [2u8, 4] {
            let balls = (0..40)
                .map(|_| {
                    let c = Vec3::new(
                        rng.range(-3.0, 3.0),
                        rng.range(-3.0, 3.0),
                        rng.range(-3.0, 3.0),
                    );
                    let q = if rng.range(0.0, 1.0) < 0.25 {
                        -0.5
                    } else {
                        1.0
                    };
                    Metaball::sphere(c, rng.range(0.8, 2.0), q, Vec3::ONE)
                })
                .collect();
            let scene = MetaballScene::new(Kernel::Power { alpha }, balls);
            for _ in 0..300 {
                let o = DVec3::new(
                    rng.range(-9.0, 9.0) as f64,
                    rng.range(-9.0, 9.0) as f64,
                    12.0,
                );
                let target = DVec3::new(
                    rng.range(-3.0, 3.0) as f64,
                    rng.range(-3.0, 3.0) as f64,
                    0.0,
                );
                let ray = ReferenceRay::new(&scene, o, target - o, 0.0, 100.0);
                let levels = [0.29, 0.3, 0.3 + 1e-9, 0.31].map(|t| ray.first_at_least(t, 0.0));
                for w in levels.windows(2) {
                    if let (Some(lo), Some(hi)) = (w[0], w[1]) {
                        assert!(lo <= hi + 1e-12, "alpha {alpha}: {levels:?}");
                    } else {
                        assert!(
                            w[1].is_none(),
                            "a higher level reached, a lower not: {levels:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn the_kernels_in_s_are_the_kernels() {
        for kernel in Kernel::ALL {
            let k = kernel_in_s(kernel);
            for i in 0..=20 {
                let s = i as f64 / 20.0;
                let mine = k.iter().rev().fold(0.0, |acc, &c| acc * s + c);
                assert!(
                    (mine - kernel.value_f64(s)).abs() < 1e-12,
                    "{kernel:?} at {s}"
                );
            }
        }
    }
}
