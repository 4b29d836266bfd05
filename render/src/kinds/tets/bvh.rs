//! The implicit min–max BVH over tets: 4-D bounds, BIH-style and SAH builds, refitting.
//!
//! How it works (tetrahedral-isosurface-ray-tracing.txt §5, §6):
//! - A node's bounds are 4-D, `{x, y, z, v}` (§5.1 "BVH Structure"): the box of its tets and
//!   the range of the scalar at their vertices, each stored in one `Vec4` so that a refit
//!   is one SIMD `min` and `max` per tet corner and per child. Traversal skips a subtree
//!   whose range misses every isovalue of the query.
//! - Builds are top-down over the tets' boxes and centroids; nodes split until a leaf holds
//!   at most [`LEAF_SIZE`] = 12 tets (§5.1, "Empirically, we have found this fixed value to
//!   work best"). [`BuildKind::Bih`] is the fast spatial-median build of Wächter and
//!   Keller's bounding interval hierarchy: the node's candidate interval (the parent's,
//!   halved) is split at its midpoint on its longest axis; when every centroid falls on one
//!   side the interval shrinks to that side and the split is retried. [`BuildKind::Sah`] is
//!   Wald's sweep SAH: per axis, sort the centroids and sweep both ways for the surface
//!   area of every prefix and suffix, and split where `A_L·N_L + A_R·N_R` is least.
//! - The two children of a node are adjacent in the node array and always come after their
//!   parent, so refitting (§6.2) is one backward pass; the build itself ends with that same
//!   pass, so a refit of an unchanged mesh reproduces the built bounds exactly.
//! - Boxes are padded by a few ulps of their coordinates so rounding in the slab test never
//!   loses a tet that touches a box face; the scalar range is exact.
//!
//! The recursion forks on rayon for large nodes; the layout does not depend on the thread
//! count.

use glam::{Vec3, Vec4, Vec4Swizzles};
use rayon::prelude::*;

/// Most tets in a leaf (§5.1).
pub const LEAF_SIZE: usize = 12;

/// Nodes with more tets than this build their children in parallel.
const PARALLEL_TETS: usize = 32_768;

/// Relative padding of boxes, in units of their coordinates' magnitude.
const BOX_PADDING: f32 = 4.0 * f32::EPSILON;

/// Which top-down build (§5.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BuildKind {
    /// The BIH-style spatial-median build (the paper's default).
    Bih,
    /// Wald's sweep SAH build.
    Sah,
}

impl BuildKind {
    pub const ALL: [BuildKind; 2] = [BuildKind::Bih, BuildKind::Sah];

    pub fn name(self) -> &'static str {
        match self {
            BuildKind::Bih => "BIH",
            BuildKind::Sah => "SAH",
        }
    }
}

/// One node: 4-D bounds, then either two adjacent children at `first` (`count == 0`) or the
/// `count` tets at `first` in the leaf order. 48 bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// `xyz`: box corner, `w`: smallest scalar.
    pub lo: Vec4,
    /// `xyz`: box corner, `w`: largest scalar.
    pub hi: Vec4,
    pub first: u32,
    pub count: u32,
}

impl Node {
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }

    /// Whether some tet below may cross `isovalue` (`min ≤ v < max`, as in
    /// [`super::march::case_of`]).
    #[inline]
    pub fn spans(&self, isovalue: f32) -> bool {
        self.lo.w <= isovalue && isovalue < self.hi.w
    }
}

/// The implicit BVH of one tet mesh: nodes, and the tets in leaf order.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh {
    pub(crate) nodes: Vec<Node>,
    /// Vertex indices of the tets in leaf order.
    pub(crate) leaf_tets: std::sync::Arc<[[u32; 4]]>,
    /// The mesh's index of each tet in leaf order.
    pub(crate) leaf_ids: std::sync::Arc<[u32]>,
    pub(crate) kind: BuildKind,
}

/// Shape of a built tree.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhStats {
    pub nodes: usize,
    pub leaves: usize,
    pub max_depth: usize,
    pub tets_per_leaf: f64,
    /// Bytes of the node array and of the leaf order (vertex indices and ids).
    pub node_bytes: usize,
    pub order_bytes: usize,
}

