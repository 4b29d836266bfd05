//! Bézier clipping on one polynomial in Bernstein form (bezier-clipping-metaballs.txt §3.1–3.2):
//! the first root in `[0, 1]` by clipping to the convex hull's crossing and splitting where
//! clipping stalls, and the power-to-Bernstein conversion it starts from.

use crate::kinds::metaballs::kernel::MAX_W_DEGREE;
use crate::kinds::metaballs::real::Real;

/// Highest Bernstein degree along a ray: `2 · MAX_W_DEGREE`.
pub const MAX_DEGREE: usize = 2 * MAX_W_DEGREE;

/// Iterations a finder may spend on one ray before it gives up (a miss).
pub const ITERATION_CAP: u32 = 20_000;

/// Bézier clipping's pending halves: (control points, lo, hi).
pub type HalfStack<R> = Vec<([R; MAX_DEGREE + 1], R, R)>;
/// Most halves Bézier clipping keeps pending; past it, it clips instead of splitting.
pub const MAX_PENDING_HALVES: usize = 48;

pub(crate) const BINOMIAL: [[f64; MAX_DEGREE + 1]; MAX_DEGREE + 1] = {
    let mut c = [[0.0; MAX_DEGREE + 1]; MAX_DEGREE + 1];
    let mut n = 0;
    while n <= MAX_DEGREE {
        c[n][0] = 1.0;
        let mut k = 1;
        while k <= n {
            c[n][k] = c[n - 1][k - 1] + if k < n { c[n - 1][k] } else { 0.0 };
            k += 1;
        }
        n += 1;
    }
    c
};

/// `TO_BERNSTEIN[n][j][i] = C(j, i) / C(n, i)`: power to Bernstein coefficients of degree `n`.
const TO_BERNSTEIN: [[[f64; MAX_DEGREE + 1]; MAX_DEGREE + 1]; MAX_DEGREE + 1] = {
    let mut m = [[[0.0; MAX_DEGREE + 1]; MAX_DEGREE + 1]; MAX_DEGREE + 1];
    let mut n = 0;
    while n <= MAX_DEGREE {
        let mut j = 0;
        while j <= n {
            let mut i = 0;
            while i <= j {
                m[n][j][i] = BINOMIAL[j][i] / BINOMIAL[n][i];
                i += 1;
            }
            j += 1;
        }
        n += 1;
    }
    m
};

/// `b_j = Σ_{i ≤ j} C(j, i) / C(n, i) · p_i` for `p(v) = Σ p_i v^i` on `[0, 1]`.
#[inline(always)]
pub fn power_to_bernstein<R: Real>(poly: &[R], n: usize, out: &mut [R]) {
    let m = &TO_BERNSTEIN[n];
    for j in 0..=n {
        let mut acc = R::default();
        for (i, &pi) in poly.iter().enumerate().take(j + 1) {
            acc = acc + R::of(m[j][i]) * pi;
        }
        out[j] = acc;
    }
}

/// De Casteljau at `v`: the control points of `[0, v]` into `left`, `[v, 1]` into `right`.
#[inline(always)]
pub(crate) fn de_casteljau<R: Real>(b: &[R], n: usize, v: R, left: &mut [R], right: &mut [R]) {
    let mut tmp = [R::default(); MAX_DEGREE + 1];
    tmp[..=n].copy_from_slice(&b[..=n]);
    let u = R::of(1.0) - v;
    for r in 0..=n {
        left[r] = tmp[0];
        right[n - r] = tmp[n - r];
        for i in 0..n - r {
            tmp[i] = u * tmp[i] + v * tmp[i + 1];
        }
    }
}

/// The smallest `v ∈ [0, 1]` where the Bernstein polynomial `b` reaches zero from below
/// (`b_0 ≥ 0` gives 0), to within `tol_v`; `None` when it stays negative.
#[inline(always)]
pub fn bezier_first_root<R: Real>(
    b: &[R; MAX_DEGREE + 1],
    n: usize,
    tol_v: R,
    iters: &mut u32,
    halves: &mut HalfStack<R>,
) -> Option<R> {
    first_root_or_piece(b, n, tol_v, iters, halves, None)
}

