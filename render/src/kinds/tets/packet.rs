//! Packet traversal: many rays from one origin through the implicit BVH together.
//!
//! How it works (tetrahedral-isosurface-ray-tracing.txt §5.2, after Wald et al.'s dynamic BVH
//! traversal), for a packet whose rays share an origin (a tile of primary rays):
//! 1. Implicit culling: a child is pushed only if its scalar range spans an isovalue and the
//!    clip box does not swallow it; every pushed node is "active".
//! 2. Speculative first-active descent: the node is tested against the packet's first
//!    active ray only; if that ray hits it, the whole packet descends without more tests.
//! 3. Frustum test: otherwise an interval-arithmetic test over the packet's direction ranges
//!    (Reshetov et al.) rejects the node when no ray of the packet can hit it.
//! 4. First-active tracking: otherwise rays after the first active one are tested in turn
//!    until one hits; the rays skipped are inactive below this node (the node's box bounds
//!    every box below it, so they cannot hit anything there).
//! 5. Leaves: per tet and isovalue the isorange test, then one isopolygon extraction and one
//!    set-up of its edge planes for the whole packet ([`PolygonFromOrigin`]); the corner-ray
//!    frustum test (§4.3) skips the packet (full miss) or the edge tests (full hit); else each
//!    active ray pays a few dot products.
//!
//! One addition for packets that are tiles of a camera's pixel grid ([`RayPacket::tile`]):
//! the frustum tests are sharpened to the pixels a node or an isopolygon covers. Its corners
//! projected onto the image bound (widened by a pixel) the rays that can meet it, so step 4
//! searches only those rays and step 5 tests only those (or skips the polygon when none).
//! This is the corner-ray idea of §4.3 applied to sub-rectangles of the tile; it matters when
//! a node or polygon covers a few of the 256 pixels, which is most of the time.
//!
//! Every test is conservative and the per-ray arithmetic is the single-ray path's, so a
//! packet returns, ray for ray, exactly what [`super::traverse`] returns.

use crate::geom::tile::{Cover, TileGrid};
use crate::kinds::tets::bvh::{Bvh, Node};
use crate::kinds::tets::counters::TetCounters;
use crate::kinds::tets::march::{extract, FrustumTest, PolygonFromOrigin};
use crate::kinds::tets::traverse::{slab, TetHit, TetQuery};
use crate::kinds::tets::walk::{walk, Walker};
use glam::{Vec3, Vec4, Vec4Swizzles};

/// Rays from one origin. `corners` are four rays such that every ray of the packet is a
/// positive combination of them (the corner pixels of a tile, see [`RayPacket::tile`]).
#[derive(Clone, Copy, Debug)]
pub struct RayPacket<'a> {
    pub origin: Vec3,
    /// Unit directions.
    pub dirs: &'a [Vec3],
    pub corners: [Vec3; 4],
    /// The pixel grid, when the packet is a tile of one (row-major `dirs`).
    pub grid: Option<TileGrid>,
}

impl<'a> RayPacket<'a> {
    /// The rays through pixels `x0..x1` × `y0..y1` (row-major) of `rays`, written to `dirs`.
    pub fn tile(
        rays: &crate::camera::PrimaryRays,
        (x0, y0, x1, y1): (u32, u32, u32, u32),
        dirs: &'a mut Vec<Vec3>,
    ) -> RayPacket<'a> {
        dirs.clear();
        for y in y0..y1 {
            rays.row_directions(y, x0, (x1 - x0) as usize, |_, dir, _| dirs.push(dir));
        }
        // Directions are affine in the pixel position, so the four corner pixels' rays span
        // every ray of the tile.
        let corners = [(x0, y0), (x1 - 1, y0), (x0, y1 - 1), (x1 - 1, y1 - 1)]
            .map(|(x, y)| rays.through_pixel(x, y).dir);
        RayPacket {
            origin: rays.through_pixel(x0, y0).origin,
            dirs,
            corners,
            grid: Some(TileGrid {
                rays: *rays,
                x0,
                y0,
                width: x1 - x0,
                height: y1 - y0,
            }),
        }
    }
}

