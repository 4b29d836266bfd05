//! Single-ray traversal of the implicit BVH: first hit along a segment and any hit (shadows).
//!
//! How it works (tetrahedral-isosurface-ray-tracing.txt §5.2, §7): a node is entered only if
//! its scalar range spans one of the query's isovalues (implicit culling, the cheap test, done
//! first), it is not wholly inside the clip box (§7, "if a node's subtree is completely
//! enclosed in the crop box, we skip the subtree"), and the ray's slab test passes within the
//! current best distance. Children are visited nearest first. In a leaf each tet's own
//! isorange is tested per isovalue (the marching-tets case is that test), then its
//! isopolygon is extracted on the fly (§4.4: no cache) and intersected. Hits inside the clip
//! box are discarded. Ties in distance go to the lower tet index, so every build and
//! traversal order returns the same hit.

use crate::geom::aabb;
use crate::geom::clip::ClipBox;
use crate::kinds::tets::bvh::{Bvh, Node};
use crate::kinds::tets::counters::TetCounters;
use crate::kinds::tets::march::{extract, intersect_one};
use crate::kinds::tets::mesh::{TetError, MAX_ISOSURFACES};
use crate::kinds::tets::walk::{walk, Walker};
use crate::ray::Ray;
use glam::{Vec3, Vec4, Vec4Swizzles};

/// A clip box checked for a tet query: `lo ≤ hi` on every axis, no NaN (bounds may be
/// infinite, to cut by a plane). The one clip box type is [`ClipBox`]; this constructor is
/// the tet kind's check of it.
impl ClipBox {
    pub fn new(lo: Vec3, hi: Vec3) -> Result<ClipBox, TetError> {
        if lo.is_nan() || hi.is_nan() || lo.cmpgt(hi).any() {
            return Err(TetError::BadClipBox);
        }
        Ok(ClipBox { min: lo, max: hi })
    }
}

/// What a ray looks for: up to [`MAX_ISOSURFACES`] isovalues and an optional clip box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TetQuery {
    isovalues: [f32; MAX_ISOSURFACES],
    count: usize,
    clip: Option<ClipBox>,
}

impl TetQuery {
    /// One isovalue, no clipping.
    pub fn single(isovalue: f32) -> TetQuery {
        TetQuery {
            isovalues: [isovalue; MAX_ISOSURFACES],
            count: 1,
            clip: None,
        }
    }

    /// Several isovalues (finite, at most [`MAX_ISOSURFACES`]) and a clip box.
    pub fn new(isovalues: &[f32], clip: Option<ClipBox>) -> Result<TetQuery, TetError> {
        if isovalues.len() > MAX_ISOSURFACES {
            return Err(TetError::TooManyIsovalues {
                count: isovalues.len(),
            });
        }
        if let Some(index) = isovalues.iter().position(|v| !v.is_finite()) {
            return Err(TetError::IsovalueNotFinite { index });
        }
        let mut q = TetQuery::single(f32::NAN);
        q.isovalues[..isovalues.len()].copy_from_slice(isovalues);
        q.count = isovalues.len();
        q.clip = clip;
        Ok(q)
    }

    pub fn isovalues(&self) -> &[f32] {
        &self.isovalues[..self.count]
    }

    pub fn clip(&self) -> Option<ClipBox> {
        self.clip
    }

    /// Whether traversal may enter `node`: its range spans an isovalue and the clip box does
    /// not swallow it.
    #[inline]
    pub(crate) fn admits(&self, node: &Node, c: &mut TetCounters) -> bool {
        c.isorange_tests += 1;
        if !self.isovalues().iter().any(|&v| node.spans(v)) {
            return false;
        }
        if self
            .clip
            .is_some_and(|clip| clip.encloses(node.lo.xyz(), node.hi.xyz()))
        {
            c.clipped_subtrees += 1;
            return false;
        }
        true
    }

    #[inline]
    pub(crate) fn clipped(&self, p: Vec3) -> bool {
        self.clip.is_some_and(|clip| clip.contains(p))
    }
}

/// A ray's hit: distance, the mesh's tet index, and which of the query's isovalues.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TetHit {
    pub t: f32,
    pub tet: u32,
    pub surface: u8,
}