/// Why [`Bvh::validate`] failed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum BvhInvalid {
    #[error("node {node}: child index {first} out of range")]
    ChildOutOfRange { node: usize, first: u32 },
    #[error("node {node}: children must come after their parent")]
    ChildBeforeParent { node: usize },
    #[error("node {node}: bounds do not contain child {child}")]
    ChildOutside { node: usize, child: usize },
    #[error("leaf {node}: bounds do not contain tet {tet}")]
    TetOutside { node: usize, tet: u32 },
    #[error("leaf {node}: {count} tets, more than {LEAF_SIZE}")]
    LeafTooBig { node: usize, count: u32 },
    #[error("node {node} is reached twice or not at all")]
    Unreachable { node: usize },
    #[error("tet {tet} appears {times} times")]
    TetCount { tet: u32, times: usize },
}

/// Per-tet data of a build: box and centroid.
struct Prims {
    lo: Vec<Vec3>,
    hi: Vec<Vec3>,
    centroid: Vec<Vec3>,
}

/// A subtree before flattening.
enum Tmp {
    Leaf { start: usize, count: usize },
    Inner(Box<Tmp>, Box<Tmp>),
}

impl Bvh {
    /// Builds over `tets` at `positions`. The bounds' scalar range is zero until
    /// [`Bvh::refit`] gives it this step's values.
    pub fn build(tets: &[[u32; 4]], positions: &[Vec3], kind: BuildKind) -> Bvh {
        let rest: Vec<Vec4> = positions.iter().map(|p| p.extend(0.0)).collect();
        Bvh::build_for(tets, &rest, kind)
    }

    /// Builds over `tets` at the positions `xyz` of `vertices`, with bounds for their scalars
    /// `w` (§6.1: a BVH of its own for one step).
    pub fn build_for(tets: &[[u32; 4]], vertices: &[Vec4], kind: BuildKind) -> Bvh {
        let prims = Prims::new(tets, vertices);
        let mut order: Vec<u32> = (0..tets.len() as u32).collect();
        let root = if tets.is_empty() {
            Tmp::Leaf { start: 0, count: 0 }
        } else {
            match kind {
                BuildKind::Bih => {
                    let (lo, hi) = centroid_bounds(&prims, &order);
                    bih(&prims, &mut order, 0, lo, hi)
                }
                BuildKind::Sah => sah(&prims, &mut order, 0),
            }
        };
        let mut nodes = vec![Node {
            lo: Vec4::ZERO,
            hi: Vec4::ZERO,
            first: 0,
            count: 0,
        }];
        flatten(&root, 0, &mut nodes);
        let leaf_tets: Vec<[u32; 4]> = order.iter().map(|&i| tets[i as usize]).collect();
        let mut bvh = Bvh {
            nodes,
            leaf_tets: leaf_tets.into(),
            leaf_ids: order.into(),
            kind,
        };
        bvh.refit_in_place(vertices);
        bvh
    }

    /// This tree's structure with bounds recomputed for `vertices` (`xyz` position, `w`
    /// scalar of this step): §6.2's refit.
    pub fn refit(&self, vertices: &[Vec4]) -> Bvh {
        let mut out = self.clone();
        out.refit_in_place(vertices);
        out
    }

    fn refit_in_place(&mut self, vertices: &[Vec4]) {
        if self.leaf_tets.is_empty() {
            // An empty tree: a root no ray or isovalue can enter.
            self.nodes[0].lo = Vec4::splat(f32::INFINITY);
            self.nodes[0].hi = Vec4::splat(f32::NEG_INFINITY);
            return;
        }
        let leaf_tets = &self.leaf_tets;
        // Leaves in parallel (they hold all the work), then inner nodes backwards.
        self.nodes
            .par_iter_mut()
            .with_min_len(1024)
            .for_each(|node| {
                if node.is_leaf() {
                    let mut lo = Vec4::splat(f32::INFINITY);
                    let mut hi = Vec4::splat(f32::NEG_INFINITY);
                    let first = node.first as usize;
                    for tet in &leaf_tets[first..first + node.count as usize] {
                        for &v in tet {
                            let p = vertices[v as usize];
                            lo = lo.min(p);
                            hi = hi.max(p);
                        }
                    }
                    let pad = lo.xyz().abs().max(hi.xyz().abs()) * BOX_PADDING;
                    node.lo = (lo.xyz() - pad).extend(lo.w);
                    node.hi = (hi.xyz() + pad).extend(hi.w);
                }
            });
        for i in (0..self.nodes.len()).rev() {
            let node = self.nodes[i];
            if !node.is_leaf() {
                let (a, b) = (
                    self.nodes[node.first as usize],
                    self.nodes[node.first as usize + 1],
                );
                self.nodes[i].lo = a.lo.min(b.lo);
                self.nodes[i].hi = a.hi.max(b.hi);
            }
        }
    }