/// Per-packet buffers, reused between packets.
#[derive(Debug, Default)]
pub struct PacketScratch {
    inv: Vec<Vec3>,
    best: Vec<TetHit>,
}

/// Direction ranges for the interval-arithmetic frustum test; an axis along which the
/// packet's directions change sign (or reach zero) gives no bound.
struct Frustum {
    origin: Vec3,
    inv_lo: Vec3,
    inv_hi: Vec3,
    /// Per axis: +1 all directions positive, -1 all negative, 0 mixed.
    sign: [i8; 3],
}

impl Frustum {
    fn new(origin: Vec3, inv: &[Vec3]) -> Frustum {
        let mut inv_lo = Vec3::splat(f32::INFINITY);
        let mut inv_hi = Vec3::splat(f32::NEG_INFINITY);
        for r in inv {
            inv_lo = inv_lo.min(*r);
            inv_hi = inv_hi.max(*r);
        }
        let sign = [0, 1, 2].map(|k| {
            if inv_lo[k] > 0.0 && inv_hi[k].is_finite() {
                1
            } else if inv_hi[k] < 0.0 && inv_lo[k].is_finite() {
                -1
            } else {
                0
            }
        });
        Frustum {
            origin,
            inv_lo,
            inv_hi,
            sign,
        }
    }

    /// True when no ray of the packet meets `node` within `[t_min, t_max]`: the largest
    /// possible entry exceeds the smallest possible exit. Rounded products are monotonic in
    /// the reciprocal, so this never contradicts a ray's own slab test.
    #[inline]
    fn misses(&self, node: &Node, t_min: f32, t_max: f32) -> bool {
        let mut entry = t_min;
        let mut exit = t_max;
        let lo = node.lo.xyz() - self.origin;
        let hi = node.hi.xyz() - self.origin;
        for k in 0..3 {
            let (near, far) = match self.sign[k] {
                1 => (lo[k], hi[k]),
                -1 => (hi[k], lo[k]),
                _ => continue,
            };
            let (a, b) = (near * self.inv_lo[k], near * self.inv_hi[k]);
            let (c, d) = (far * self.inv_lo[k], far * self.inv_hi[k]);
            entry = entry.max(a.min(b));
            exit = exit.min(c.max(d));
        }
        entry > exit
    }
}

/// The nearest hit of every ray of `packet` in `[t_min, t_max]`, into `out`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn first_hits(
    bvh: &Bvh,
    verts: &[Vec4],
    packet: &RayPacket<'_>,
    t_min: f32,
    t_max: f32,
    q: &TetQuery,
    scratch: &mut PacketScratch,
    out: &mut [Option<TetHit>],
    c: &mut TetCounters,
) {
    let n = packet.dirs.len();
    c.rays += n as u64;
    scratch.inv.clear();
    scratch.inv.extend(packet.dirs.iter().map(|d| d.recip()));
    scratch.best.clear();
    scratch.best.resize(n, TetHit::none(t_max));
    out.iter_mut().for_each(|o| *o = None);
    if n == 0 {
        return;
    }
    let (inv, best) = (&scratch.inv, &mut scratch.best);
    if q.admits(&bvh.nodes[0], c) {
        let mut packet_walk = PacketWalk {
            bvh,
            verts,
            packet,
            inv,
            frustum: Frustum::new(packet.origin, inv),
            t_min,
            far_best: t_max,
            q,
            best,
            c,
        };
        walk(bvh, 0, &mut packet_walk);
    }
    for (o, b) in out.iter_mut().zip(best.iter()) {
        if b.found() {
            c.hits += 1;
            *o = Some(*b);
        }
    }
}

/// A packet's walk: a node's entry is the packet's first active ray there.
struct PacketWalk<'a, 'p> {
    bvh: &'a Bvh,
    verts: &'a [Vec4],
    packet: &'a RayPacket<'p>,
    inv: &'a [Vec3],
    frustum: Frustum,
    t_min: f32,
    /// The farthest of the rays' best distances: no ray can hit beyond it.
    far_best: f32,
    q: &'a TetQuery,
    best: &'a mut [TetHit],
    c: &'a mut TetCounters,
}

impl Walker for PacketWalk<'_, '_> {
    type Entry = u32;

