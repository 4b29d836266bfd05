//! Isolated roots in lanes: the regula falsi of [`bezier`](super::bezier)'s isolated pieces
//! for up to [`LANES`] rays at once.
//!
//! Why: nearly every Bézier search ends on a piece whose control points change sign once
//! (one simple root), which regula falsi then narrows in about four evaluations, each a
//! Horner's rule of `2n` multiplications waiting on the one before, with two divisions and a
//! branch between them. One ray at a time that is a chain of latencies. A primary packet
//! instead sets each ray's isolated piece aside ([`Piece`]; the ray's hit is known to lie in
//! it, so the ray is done) and solves the tile's pieces [`LANES`] at a time: the evaluations
//! run across the lanes (structure-of-arrays, a loop the compiler vectorizes), and the lanes'
//! independent chains overlap.
//!
//! Each lane performs [`bezier::isolated_root`](super::bezier)'s operations in its order, so
//! its root and iteration count are the scalar ones bit for bit (test
//! `lanes_give_the_scalar_roots_bit_for_bit`); a lane that has finished only idles.

pub use crate::kinds::metaballs::bezier::Piece;
use crate::kinds::metaballs::bezier::{BINOMIAL, ITERATION_CAP, MAX_DEGREE};
use crate::kinds::metaballs::real::Real;

/// Pieces solved together.
pub const LANES: usize = 8;

/// Each piece's root as a ray parameter (`None` past the iteration cap, as `isolated_root`)
/// and the section's iterations after it, into `out` (cleared first). Pieces of one degree
/// run in lanes, [`LANES`] at a time; any other degree one by one.
pub fn solve<R: Real>(pieces: &[Piece<R>], out: &mut Vec<(Option<R>, u32)>) {
    out.clear();
    let Some(first) = pieces.first() else {
        return;
    };
    let n = first.n;
    for chunk in pieces.chunks(LANES) {
        if chunk.iter().all(|p| p.n == n) {
            let mut lane_out = [(None, 0); LANES];
            solve_lanes(chunk, n, &mut lane_out);
            out.extend_from_slice(&lane_out[..chunk.len()]);
        } else {
            out.extend(chunk.iter().map(Piece::solve_one));
        }
    }
}

