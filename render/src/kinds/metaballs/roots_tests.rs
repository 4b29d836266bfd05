//! Tests of the section bound's early exit ([`super::may_reach`]), and the whole-stretch
//! bound for the tests of its copies in lanes.

use super::*;
use crate::geom::rng::SplitMix64;
use crate::kinds::metaballs::kernel::Kernel;

/// The whole-stretch bound a search of `balls` on `[lo, hi]` under `p` starts with
/// ([`super::stretch_bound`]; the kernel's degree read at run time, the same Horner steps), for
/// tests of the copies that compute it in lanes.
pub(crate) fn whole_stretch_bound(
    p: &FindParams<f32>,
    balls: &[RayBall<f32>],
    lo: f32,
    hi: f32,
) -> f32 {
    stretch_bound::<f32, 0>(p, balls, lo, hi)
}

/// Up to 12 balls of random centre and radius along the ray `o + t x̂`, a fifth of them
/// carving when `carving`, the ones the ray meets.
fn balls_along(rng: &mut SplitMix64, carving: bool) -> Vec<RayBall<f32>> {
    let n = 1 + rng.next_u64() % 12;
    (0..n as u32)
        .filter_map(|ball| {
            let r = 0.3 + rng.next_f32();
            let p = [
                4.0 * rng.next_f32(),
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            ];
            let e = [-p[0] / r, -p[1] / r, -p[2] / r];
            let (t0, t1, a, tc, s_min) = RayBall::along(e, [1.0 / r, 0.0, 0.0])?;
            let q = if carving && rng.next_u64() % 5 == 0 {
                -0.5
            } else {
                1.0
            };
            Some(RayBall {
                ball,
                t0,
                t1,
                a,
                tc,
                s_min,
                q,
                lipschitz: 2.0 / r,
                min_radius: r,
                owner: true,
            })
        })
        .collect()
}

/// The way-out search's bound stops at a partial sum below `T` only when every term is
/// `≤ 0`, and then decides as the whole sum does, on every section of random balls, with
/// and without carving balls (whose negated terms are positive: there it must not stop).
#[test]
fn the_bounds_early_exit_decides_as_the_whole_sum() {
    let mut rng = SplitMix64(5);
    let (mut stopped_early, mut mixed) = (0, 0);
    for trial in 0..4000 {
        let balls = balls_along(&mut rng, trial % 2 == 1);
        let mut p = FindParams {
            kernel: KernelPoly::new(Kernel::Wyvill),
            isovalue: 0.2 + 0.6 * rng.next_f32(),
            tolerance: 1e-4,
            owners_only: false,
            step: f32::INFINITY,
            bounded: false,
        };
        p.kernel.c.iter_mut().for_each(|c| *c = -*c);
        p.isovalue = -p.isovalue;
        let falling = all_falling::<f32, 3>(&p, &balls);
        mixed += (!falling) as usize;
        for _ in 0..8 {
            let a = -1.0 + 6.0 * rng.next_f32();
            let b = a + 0.5 * rng.next_f32();
            let active: Vec<u32> = (0..balls.len() as u32)
                .filter(|&i| balls[i as usize].t0 <= a && b <= balls[i as usize].t1)
                .collect();
            let whole = may_reach::<f32, 3>(&p, &balls, &active, a, b, false);
            let early = may_reach::<f32, 3>(&p, &balls, &active, a, b, falling);
            assert_eq!(early, whole, "[{a}, {b}] over {balls:?}");
            // Whether the early exit had terms left to skip: the sum of the first four terms
            // (where it is first checked) below `T`, with more terms after them.
            let peak = p.kernel.at_w_of::<3>(1.0);
            let four = (active.iter().take(4))
                .map(|&i| term_bound::<f32, 3>(&p, peak, &balls[i as usize], a, b))
                .fold(0.0, |sum, term| sum + term);
            stopped_early += (falling && active.len() > 4 && four < p.isovalue) as usize;
        }
    }
    assert!(
        stopped_early > 300,
        "the early exit skipped terms {stopped_early} times"
    );
    assert!(mixed > 500, "only {mixed} sets of balls with carving ones");
}
