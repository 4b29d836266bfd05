//! The slab test of a packet's rays against one box, eight rays at a time.
//!
//! A packet leaf lists the rays of its cover that are not done and cross its box, with their
//! ranges; ray by ray that was a tenth of `scattered-1k`'s frame. The rays share the eye as
//! origin, so `lo − o` and `hi − o` are the box's alone, and the rest runs in `wide`'s `f32x8`
//! with [`slab`](crate::geom::aabb::slab)'s operations in its order: glam's `min`/`max` as the comparisons they are
//! (`a < b ? a : b`, which keeps a NaN in `b`), `f32::max`/`min` against `t_min`/`t_max` as
//! the NaN-dropping choice they are. The ranges are the single ray's, bit for bit but for the
//! sign of a zero where `f32::max(−0, +0)` may give either (a range's zero end is the same
//! place to every later use: the searches' event keys read `−0` as `+0`).

#[cfg(test)]
use crate::geom::aabb::slab;
use crate::geom::aabb::Aabb;
use crate::geom::tile::Cover;
use glam::Vec3;
use wide::{f32x8, CmpGt, CmpLe, CmpLt};

/// Rays at once.
const LANES: usize = 8;

/// A tile's `1/dir` as structure-of-arrays, padded by a vector's width so that every load
/// of eight is in bounds.
#[derive(Debug, Default)]
pub(super) struct TileInverses {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
}

impl TileInverses {
    /// The tile's rays' inverse directions.
    pub(super) fn load(&mut self, inv: &[Vec3]) {
        for (axis, out) in [&mut self.x, &mut self.y, &mut self.z]
            .into_iter()
            .enumerate()
        {
            out.clear();
            out.extend(inv.iter().map(|v| v[axis]));
            out.resize(inv.len() + LANES, 0.0);
        }
    }

    /// `(ray, near, far)` for every ray of `cover` (rays `from..n` of a tile `width` wide, by
    /// index) not `done` whose line from `origin` crosses `bounds` within `[0, t_max]`, in
    /// index order: what [`crate::geom::aabb::slab`] gives ray by ray.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn crossing(
        &self,
        cover: Cover,
        (width, from, n): (usize, usize, usize),
        done: &[bool],
        bounds: &Aabb,
        origin: Vec3,
        t_max: f32,
        out: &mut Vec<(u32, f32, f32)>,
    ) {
        out.clear();
        let b = BoxFromEye::new(bounds, origin, t_max);
        match cover {
            Cover::Empty => {}
            Cover::Unknown => self.run(&b, from..n, done, out),
            Cover::Rect { c0, c1, r0, r1 } => {
                for r in (from / width).max(r0 as usize)..=r1 as usize {
                    let start = (r * width + c0 as usize).max(from);
                    let end = (r * width + c1 as usize + 1).min(n);
                    if start < end {
                        self.run(&b, start..end, done, out);
                    }
                }
            }
        }
    }

    /// [`TileInverses::crossing`] over the consecutive rays `range`.
    #[inline]
    fn run(
        &self,
        b: &BoxFromEye,
        range: std::ops::Range<usize>,
        done: &[bool],
        out: &mut Vec<(u32, f32, f32)>,
    ) {
        let mut s = range.start;
        while s < range.end {
            let lanes = (range.end - s).min(LANES);
            let mut live = 0u32;
            for (l, &d) in done[s..s + lanes].iter().enumerate() {
                live |= (!d as u32) << l;
            }
            if live != 0 {
                let load = |v: &[f32]| {
                    let mut a = [0f32; LANES];
                    a.copy_from_slice(&v[s..s + LANES]);
                    f32x8::from(a)
                };
                let (near, far) = b.ranges([load(&self.x), load(&self.y), load(&self.z)]);
                let mut meets = near.cmp_le(far).move_mask() as u32 & live;
                if meets != 0 {
                    let (near, far) = (near.to_array(), far.to_array());
                    while meets != 0 {
                        let l = meets.trailing_zeros() as usize;
                        out.push(((s + l) as u32, near[l], far[l]));
                        meets &= meets - 1;
                    }
                }
            }
            s += lanes;
        }
    }
}

/// One box as seen from the shared origin: `lo − o` and `hi − o` per axis, and the clamp.
struct BoxFromEye {
    lo: [f32x8; 3],
    hi: [f32x8; 3],
    t_max: f32x8,
}

impl BoxFromEye {
    fn new(bounds: &Aabb, origin: Vec3, t_max: f32) -> Self {
        let (lo, hi) = (bounds.min - origin, bounds.max - origin);
        BoxFromEye {
            lo: [0, 1, 2].map(|k| f32x8::splat(lo[k])),
            hi: [0, 1, 2].map(|k| f32x8::splat(hi[k])),
            t_max: f32x8::splat(t_max),
        }
    }

    /// `(near, far)` of eight rays with inverse directions `inv` (`slab` on `[0, t_max]`;
    /// `near > far` where a ray misses).
    #[inline(always)]
    fn ranges(&self, inv: [f32x8; 3]) -> (f32x8, f32x8) {
        // glam's `Vec3::min`/`max` and `min_element`/`max_element`: `a < b ? a : b`.
        let min = |a: f32x8, b: f32x8| a.cmp_lt(b).blend(a, b);
        let max = |a: f32x8, b: f32x8| a.cmp_gt(b).blend(a, b);
        let t0 = [0, 1, 2].map(|k| self.lo[k] * inv[k]);
        let t1 = [0, 1, 2].map(|k| self.hi[k] * inv[k]);
        let lows = [0, 1, 2].map(|k| min(t0[k], t1[k]));
        let highs = [0, 1, 2].map(|k| max(t0[k], t1[k]));
        let near = max(lows[0], max(lows[1], lows[2]));
        let far = min(highs[0], min(highs[1], highs[2]));
        // `f32::max(near, 0)` and `f32::min(far, t_max)`: a NaN gives way to the bound.
        let zero = f32x8::ZERO;
        let near = near.cmp_gt(zero).blend(near, zero);
        let far = far.cmp_lt(self.t_max).blend(far, self.t_max);
        #[cfg(isoray_mutation = "slab-infinities")]
        let far = {
            // The mutation `slab` carries: a ray with an infinite or NaN slab misses.
            let finite = |v: f32x8| {
                v.cmp_lt(f32x8::splat(f32::INFINITY)) & v.cmp_gt(f32x8::splat(f32::NEG_INFINITY))
            };
            let all = (0..3).fold(f32x8::splat(f32::from_bits(u32::MAX)), |m, k| {
                m & finite(t0[k]) & finite(t1[k])
            });
            all.blend(far, f32x8::splat(f32::NEG_INFINITY))
        };
        (near, far)
    }
}

/// The ranges [`TileInverses::crossing`] would give, ray by ray through [`slab`].
#[cfg(test)]
pub(super) fn crossing_one_by_one(
    cover: Cover,
    (width, from, n): (usize, usize, usize),
    done: &[bool],
    inv: &[Vec3],
    bounds: &Aabb,
    origin: Vec3,
    t_max: f32,
) -> Vec<(u32, f32, f32)> {
    let mut out = Vec::new();
    cover.visit(width, from, n, |r| {
        if !done[r] {
            if let Some((near, far)) = slab(bounds.min, bounds.max, origin, inv[r], 0.0, t_max) {
                out.push((r as u32, near, far));
            }
        }
        false
    });
    out
}
