//! Isolated roots in lanes: the regula falsi of [`bezier`](super::bezier)'s isolated pieces
//! for up to [`LANES`] rays at once.
//!
//! Why: nearly every Bézier search ends on a piece whose control points change sign once
//! (one simple root), which regula falsi then narrows in about four evaluations, each a
//! Horner's rule of `2n` multiplications waiting on the one before, with two divisions and a
//! branch between them. One ray at a time that is a chain of latencies. A primary packet
//! instead sets each ray's isolated piece aside ([`Piece`]; the ray's hit is known to lie in
//! it, so the ray is done) and solves the tile's pieces [`LANES`] at a time in `wide`'s
//! `f32x8` vectors (one AVX register, two SSE ones in the portable build): the evaluations,
//! divisions and bracket updates of eight rays per instruction, each lane's case picked by
//! masks. On 200,000 random degree-6 pieces (Intel Xeon, portable build) that took 11.3 ms
//! against 28.0 ms one piece at a time and 22.9 ms for the same lockstep over plain arrays,
//! whose branchy per-lane control the compiler left scalar.
//!
//! Each lane performs [`bezier::isolated_root`](super::bezier)'s operations in its order, so
//! its root and iteration count are the scalar ones bit for bit (test
//! `lanes_give_the_scalar_roots_bit_for_bit`); a lane that has finished only idles.

pub use crate::kinds::metaballs::bezier::Piece;
use crate::kinds::metaballs::bezier::{BINOMIAL, ITERATION_CAP, MAX_DEGREE};
use wide::{f32x8, CmpGt, CmpLe, CmpLt};

/// Pieces solved together.
pub const LANES: usize = 8;

/// Each piece's root as a ray parameter (`None` past the iteration cap, as `isolated_root`)
/// and the section's iterations after it, into `out` (cleared first). Pieces run in lanes,
/// [`LANES`] at a time, where a chunk's pieces all have the first piece's degree (a packet's
/// do: one kernel); a chunk that mixes degrees is solved one piece at a time.
pub fn solve(pieces: &[Piece<f32>], out: &mut Vec<(Option<f32>, u32)>) {
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

/// `f32::max`'s choice lane by lane (a NaN gives the other operand).
#[inline(always)]
fn max(x: f32x8, y: f32x8) -> f32x8 {
    let larger = x.cmp_lt(y).blend(y, x);
    x.is_nan().blend(y, larger)
}

/// `f32::min`'s choice lane by lane.
#[inline(always)]
fn min(x: f32x8, y: f32x8) -> f32x8 {
    let smaller = y.cmp_lt(x).blend(y, x);
    x.is_nan().blend(y, smaller)
}

/// `isolated_root` on up to [`LANES`] pieces of degree `n` in lockstep: the arithmetic in
/// vector lanes, each lane's case chosen by masks (the same operations and choices as the
/// scalar code's branches), and a lane's exits (a closed bracket, the cap, an exhausted
/// precision) decided from the masks one lane at a time.
#[inline(always)]
fn solve_lanes(pieces: &[Piece<f32>], n: usize, out: &mut [(Option<f32>, u32); LANES]) {
    let lane = |f: &dyn Fn(&Piece<f32>) -> f32, pad: f32| {
        let mut v = [pad; LANES];
        for (l, p) in pieces.iter().enumerate() {
            v[l] = f(p);
        }
        f32x8::from(v)
    };
    let mut d = [f32x8::ZERO; MAX_DEGREE + 1];
    for (k, dk) in d.iter_mut().enumerate().take(n + 1) {
        *dk = lane(&|p| p.c[k] * BINOMIAL[n][k] as f32, 0.0);
    }
    let (zero, one, half) = (f32x8::ZERO, f32x8::ONE, f32x8::splat(0.5));
    let lo = lane(&|p| p.lo, 0.0);
    let width = lane(&|p| p.hi - p.lo, 1.0);
    let tol_v = lane(&|p| p.tol_v, 1.0);
    let nudge = half * tol_v / width;
    let (mut a, mut b) = (zero, one);
    let (mut ga, mut gb) = (lane(&|p| p.c[0], -1.0), lane(&|p| p.c[n], 1.0));
    let (mut fa, mut fb) = (ga, gb);
    let mut side = zero;
    let mut iters = [0u32; LANES];
    for (l, p) in pieces.iter().enumerate() {
        iters[l] = p.iters;
    }
    let mut active: u32 = (1u32 << pieces.len()) - 1;
    loop {
        // The bracket's tests and the next point, as `isolated_root` makes them.
        let ba = b - a;
        let closed = (width * ba).cmp_le(tol_v).move_mask() as u32;
        let chord = a + ba * (ga / (ga - gb));
        let within = a.cmp_le(chord) & chord.cmp_le(b);
        let closed_root = (lo + width * within.blend(chord, a)).to_array();
        let secant = a + ba * (fa / (fa - fb));
        let step = min(max(secant, a + nudge), b - nudge);
        let step_inside = a.cmp_lt(step) & step.cmp_lt(b);
        let mid = half * (a + b);
        let mid_inside = a.cmp_lt(mid) & mid.cmp_lt(b);
        let x = step_inside.blend(step, mid);
        let exhausted = (!(step_inside | mid_inside)).move_mask() as u32;
        let exhausted_root = (lo + width * a).to_array();
        let mut left = active;
        while left != 0 {
            let l = left.trailing_zeros() as usize;
            left &= left - 1;
            let bit = 1u32 << l;
            if closed & bit != 0 {
                out[l] = (Some(closed_root[l]), iters[l]);
                active &= !bit;
            } else if iters[l] > ITERATION_CAP {
                out[l] = (None, iters[l]);
                active &= !bit;
            } else {
                iters[l] += 1;
                if exhausted & bit != 0 {
                    out[l] = (Some(exhausted_root[l]), iters[l]);
                    active &= !bit;
                }
            }
        }
        if active == 0 {
            break;
        }
        // `Σ d_k x^k (1 - x)^(n-k)` by Horner's rule in `x` with the powers of `1 - x`.
        let u = one - x;
        let (mut g, mut up) = (d[n], one);
        for k in (0..n).rev() {
            up *= u;
            g = g * x + d[k] * up;
        }
        // Anderson–Björck: an end kept twice in a row has its value scaled down.
        let mut on = [0.0f32; LANES];
        for (l, o) in on.iter_mut().enumerate() {
            if active & (1 << l) != 0 {
                *o = f32::from_bits(u32::MAX);
            }
        }
        let on = f32x8::from(on);
        let below = g.cmp_lt(zero);
        let (to_a, to_b) = (on & below, on & !below);
        let ma = one - g / fa;
        let mb = one - g / fb;
        let fb_kept = side
            .cmp_lt(zero)
            .blend(fb * ma.cmp_gt(zero).blend(ma, half), fb);
        let fa_kept = side
            .cmp_gt(zero)
            .blend(fa * mb.cmp_gt(zero).blend(mb, half), fa);
        fb = to_a.blend(fb_kept, fb);
        fa = to_b.blend(fa_kept, fa);
        (a, ga, fa) = (to_a.blend(x, a), to_a.blend(g, ga), to_a.blend(g, fa));
        (b, gb, fb) = (to_b.blend(x, b), to_b.blend(g, gb), to_b.blend(g, fb));
        side = to_a.blend(-one, to_b.blend(one, side));
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