/// [`bezier_first_root`], except that with `defer` an isolated piece is not solved: it goes
/// into `defer` (its `a`, `h` left for the caller) and the piece's start `lo` comes back, a
/// placeholder for the root found later (the `lanes` module solves such pieces together).
#[inline(always)]
pub(crate) fn first_root_or_piece<R: Real>(
    b: &[R; MAX_DEGREE + 1],
    n: usize,
    tol_v: R,
    iters: &mut u32,
    halves: &mut HalfStack<R>,
    mut defer: Option<&mut Option<Piece<R>>>,
) -> Option<R> {
    let zero = R::default();
    let inv_n = R::of(1.0 / n.max(1) as f64);
    // Pending halves, nearest last popped first.
    halves.clear();
    let mut cur = (*b, zero, R::of(1.0));
    loop {
        let (ref mut c, ref mut lo, ref mut hi) = cur;
        *iters += 1;
        let mut done = *iters > ITERATION_CAP;
        if c[0] >= zero {
            return Some(*lo);
        }
        if !done && c[..=n].iter().all(|&x| x < zero) {
            done = true; // the hull lies below the axis: no root here
        }
        if !done && isolated(c, n) {
            if let Some(slot) = defer.as_deref_mut() {
                *slot = Some(Piece {
                    c: *c,
                    n,
                    lo: *lo,
                    hi: *hi,
                    tol_v,
                    iters: *iters,
                    a: zero,
                    h: zero,
                });
                return Some(*lo);
            }
            return isolated_root(c, n, *lo, *hi, tol_v, iters);
        }
        if !done {
            // Where the convex hull of (k/n, c_k) meets the axis: over every segment from a
            // negative to a non-negative control point.
            let (mut xl, mut xr) = (R::of(1.0), zero);
            for i in 0..=n {
                if c[i] >= zero {
                    continue;
                }
                for j in 0..=n {
                    if c[j] < zero {
                        continue;
                    }
                    let (xi, xj) = (R::of(i as f64) * inv_n, R::of(j as f64) * inv_n);
                    let x = xi + (xj - xi) * (-c[i]) / (c[j] - c[i]);
                    xl = xl.min(x);
                    xr = xr.max(x);
                }
            }
            let (xl, xr) = (xl.max(zero), xr.min(R::of(1.0)));
            let width = *hi - *lo;
            let converged = width * (xr - xl) <= tol_v || width <= tol_v;
            let mut left = [zero; MAX_DEGREE + 1];
            let mut right = [zero; MAX_DEGREE + 1];
            if !converged && xr - xl > R::of(0.8) && halves.len() < MAX_PENDING_HALVES {
                // Clipping stalls (several roots or a flat stretch): split in half.
                de_casteljau(c, n, R::of(0.5), &mut left, &mut right);
                let mid = *lo + width * R::of(0.5);
                halves.push((right, mid, *hi));
                *c = left;
                *hi = mid;
                continue;
            }
            // Keep [xl, xr]: cut at xr, then cut the left part at xl / xr.
            de_casteljau(c, n, xr, &mut left, &mut right);
            let inner = if xr > zero { xl / xr } else { zero };
            let mut l2 = [zero; MAX_DEGREE + 1];
            de_casteljau(&left, n, inner, &mut l2, c);
            let new_lo = *lo + width * xl;
            *hi = *lo + width * xr;
            *lo = new_lo;
            if !converged {
                continue;
            }
            // The hull meets the axis on a stretch narrower than the tolerance, which alone
            // proves no root: the control polygon can poke above the axis where the curve
            // stays well below it (the `blobs` demo's section polygon [-0.47, -0.42, -0.27,
            // -0.065, +7·10⁻⁷, -0.023, -0.069], whose curve peaks at -0.03, reported a surface
            // there). The ends of the clipped polygon are the curve's own values: one at the
            // axis (up to what the subdivisions may have rounded it by, a few hundred units
            // in the last place of the section's largest control point) puts the first root
            // within the stretch, so within the tolerance; a polygon wholly below the axis
            // proves the curve below it; an inner point at the axis alone decides nothing,
            // and clipping goes on until the stretch is so short that the curve lies within
            // rounding of its polygon.
            let scale = b[..=n].iter().fold(zero, |m, &x| m.max(x.abs()));
            let floor = -(R::EPSILON * R::of(512.0) * scale);
            if c[0].max(c[n]) >= floor {
                return Some(*lo);
            }
            if c[..=n].iter().any(|&x| x >= floor) {
                if *hi - *lo <= R::EPSILON * R::of(64.0) {
                    return Some(*lo);
                }
                continue;
            }
        }
        if *iters > ITERATION_CAP {
            return None;
        }
        match halves.pop() {
            Some(half) => cur = half,
            None => return None,
        }
    }
}