    #[inline]
    fn enter(&mut self, node: &Node, first_active: u32) -> Option<u32> {
        self.c.nodes += 1;
        let (origin, inv, t_min) = (self.packet.origin, self.inv, self.t_min);
        let hits = |r: usize, c: &mut TetCounters, best: &[TetHit]| {
            c.ray_box_tests += 1;
            slab(node, origin, inv[r], t_min, best[r].t).is_some()
        };
        let fa = first_active as usize;
        if hits(fa, self.c, self.best) {
            return Some(first_active);
        }
        self.c.frustum_box_tests += 1;
        if self.frustum.misses(node, t_min, self.far_best) {
            return None;
        }
        let cover = match &self.packet.grid {
            Some(grid) => {
                self.c.frustum_box_tests += 1;
                grid.cover_box(node.lo.xyz(), node.hi.xyz())
            }
            None => Cover::Unknown,
        };
        let width = self.packet.grid.map_or(1, |g| g.width);
        let n = self.packet.dirs.len();
        let (c, best) = (&mut *self.c, &*self.best);
        cover
            .rays(width, fa + 1, n)
            .find(|&r| hits(r, c, best))
            .map(|r| r as u32)
    }

    #[inline]
    fn leaf(&mut self, node: &Node, first_active: u32) -> bool {
        let (bvh, packet, q, c) = (self.bvh, self.packet, self.q, &mut *self.c);
        let (origin, fa, n) = (packet.origin, first_active as usize, packet.dirs.len());
        let best = &mut *self.best;
        let mut improved = false;
        let first = node.first as usize;
        for k in first..first + node.count as usize {
            let ids = bvh.leaf_tets[k];
            let corners = ids.map(|v| self.verts[v as usize]);
            for (s, &iso) in q.isovalues().iter().enumerate() {
                let Some(poly) = extract(ids, corners, iso) else {
                    continue;
                };
                c.extractions += 1;
                let cover = match &packet.grid {
                    Some(grid) => grid.cover(poly.points[..poly.count].iter().copied()),
                    None => Cover::Unknown,
                };
                if cover == Cover::Empty {
                    c.polygons_culled += 1;
                    continue;
                }
                // The corner test is four ray–isopolygon tests (for a 2×2 packet it is
                // the whole packet's).
                c.polygon_tests += 4;
                let prep = PolygonFromOrigin::new(&poly, origin);
                let verdict = prep.frustum(&packet.corners);
                let tet = bvh.leaf_ids[k];
                let tested = match verdict {
                    FrustumTest::Miss => {
                        c.polygons_culled += 1;
                        continue;
                    }
                    FrustumTest::Hit => {
                        c.polygons_full += 1;
                        Cover::Unknown
                    }
                    FrustumTest::Partial => cover,
                };
                let width = packet.grid.map_or(1, |g| g.width);
                for r in tested.rays(width, fa, n) {
                    let dir = packet.dirs[r];
                    let t = match verdict {
                        FrustumTest::Hit => prep.distance(dir),
                        _ => {
                            c.polygon_tests += 1;
                            prep.intersect(dir)
                        }
                    };
                    let Some(t) = t else { continue };
                    if t >= self.t_min && best[r].beaten_by(t, tet) && !q.clipped(origin + t * dir)
                    {
                        best[r] = TetHit {
                            t,
                            tet,
                            surface: s as u8,
                        };
                        improved = true;
                    }
                }
            }
        }
        if improved {
            self.far_best = best.iter().fold(self.t_min, |m, b| m.max(b.t));
        }
        false
    }

    #[inline]
    fn children(
        &mut self,
        a: &Node,
        b: &Node,
        first_active: u32,
    ) -> (Option<u32>, Option<u32>, bool) {
        let admit_a = self.q.admits(a, self.c);
        let admit_b = self.q.admits(b, self.c);
        // Nearer child first along the first active ray.
        let (ca, cb) = (a.lo + a.hi, b.lo + b.hi);
        let a_first = (cb - ca).xyz().dot(self.packet.dirs[first_active as usize]) >= 0.0;
        (
            admit_a.then_some(first_active),
            admit_b.then_some(first_active),
            a_first,
        )
    }
}