    pub fn kind(&self) -> BuildKind {
        self.kind
    }

    /// The tree's surface-area cost: the summed surface areas of every node's box (`xyz`)
    /// over the root's, the expected number of nodes a random ray through the root visits
    /// (the SAH with unit costs). Scale-free, so a refitted tree can be compared with the
    /// same tree when it was built. `0` for an empty tree.
    pub fn area_cost(&self) -> f64 {
        let area = |n: &Node| {
            let d = (n.hi.xyz() - n.lo.xyz()).max(glam::Vec3::ZERO).as_dvec3();
            2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
        };
        let root = area(&self.nodes[0]);
        if self.leaf_tets.is_empty() || !(root > 0.0) {
            return 0.0;
        }
        self.nodes.iter().map(area).sum::<f64>() / root
    }

    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    pub fn stats(&self) -> BvhStats {
        let mut leaves = 0;
        let mut max_depth = 0;
        let mut stack = vec![(0usize, 1usize)];
        while let Some((i, depth)) = stack.pop() {
            max_depth = max_depth.max(depth);
            let n = self.nodes[i];
            if n.is_leaf() || self.leaf_tets.is_empty() {
                leaves += 1;
            } else {
                stack.push((n.first as usize, depth + 1));
                stack.push((n.first as usize + 1, depth + 1));
            }
        }
        BvhStats {
            nodes: self.nodes.len(),
            leaves,
            max_depth,
            tets_per_leaf: self.leaf_tets.len() as f64 / leaves.max(1) as f64,
            node_bytes: self.nodes.len() * std::mem::size_of::<Node>(),
            order_bytes: self.leaf_tets.len()
                * (std::mem::size_of::<[u32; 4]>() + std::mem::size_of::<u32>()),
        }
    }

    /// Checks the invariants traversal relies on: children after parents and in range, every
    /// node reached once, parents' bounds contain children's, leaves' contain their tets'
    /// vertices (`vertices` as given to the last refit), leaves small, every tet once.
    pub fn validate(&self, vertices: &[Vec4]) -> Result<(), BvhInvalid> {
        let mut reached = vec![0usize; self.nodes.len()];
        let mut seen = vec![0usize; self.leaf_ids.len()];
        let mut stack = vec![0usize];
        let contains =
            |outer: &Node, lo: Vec4, hi: Vec4| outer.lo.cmple(lo).all() && outer.hi.cmpge(hi).all();
        while let Some(i) = stack.pop() {
            reached[i] += 1;
            let n = self.nodes[i];
            if self.leaf_tets.is_empty() {
                continue;
            }
            if n.is_leaf() {
                if n.count as usize > LEAF_SIZE {
                    return Err(BvhInvalid::LeafTooBig {
                        node: i,
                        count: n.count,
                    });
                }
                for k in n.first..n.first + n.count {
                    seen[k as usize] += 1;
                    for &v in &self.leaf_tets[k as usize] {
                        let p = vertices[v as usize];
                        if !contains(&n, p, p) {
                            return Err(BvhInvalid::TetOutside {
                                node: i,
                                tet: self.leaf_ids[k as usize],
                            });
                        }
                    }
                }
                continue;
            }
            if n.first as usize + 1 >= self.nodes.len() {
                return Err(BvhInvalid::ChildOutOfRange {
                    node: i,
                    first: n.first,
                });
            }
            if n.first as usize <= i {
                return Err(BvhInvalid::ChildBeforeParent { node: i });
            }
            for child in [n.first as usize, n.first as usize + 1] {
                let c = self.nodes[child];
                if !contains(&n, c.lo, c.hi) {
                    return Err(BvhInvalid::ChildOutside { node: i, child });
                }
                stack.push(child);
            }
        }
        if let Some(node) = reached.iter().position(|&r| r != 1) {
            return Err(BvhInvalid::Unreachable { node });
        }
        let mut per_tet = vec![0usize; self.leaf_ids.len()];
        for (k, &times) in seen.iter().enumerate() {
            per_tet[self.leaf_ids[k] as usize] += times;
        }
        if let Some(tet) = per_tet.iter().position(|&t| t != 1) {
            return Err(BvhInvalid::TetCount {
                tet: tet as u32,
                times: per_tet[tet],
            });
        }
        Ok(())
    }
}