/// Whether the control points are negative up to some index and non-negative from it on,
/// ending positive: one sign change and a positive end, so (Descartes' rule of signs for the
/// Bernstein basis) exactly one root in `(0, 1)`, a simple one.
#[inline(always)]
fn isolated<R: Real>(c: &[R; MAX_DEGREE + 1], n: usize) -> bool {
    let zero = R::default();
    if !(c[n] > zero) {
        return false;
    }
    let mut k = 0;
    while k < n && c[k] < zero {
        k += 1;
    }
    c[k..=n].iter().all(|&x| x >= zero)
}

/// The one root in `(0, 1)` of the Bernstein polynomial `c` ([`isolated`]), mapped to
/// `[lo, hi]`: regula falsi with Anderson and Björck's modification narrows the bracket
/// `g(a) < 0 ≤ g(b)` until it is within `tol_v` (of the whole `[0, 1]`), and the chord across
/// it gives the root. Each evaluation (the Bernstein form by Horner's rule in `v` with the
/// powers of `1 - v` alongside: `2n` multiplications and `n` additions, no division and no
/// branch) counts as an iteration. Clipping would converge about as fast here, but each of its
/// iterations costs two de Casteljau subdivisions and the hull's crossings over every pair of
/// control points.
#[inline(always)]
pub(crate) fn isolated_root<R: Real>(
    c: &[R; MAX_DEGREE + 1],
    n: usize,
    lo: R,
    hi: R,
    tol_v: R,
    iters: &mut u32,
) -> Option<R> {
    let (zero, one, half) = (R::default(), R::of(1.0), R::of(0.5));
    let mut d = [zero; MAX_DEGREE + 1];
    for k in 0..=n {
        d[k] = c[k] * R::of(BINOMIAL[n][k]);
    }
    // `Σ d_k v^k (1 - v)^(n-k)`: after the step for `k`, `h` is `Σ_{j ≥ k} d_j v^(j-k)
    // (1 - v)^(n-j)`, each term at most `|d_j|` (`v` and `1 - v` lie in `[0, 1]`), and what
    // each step rounds is scaled by `v` in the steps after it; the chain through `h` is one
    // multiply and one add a step.
    let eval = |v: R| -> R {
        let u = one - v;
        let mut h = d[n];
        let mut up = one;
        for k in (0..n).rev() {
            up = up * u;
            h = h * v + d[k] * up;
        }
        h
    };
    let width = hi - lo;
    // Each evaluation lands at least half the tolerance inside the bracket, so a converging
    // secant closes it with one step past the root instead of creeping up to it.
    let nudge = half * tol_v / width;
    // `ga`, `gb`: the polynomial at the bracket's ends; `fa`, `fb`: the values the secant
    // uses, an end's scaled down each time it is kept.
    let (mut a, mut ga, mut b, mut gb) = (zero, c[0], one, c[n]);
    let (mut fa, mut fb) = (ga, gb);
    let mut side = 0i8;
    loop {
        if width * (b - a) <= tol_v {
            // The root lies in the bracket, and so does the chord's crossing: within `tol_v`
            // of it, and far closer where the curve is nearly straight across the bracket
            // (its lower end where rounding, or a value past `f32`'s range, puts it outside).
            let chord = a + (b - a) * (ga / (ga - gb));
            let v = if a <= chord && chord <= b { chord } else { a };
            return Some(lo + width * v);
        }
        if *iters > ITERATION_CAP {
            return None;
        }
        *iters += 1;
        let secant = a + (b - a) * (fa / (fa - fb));
        let mut x = secant.max(a + nudge).min(b - nudge);
        if !(a < x && x < b) {
            x = half * (a + b);
            if !(a < x && x < b) {
                return Some(lo + width * a); // the precision is exhausted
            }
        }
        let gx = eval(x);
        // Anderson–Björck: an end kept twice in a row has its value scaled down.
        if gx < zero {
            if side < 0 {
                let m = one - gx / fa;
                fb = fb * if m > zero { m } else { half };
            }
            (a, ga, fa, side) = (x, gx, gx, -1);
        } else {
            if side > 0 {
                let m = one - gx / fb;
                fa = fa * if m > zero { m } else { half };
            }
            (b, gb, fb, side) = (x, gx, gx, 1);
        }
    }
}