impl TetHit {
    /// `t` in `[t_min, best]`, nearer than `self` or as near with a lower tet index.
    #[inline]
    pub(crate) fn beaten_by(&self, t: f32, tet: u32) -> bool {
        t < self.t || (t == self.t && tet < self.tet)
    }

    pub(crate) fn none(t_max: f32) -> TetHit {
        TetHit {
            t: t_max,
            tet: u32::MAX,
            surface: 0,
        }
    }

    pub(crate) fn found(&self) -> bool {
        self.tet != u32::MAX
    }
}

/// The slab test of `node` against a ray; the entry distance if it meets `[t_min, t_max]`.
#[inline]
pub(crate) fn slab(
    node: &Node,
    origin: Vec3,
    inv_dir: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<f32> {
    aabb::slab(node.lo.xyz(), node.hi.xyz(), origin, inv_dir, t_min, t_max).map(|(near, _)| near)
}

/// The nearest hit in `[t_min, t_max]`, or with `ANY` the first found.
pub(crate) fn trace<const ANY: bool>(
    bvh: &Bvh,
    verts: &[Vec4],
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    q: &TetQuery,
    c: &mut TetCounters,
) -> Option<TetHit> {
    c.rays += 1;
    let inv = ray.dir.recip();
    let root = &bvh.nodes[0];
    if !q.admits(root, c) {
        return None;
    }
    c.ray_box_tests += 1;
    let t_root = slab(root, ray.origin, inv, t_min, t_max)?;
    let mut ray_walk = RayWalk::<ANY> {
        bvh,
        verts,
        ray,
        inv,
        t_min,
        q,
        c,
        best: TetHit::none(t_max),
    };
    walk(bvh, t_root, &mut ray_walk);
    let best = ray_walk.best;
    if best.found() {
        c.hits += 1;
        Some(best)
    } else {
        None
    }
}

/// One ray's walk: a node's entry is the ray's distance to its box.
struct RayWalk<'a, const ANY: bool> {
    bvh: &'a Bvh,
    verts: &'a [Vec4],
    ray: &'a Ray,
    inv: Vec3,
    t_min: f32,
    q: &'a TetQuery,
    c: &'a mut TetCounters,
    best: TetHit,
}

impl<const ANY: bool> Walker for RayWalk<'_, ANY> {
    type Entry = f32;

    #[inline]
    fn enter(&mut self, _node: &Node, t_near: f32) -> Option<f32> {
        if t_near > self.best.t {
            return None;
        }
        self.c.nodes += 1;
        Some(t_near)
    }

    #[inline]
    fn leaf(&mut self, node: &Node, _t_near: f32) -> bool {
        let (bvh, ray, c) = (self.bvh, self.ray, &mut *self.c);
        let first = node.first as usize;
        for k in first..first + node.count as usize {
            let ids = bvh.leaf_tets[k];
            let corners = ids.map(|v| self.verts[v as usize]);
            for (s, &iso) in self.q.isovalues().iter().enumerate() {
                let Some(poly) = extract(ids, corners, iso) else {
                    continue;
                };
                c.extractions += 1;
                c.polygon_tests += 1;
                let Some(t) = intersect_one(&poly, ray.origin, ray.dir, self.t_min, self.best.t)
                else {
                    continue;
                };
                let tet = bvh.leaf_ids[k];
                if self.best.beaten_by(t, tet) && !self.q.clipped(ray.at(t)) {
                    self.best = TetHit {
                        t,
                        tet,
                        surface: s as u8,
                    };
                    if ANY {
                        return true;
                    }
                }
            }
        }
        false
    }

    #[inline]
    fn children(&mut self, a: &Node, b: &Node, _t_near: f32) -> (Option<f32>, Option<f32>, bool) {
        let mut entry = |n: &Node| {
            if !self.q.admits(n, self.c) {
                return None;
            }
            self.c.ray_box_tests += 1;
            slab(n, self.ray.origin, self.inv, self.t_min, self.best.t)
        };
        let (ta, tb) = (entry(a), entry(b));
        let a_first = match (ta, tb) {
            (Some(ta), Some(tb)) => ta <= tb,
            _ => true,
        };
        (ta, tb, a_first)
    }
}