impl Prims {
    fn new(tets: &[[u32; 4]], vertices: &[Vec4]) -> Prims {
        let boxes: Vec<(Vec3, Vec3)> = tets
            .par_iter()
            .with_min_len(4096)
            .map(|t| {
                let p = t.map(|v| vertices[v as usize].xyz());
                (
                    p[0].min(p[1]).min(p[2].min(p[3])),
                    p[0].max(p[1]).max(p[2].max(p[3])),
                )
            })
            .collect();
        let centroid = boxes.iter().map(|(lo, hi)| 0.5 * (*lo + *hi)).collect();
        let (lo, hi) = boxes.into_iter().unzip();
        Prims { lo, hi, centroid }
    }
}

fn centroid_bounds(prims: &Prims, order: &[u32]) -> (Vec3, Vec3) {
    order.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &i| {
            let c = prims.centroid[i as usize];
            (lo.min(c), hi.max(c))
        },
    )
}

fn fork<A: Send, B: Send>(
    big: bool,
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    if big {
        rayon::join(a, b)
    } else {
        (a(), b())
    }
}

/// Splits `order` (positions `start..` of the leaf order) into the two children of a node.
fn split_children(
    order: &mut [u32],
    start: usize,
    mid: usize,
    left: impl FnOnce(&mut [u32], usize) -> Tmp + Send,
    right: impl FnOnce(&mut [u32], usize) -> Tmp + Send,
) -> Tmp {
    let big = order.len() > PARALLEL_TETS;
    let (l, r) = order.split_at_mut(mid);
    let (a, b) = fork(big, || left(l, start), || right(r, start + mid));
    Tmp::Inner(Box::new(a), Box::new(b))
}

/// The BIH-style build: split the candidate interval `[lo, hi]` at its midpoint.
fn bih(prims: &Prims, order: &mut [u32], start: usize, mut lo: Vec3, mut hi: Vec3) -> Tmp {
    if order.len() <= LEAF_SIZE {
        return Tmp::Leaf {
            start,
            count: order.len(),
        };
    }
    // Each retry halves the interval; 3 × 64 halvings exhaust f32 on every axis.
    for _ in 0..192 {
        let extent = hi - lo;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let plane = 0.5 * (lo[axis] + hi[axis]);
        if !(plane > lo[axis] && plane < hi[axis]) {
            break;
        }
        let mid = partition(order, |i| prims.centroid[i as usize][axis] < plane);
        if mid == 0 {
            lo[axis] = plane;
        } else if mid == order.len() {
            hi[axis] = plane;
        } else {
            let (mut left_hi, mut right_lo) = (hi, lo);
            left_hi[axis] = plane;
            right_lo[axis] = plane;
            return split_children(
                order,
                start,
                mid,
                |o, s| bih(prims, o, s, lo, left_hi),
                |o, s| bih(prims, o, s, right_lo, hi),
            );
        }
    }
    // Every centroid in one point: split by count.
    let mid = order.len() / 2;
    split_children(
        order,
        start,
        mid,
        |o, s| {
            let (lo, hi) = centroid_bounds(prims, o);
            bih(prims, o, s, lo, hi)
        },
        |o, s| {
            let (lo, hi) = centroid_bounds(prims, o);
            bih(prims, o, s, lo, hi)
        },
    )
}

/// In-place partition: elements with `left(x)` first; returns their count. Deterministic.
fn partition(order: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let mut mid = 0;
    for i in 0..order.len() {
        if left(order[i]) {
            order.swap(i, mid);
            mid += 1;
        }
    }
    mid
}