/// An isolated piece whose root was set aside: what `isolated_root` takes, the section's
/// iterations so far, and the section's map from the piece's `v` to `t` (`a + h v`).
#[derive(Clone, Copy, Debug)]
pub struct Piece<R> {
    /// Bernstein control points of degree `n`, one sign change, the last positive.
    pub c: [R; MAX_DEGREE + 1],
    pub n: usize,
    /// The piece's stretch of the section's `[0, 1]`.
    pub lo: R,
    pub hi: R,
    pub tol_v: R,
    /// The section's iterations when the piece was set aside.
    pub iters: u32,
    /// The section's start and length.
    pub a: R,
    pub h: R,
}

impl<R: Real> Piece<R> {
    /// The piece's root as a ray parameter and the section's iterations, one at a time: what
    /// the search would have returned had it not set the piece aside.
    pub fn solve_one(&self) -> (Option<R>, u32) {
        let mut iters = self.iters;
        let v = isolated_root(&self.c, self.n, self.lo, self.hi, self.tol_v, &mut iters);
        (v.map(|v| self.a + self.h * v), iters)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The root of a Bernstein polynomial in `(0, 1)` where it turns from negative to
    /// non-negative, by `f64` bisection on the sum of its terms `c_k C(n, k) v^k (1 - v)^(n-k)`
    /// (binomials by their product formula; no Horner's rule, no secant).
    fn reference_root(c: &[f64], n: usize) -> f64 {
        bisect(|v| bernstein(c, n, v), 0.0, 1.0, 200)
    }

    /// Control points negative before index `k0`, non-negative from it, the last positive.
    fn isolated_points() -> impl Strategy<Value = (usize, Vec<f64>)> {
        (2usize..=MAX_DEGREE).prop_flat_map(|n| {
            (1usize..=n).prop_flat_map(move |k0| {
                (
                    prop::collection::vec(-10.0f64..-0.01, k0),
                    prop::collection::vec(0.0f64..10.0, n - k0),
                    0.01f64..10.0,
                )
                    .prop_map(move |(neg, nonneg, last)| {
                        let mut c = neg;
                        c.extend(nonneg);
                        c.push(last);
                        (n, c)
                    })
            })
        })
    }

    proptest! {
        #[test]
        fn an_isolated_root_is_the_reference_root_within_the_tolerance((n, c) in isolated_points()) {
            let truth = reference_root(&c, n);
            let mut points = [0.0f64; MAX_DEGREE + 1];
            points[..=n].copy_from_slice(&c);
            prop_assert!(isolated(&points, n));
            let mut iters = 0;
            let v = bezier_first_root(&points, n, 1e-10, &mut iters, &mut Vec::new()).expect("a root");
            prop_assert!((v - truth).abs() <= 1e-10, "f64: {} against {}", v, truth);
            prop_assert!(iters < 100, "{} iterations", iters);
            let mut singles = [0.0f32; MAX_DEGREE + 1];
            for k in 0..=n {
                singles[k] = c[k] as f32;
            }
            let singles_truth = reference_root(&singles.map(f64::from), n);
            let mut iters = 0;
            let v = bezier_first_root(&singles, n, 1e-4, &mut iters, &mut Vec::new()).expect("a root");
            prop_assert!((v as f64 - singles_truth).abs() <= 1e-4, "f32: {} against {}", v, singles_truth);
        }
    }

    /// The Bernstein polynomial of `c` at `v`, term by term in `f64`, its binomials by their
    /// product formula (not the finder's table).
    fn bernstein(c: &[f64], n: usize, v: f64) -> f64 {
        let choose = |k: usize| (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64);
        (0..=n)
            .map(|k| c[k] * choose(k) * v.powi(k as i32) * (1.0 - v).powi((n - k) as i32))
            .sum()
    }

    /// Where `g` turns from negative to non-negative in `[lo, hi]` (`g(lo) < 0 ≤ g(hi)`),
    /// by `steps` bisections.
    fn bisect(g: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64, steps: usize) -> f64 {
        for _ in 0..steps {
            let mid = 0.5 * (lo + hi);
            if g(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }

    /// The largest of `c`'s curve over 4,097 even samples of `[0, 1]`.
    fn sampled_max(c: &[f64], n: usize) -> f64 {
        (0..=4096)
            .map(|i| bernstein(c, n, i as f64 / 4096.0))
            .fold(f64::MIN, f64::max)
    }

    /// Control points below the axis but one inner point, a hair above it: the hull meets
    /// the axis on a sliver around that point while the curve stays well below (the shape of
    /// the `blobs` demo's false hits).
    fn poked_polygons() -> impl Strategy<Value = (usize, Vec<f64>)> {
        (2usize..=MAX_DEGREE).prop_flat_map(|n| {
            (
                prop::collection::vec(-1.0f64..-0.05, n + 1),
                1..n,
                1e-9f64..1e-5,
            )
                .prop_map(move |(mut c, k, poke)| {
                    c[k] = poke;
                    (n, c)
                })
        })
    }

    /// The first root of `c`'s curve: `Ok(None)` where the curve stays 10⁻⁴ below the axis,
    /// `Err` where its first approach to the axis is no clear crossing (a start on the axis,
    /// a touch, a slope under 0.01). Dense samples in `f64` (8,192 of them: between two, a
    /// curve of these control points bends by under 10⁻⁶), then bisection.
    fn clear_first_root(c: &[f64], n: usize) -> Result<Option<f64>, ()> {
        const SAMPLES: usize = 8192;
        let g = |v: f64| bernstein(c, n, v);
        let x = |i: usize| i as f64 / SAMPLES as f64;
        let Some(i) = (0..=SAMPLES).find(|&i| g(x(i)) >= -1e-4) else {
            return Ok(None);
        };
        let end = (i + 8).min(SAMPLES);
        if i == 0 || g(x(end)) < 0.0 {
            return Err(());
        }
        let hi = bisect(g, x(i - 1), x(end), 100);
        let slope = (g((hi + 1e-6).min(1.0)) - g(hi - 1e-6)) / 2e-6;
        if slope < 0.01 {
            return Err(());
        }
        Ok(Some(hi))
    }

    /// Polygons with inner control points above the axis, ends below it.
    fn raised_polygons() -> impl Strategy<Value = (usize, Vec<f64>)> {
        (2usize..=MAX_DEGREE).prop_flat_map(|n| {
            prop::collection::vec(-1.0f64..0.5, n + 1).prop_map(move |mut c| {
                c[0] = -c[0].abs() - 0.01;
                c[n] = -c[n].abs() - 0.01;
                (n, c)
            })
        })
    }

    /// Whether Bézier clipping, in `f64` and in `f32`, finds no root of `c` at `tol_v`.
    fn no_root_found(c: &[f64], n: usize, tol_v: f64) -> Result<(), TestCaseError> {
        let mut points = [0.0f64; MAX_DEGREE + 1];
        points[..=n].copy_from_slice(c);
        let singles = points.map(|x| x as f32);
        let mut iters = 0;
        let v = bezier_first_root(&points, n, tol_v, &mut iters, &mut Vec::new());
        prop_assert_eq!(v, None, "f64 at {} over {:?}", tol_v, c);
        let v = bezier_first_root(&singles, n, tol_v as f32, &mut iters, &mut Vec::new());
        prop_assert_eq!(v, None, "f32 at {} over {:?}", tol_v, singles);
        Ok(())
    }

    proptest! {
        #[test]
        fn a_control_point_poking_above_the_axis_is_no_root_where_the_curve_stays_below(
            (n, c) in poked_polygons()
        ) {
            prop_assume!(sampled_max(&c, n) < -1e-3);
            no_root_found(&c, n, 1e-4)?;
        }

        /// At a loose tolerance the hull's crossing is narrower than the tolerance from the
        /// first clip on, however far above the axis the polygon reaches.
        #[test]
        fn a_polygon_above_the_axis_is_no_root_at_a_loose_tolerance(
            (n, c) in raised_polygons()
        ) {
            prop_assume!(c.iter().any(|&x| x > 0.0) && sampled_max(&c, n) < -1e-3);
            for tol_v in [0.05, 0.2, 0.5, 1.0] {
                no_root_found(&c, n, tol_v)?;
            }
        }

        #[test]
        fn the_first_clear_root_of_any_polygon_is_found_and_no_other(
            n in 2usize..=MAX_DEGREE,
            c in prop::collection::vec(-1.0f64..1.0, MAX_DEGREE + 1),
        ) {
            let mut points = [0.0f64; MAX_DEGREE + 1];
            points[..=n].copy_from_slice(&c[..=n]);
            prop_assume!(points[0] < 0.0);
            let singles = points.map(|x| x as f32);
            let truth = clear_first_root(&singles.map(f64::from), n);
            prop_assume!(truth.is_ok());
            for tol_v in [1e-4f32, 0.05] {
                let mut iters = 0;
                let v = bezier_first_root(&singles, n, tol_v, &mut iters, &mut Vec::new());
                match truth {
                    Ok(Some(r)) => {
                        let v = v.map(f64::from);
                        let near = |v: f64| (v - r).abs() <= tol_v as f64 + 1e-4;
                        prop_assert!(v.is_some_and(near), "{:?} against {} at {} over {:?}", v, r, tol_v, singles);
                    }
                    _ => prop_assert_eq!(v, None, "no root at {} over {:?}", tol_v, singles),
                }
            }
        }
    }

    #[test]
    fn bezier_clipping_finds_the_smallest_root_of_a_cubic() {
        // (v - 0.2)(v - 0.5)(v - 0.9) · -1: negative at 0, roots at 0.2, 0.5, 0.9.
        let poly = [0.09, -0.73, 1.6, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut b = [0.0f64; MAX_DEGREE + 1];
        power_to_bernstein(&poly, 3, &mut b);
        let mut iters = 0;
        let v = bezier_first_root(
            &[-b[0], -b[1], -b[2], -b[3], 0.0, 0.0, 0.0, 0.0, 0.0],
            3,
            1e-12,
            &mut iters,
            &mut Vec::new(),
        )
        .expect("a root");
        assert!((v - 0.2).abs() < 1e-9, "v = {v}");
        assert!(iters < 40, "{iters} iterations");
    }

    #[test]
    fn de_casteljau_halves_evaluate_like_the_whole() {
        let b = [0.1f64, -0.5, 0.3, 0.9, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut l = [0.0; MAX_DEGREE + 1];
        let mut r = [0.0; MAX_DEGREE + 1];
        de_casteljau(&b, 3, 0.3, &mut l, &mut r);
        assert!((l[3] - r[0]).abs() < 1e-12);
        let eval = |c: &[f64], v: f64| {
            (0..=3)
                .map(|k| BINOMIAL[3][k] * v.powi(k as i32) * (1.0 - v).powi(3 - k as i32) * c[k])
                .sum::<f64>()
        };
        assert!((eval(&b, 0.15) - eval(&l, 0.5)).abs() < 1e-12);
        assert!((eval(&b, 0.65) - eval(&r, 0.5)).abs() < 1e-12);
    }
}