/// `isolated_root` on up to [`LANES`] pieces of degree `n` in lockstep.
#[inline(always)]
fn solve_lanes<R: Real>(pieces: &[Piece<R>], n: usize, out: &mut [(Option<R>, u32); LANES]) {
    let (zero, one, half) = (R::default(), R::of(1.0), R::of(0.5));
    let m = pieces.len();
    // Per lane: the scaled control points (`d[k][lane]`), the bracket and its values.
    let mut d = [[zero; LANES]; MAX_DEGREE + 1];
    let (mut lo, mut width, mut tol_v, mut nudge) =
        ([zero; LANES], [one; LANES], [zero; LANES], [zero; LANES]);
    let (mut a, mut ga, mut b, mut gb) = ([zero; LANES], [zero; LANES], [one; LANES], [one; LANES]);
    let mut iters = [0u32; LANES];
    let mut active = [false; LANES];
    for (l, p) in pieces.iter().enumerate() {
        for k in 0..=n {
            d[k][l] = p.c[k] * R::of(BINOMIAL[n][k]);
        }
        lo[l] = p.lo;
        width[l] = p.hi - p.lo;
        tol_v[l] = p.tol_v;
        nudge[l] = half * p.tol_v / width[l];
        (ga[l], gb[l]) = (p.c[0], p.c[n]);
        iters[l] = p.iters;
        active[l] = true;
    }
    let (mut fa, mut fb) = (ga, gb);
    let mut side = [0i8; LANES];
    let mut x = [half; LANES];
    loop {
        // The bracket's tests, as `isolated_root` makes them before each evaluation.
        let mut any = false;
        for l in 0..m {
            if !active[l] {
                continue;
            }
            if width[l] * (b[l] - a[l]) <= tol_v[l] {
                let chord = a[l] + (b[l] - a[l]) * (ga[l] / (ga[l] - gb[l]));
                let v = if a[l] <= chord && chord <= b[l] {
                    chord
                } else {
                    a[l]
                };
                out[l] = (Some(lo[l] + width[l] * v), iters[l]);
                active[l] = false;
                continue;
            }
            if iters[l] > ITERATION_CAP {
                out[l] = (None, iters[l]);
                active[l] = false;
                continue;
            }
            iters[l] += 1;
            let secant = a[l] + (b[l] - a[l]) * (fa[l] / (fa[l] - fb[l]));
            let mut xl = secant.max(a[l] + nudge[l]).min(b[l] - nudge[l]);
            if !(a[l] < xl && xl < b[l]) {
                xl = half * (a[l] + b[l]);
                if !(a[l] < xl && xl < b[l]) {
                    out[l] = (Some(lo[l] + width[l] * a[l]), iters[l]);
                    active[l] = false;
                    continue;
                }
            }
            x[l] = xl;
            any = true;
        }
        if !any {
            break;
        }
        // The evaluations, across the lanes: `Σ d_k x^k (1 - x)^(n-k)` by Horner's rule in `x`
        // with the powers of `1 - x` alongside (idle lanes compute a value nobody reads).
        let mut g = [zero; LANES];
        let mut up = [one; LANES];
        let mut u = [zero; LANES];
        for l in 0..LANES {
            u[l] = one - x[l];
            g[l] = d[n][l];
        }
        for k in (0..n).rev() {
            for l in 0..LANES {
                up[l] = up[l] * u[l];
                g[l] = g[l] * x[l] + d[k][l] * up[l];
            }
        }
        // Anderson–Björck: an end kept twice in a row has its value scaled down.
        for l in 0..m {
            if !active[l] {
                continue;
            }
            let gx = g[l];
            if gx < zero {
                if side[l] < 0 {
                    let mm = one - gx / fa[l];
                    fb[l] = fb[l] * if mm > zero { mm } else { half };
                }
                (a[l], ga[l], fa[l], side[l]) = (x[l], gx, gx, -1);
            } else {
                if side[l] > 0 {
                    let mm = one - gx / fb[l];
                    fa[l] = fa[l] * if mm > zero { mm } else { half };
                }
                (b[l], gb[l], fb[l], side[l]) = (x[l], gx, gx, 1);
            }
        }
    }
    for (l, p) in pieces.iter().enumerate() {
        out[l].0 = out[l].0.map(|v| p.a + p.h * v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A piece of degree `n` with one sign change (negative before `k0`, the last positive).
    fn piece() -> impl Strategy<Value = Piece<f32>> {
        (2usize..=MAX_DEGREE).prop_flat_map(|n| {
            (1usize..=n).prop_flat_map(move |k0| {
                (
                    prop::collection::vec(-10.0f32..-0.01, k0),
                    prop::collection::vec(0.0f32..10.0, n - k0),
                    0.01f32..10.0,
                    0.0f32..0.5,
                    0.5f32..1.0,
                    prop::sample::select(vec![1e-2f32, 1e-4, 1e-6, 1e-9]),
                    0u32..40,
                    -5.0f32..5.0,
                    0.01f32..3.0,
                )
                    .prop_map(
                        move |(neg, nonneg, last, lo, hi, tol_v, iters, a, h)| {
                            let mut c = [0.0; MAX_DEGREE + 1];
                            for (k, v) in neg.iter().chain(&nonneg).chain([&last]).enumerate() {
                                c[k] = *v;
                            }
                            Piece {
                                c,
                                n,
                                lo,
                                hi,
                                tol_v,
                                iters,
                                a,
                                h,
                            }
                        },
                    )
            })
        })
    }

    proptest! {
        /// Batches of one degree and of mixed degrees, of every length up to two chunks: every
        /// root and iteration count is `isolated_root`'s.
        #[test]
        fn lanes_give_the_scalar_roots_bit_for_bit(
            pieces in prop::collection::vec(piece(), 1..=2 * LANES),
            same_degree in any::<bool>(),
        ) {
            let mut pieces = pieces;
            if same_degree {
                // Bring every piece to the first one's degree by padding with its last point
                // (still one sign change, the last positive).
                let n = pieces[0].n;
                for p in &mut pieces {
                    if p.n < n {
                        for k in p.n + 1..=n {
                            p.c[k] = p.c[p.n];
                        }
                    }
                    p.n = n;
                    let k0 = (0..=n).find(|&k| p.c[k] >= 0.0).unwrap_or(n);
                    for k in k0..=n {
                        p.c[k] = p.c[k].abs().max(0.01);
                    }
                }
            }
            let mut got = Vec::new();
            solve(&pieces, &mut got);
            prop_assert_eq!(got.len(), pieces.len());
            for (p, &(t, iters)) in pieces.iter().zip(&got) {
                let (want_t, want_iters) = p.solve_one();
                prop_assert_eq!(t.map(f32::to_bits), want_t.map(f32::to_bits));
                prop_assert_eq!(iters, want_iters);
            }
        }
    }

    /// A piece at the iteration cap gives up in a lane as it does alone.
    #[test]
    fn a_lane_past_the_cap_gives_up_like_the_scalar_search() {
        let mut c = [0.0f32; MAX_DEGREE + 1];
        c[..4].copy_from_slice(&[-1.0, -0.5, 0.5, 1.0]);
        let base = Piece {
            c,
            n: 3,
            lo: 0.0,
            hi: 1.0,
            tol_v: 1e-6,
            iters: 0,
            a: 0.0,
            h: 1.0,
        };
        let capped = Piece {
            iters: ITERATION_CAP + 1,
            ..base
        };
        let mut got = Vec::new();
        solve(&[base, capped, base], &mut got);
        assert_eq!(got[1], (None, ITERATION_CAP + 1));
        assert_eq!(got[1], capped.solve_one());
        assert!(got[0].0.is_some() && got[0] == got[2] && got[0] == base.solve_one());
    }
}