fn area(lo: Vec3, hi: Vec3) -> f32 {
    let e = (hi - lo).max(Vec3::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// Wald's sweep SAH build.
fn sah(prims: &Prims, order: &mut [u32], start: usize) -> Tmp {
    let n = order.len();
    if n <= LEAF_SIZE {
        return Tmp::Leaf { start, count: n };
    }
    let key = |axis: usize| {
        move |&a: &u32, &b: &u32| {
            prims.centroid[a as usize][axis]
                .total_cmp(&prims.centroid[b as usize][axis])
                .then(a.cmp(&b))
        }
    };
    let mut right_area = vec![0.0f32; n];
    let mut best: Option<(usize, usize, f32)> = None;
    for axis in 0..3 {
        order.sort_unstable_by(key(axis));
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for k in (1..n).rev() {
            let i = order[k] as usize;
            lo = lo.min(prims.lo[i]);
            hi = hi.max(prims.hi[i]);
            right_area[k] = area(lo, hi);
        }
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for k in 1..n {
            let i = order[k - 1] as usize;
            lo = lo.min(prims.lo[i]);
            hi = hi.max(prims.hi[i]);
            let cost = area(lo, hi) * k as f32 + right_area[k] * (n - k) as f32;
            if best.is_none_or(|b| cost < b.2) {
                best = Some((axis, k, cost));
            }
        }
    }
    let (axis, mid, _) = best.unwrap_or((0, n / 2, 0.0));
    order.sort_unstable_by(key(axis));
    split_children(
        order,
        start,
        mid,
        |o, s| sah(prims, o, s),
        |o, s| sah(prims, o, s),
    )
}

fn flatten(t: &Tmp, index: usize, nodes: &mut Vec<Node>) {
    match t {
        Tmp::Leaf { start, count } => {
            nodes[index].first = *start as u32;
            nodes[index].count = *count as u32;
        }
        Tmp::Inner(a, b) => {
            let first = nodes.len();
            let blank = nodes[index];
            nodes.push(blank);
            nodes.push(blank);
            nodes[index].first = first as u32;
            nodes[index].count = 0;
            flatten(a, first, nodes);
            flatten(b, first + 1, nodes);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::tets::generate;

    #[test]
    fn both_builds_are_valid_and_refit_equals_rebuild_for_static_vertices() {
        let mesh = generate::box_mesh([9, 7, 8], Vec3::splat(-1.0), Vec3::splat(1.0), 0.2, 3);
        let scalars: Vec<f32> = mesh.vertices().iter().map(|p| p.length()).collect();
        let verts: Vec<Vec4> = mesh
            .vertices()
            .iter()
            .zip(&scalars)
            .map(|(p, &s)| p.extend(s))
            .collect();
        for kind in BuildKind::ALL {
            let built = Bvh::build(mesh.tets(), mesh.vertices(), kind);
            let bvh = built.refit(&verts);
            bvh.validate(&verts).expect("valid");
            let stats = bvh.stats();
            assert!(stats.leaves > 1 && stats.tets_per_leaf > 2.0, "{stats:?}");
            let (lo, hi) = scalars
                .iter()
                .fold((f32::INFINITY, 0.0f32), |(lo, hi), &s| {
                    (lo.min(s), hi.max(s))
                });
            assert_eq!(
                (bvh.nodes[0].lo.w, bvh.nodes[0].hi.w),
                (lo, hi),
                "the root's scalar range is the field's"
            );
            // Refitting the shared tree to new scalars gives what a rebuild gives.
            let shifted: Vec<Vec4> = verts.iter().map(|v| *v + Vec4::W).collect();
            let rebuilt = Bvh::build(mesh.tets(), mesh.vertices(), kind).refit(&shifted);
            assert_eq!(bvh.refit(&shifted), rebuilt, "{kind:?}");
            // A stale tree is caught.
            let moved: Vec<Vec4> = verts.iter().map(|v| *v * 2.0).collect();
            assert!(bvh.validate(&moved).is_err());
        }
    }

    #[test]
    fn degenerate_centroids_still_build() {
        // Many tets with the same centroid (a fan around one point) split by count.
        let mut vertices = vec![Vec3::ZERO];
        let mut tets = Vec::new();
        for k in 0..40 {
            let a = k as f32 * 0.15;
            let base = vertices.len() as u32;
            vertices.push(Vec3::new(a.cos(), a.sin(), -1.0));
            vertices.push(Vec3::new((a + 2.1).cos(), (a + 2.1).sin(), -1.0));
            vertices.push(Vec3::new((a + 4.2).cos(), (a + 4.2).sin(), -1.0));
            tets.push([base, base + 1, base + 2, 0]);
        }
        let verts: Vec<Vec4> = vertices.iter().map(|p| p.extend(0.0)).collect();
        for kind in BuildKind::ALL {
            let bvh = Bvh::build(&tets, &vertices, kind);
            bvh.validate(&verts).expect("valid");
        }
        let empty = Bvh::build(&[], &[], BuildKind::Bih);
        empty.validate(&[]).expect("an empty tree is valid");
        assert!(!empty.nodes[0].spans(0.0));
    }
}
