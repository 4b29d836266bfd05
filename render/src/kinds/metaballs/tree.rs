//! The BVH with split metaballs and the Fitted BVH, built from scratch for every state.
//!
//! How it works (fitted-bvh-metaballs.txt):
//! - §4, Algorithm 1 (`TreeKind::Bvh`): a BVH over the balls' bounding spheres. A node keeps
//!   its *split metaballs*: balls outside it whose sphere overlaps the sphere of one of its
//!   balls. Splitting a node hands each child the parent's split balls and the other child's
//!   balls that overlap one of its own (a neighbour list from a uniform grid answers "overlaps
//!   one of its own", after a cheap box test). Leaves overlap, so a ray visits every leaf it
//!   crosses and keeps the nearest hit.
//! - §5, Algorithm 2 (`TreeKind::Fitted`): the node's *box* is split at the plane, a child's
//!   split balls are those of the parent or of the other child whose sphere overlaps the
//!   child's half box, and the half box is intersected with the bounds of the child's balls
//!   (the fitting step, Fig. 4). Siblings never overlap, so the front-to-back traversal stops
//!   at the first leaf with a hit.
//! - §5.1: binned SAH with the leaf cost `n²` (or `n`, switchable), `n` counting the split
//!   balls a child will get: the parent's that reach its side of the plane and the other
//!   side's owned balls whose spheres cross it (counted per bin with difference arrays).
//! - §5.3.1: tighter boxes: a ball's box uses `min(R_i, r_max)` with
//!   `r_max = R_K · sqrt(s*)`, `f(s*) = T / (n q_max)` (the paper's `(1-(T/n)^{1/α})^{1/2}`
//!   for its kernel, generalised to any kernel and strength).
//! - §5.3.2: a positive split ball is discarded when its `r_max` sphere misses the node's box
//!   and it lies at least `R_i + r_max` from every other ball of the node (run on the leaves,
//!   whose lists the rays read; running it on every small node cost more than it saved).
//!
//! The build: a node's owned balls are a contiguous slice of `Prim`s partitioned in place,
//! so the passes over them read memory in order; nodes with more than `PARALLEL_BALLS`
//! owned balls fork on rayon (both cores), smaller subtrees are built sequentially into one
//! chunk with their split lists on a stack, and the chunks are stitched once at the end in a
//! fixed order, so the tree is the same whatever the thread count.

use crate::geom::aabb::Aabb;
use crate::kinds::metaballs::kernel::Kernel;
use glam::Vec3;
use rayon::prelude::*;

/// Which of the paper's two structures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TreeKind {
    /// Algorithm 1: BVH with split metaballs.
    Bvh,
    /// Algorithm 2: the Fitted BVH.
    Fitted,
}

/// The leaf cost the SAH compares against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeafCost {
    /// `n²` (fitted-bvh-metaballs.txt §5.1.1).
    Squared,
    /// The classic `n`.
    Linear,
}

/// Every switch of the build.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildOptions {
    pub kind: TreeKind,
    pub leaf_cost: LeafCost,
    /// Fitted BVH only: intersect half boxes with the children's ball bounds (§5.1.2).
    pub fit_boxes: bool,
    /// Fitted BVH only: `min(R_i, r_max)` boxes (§5.3.1).
    pub tight_boxes: bool,
    /// Fitted BVH only: drop non-contributing split balls (§5.3.2).
    pub discard_split: bool,
    /// The lowest isovalue the §5.3 optimisations must stay correct for.
    pub isovalue: f32,
    /// SAH bins per axis.
    pub bins: usize,
    /// Cost of one traversal step in the units of the leaf cost (one ball for `n`, one
    /// field term at one sample for `n²`).
    pub traversal_cost: f32,
}

/// The SAH's traversal cost, from timing the paper scenes with `isoray-bench build`.
pub const DEFAULT_TRAVERSAL_COST: f32 = 4.0;

impl BuildOptions {
    /// The Fitted BVH with every optimisation of the paper.
    pub fn fitted(isovalue: f32) -> BuildOptions {
        BuildOptions {
            kind: TreeKind::Fitted,
            leaf_cost: LeafCost::Squared,
            fit_boxes: true,
            tight_boxes: true,
            discard_split: true,
            isovalue,
            bins: 16,
            traversal_cost: DEFAULT_TRAVERSAL_COST,
        }
    }

    /// Algorithm 1's BVH with the `n²` SAH.
    pub fn bvh() -> BuildOptions {
        BuildOptions {
            kind: TreeKind::Bvh,
            leaf_cost: LeafCost::Squared,
            fit_boxes: false,
            tight_boxes: false,
            discard_split: false,
            isovalue: 0.0,
            bins: 16,
            traversal_cost: DEFAULT_TRAVERSAL_COST,
        }
    }

    /// Whether the result depends on the isovalue (and so needs `isovalue` as a floor).
    pub fn depends_on_isovalue(&self) -> bool {
        self.kind == TreeKind::Fitted && (self.tight_boxes || self.discard_split)
    }
}

/// What the build needs of a ball: its bounding sphere and strength.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeBall {
    pub center: Vec3,
    pub radius: f32,
    pub strength: f32,
}

/// One node of the flattened tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    pub bounds: Aabb,
    /// Interior: index of the first child (the second is `first + 1`). Leaf: start in
    /// [`Tree::balls`].
    pub first: u32,
    /// Balls in the leaf (owned then split); 0 for an interior node.
    pub count: u32,
    /// How many of the leaf's balls it owns (the rest are split metaballs).
    pub owned: u32,
}

impl Node {
    pub fn is_leaf(&self) -> bool {
        self.count > 0 || self.first == u32::MAX
    }
}

/// A flattened BVH or FBVH: node 0 is the root.
#[derive(Clone, Debug, PartialEq)]
pub struct Tree {
    pub kind: TreeKind,
    pub nodes: Vec<Node>,
    pub balls: Vec<u32>,
}

/// What [`Tree::validate`] found wrong.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("node {node}: {problem}")]
pub struct TreeError {
    pub node: usize,
    pub problem: String,
}

/// Figures of a built tree.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TreeStats {
    pub nodes: usize,
    pub leaves: usize,
    pub max_depth: usize,
    /// Mean depth of a leaf (the root is at depth 1).
    pub mean_leaf_depth: f64,
    /// Mean owned and split balls per leaf.
    pub owned_per_leaf: f64,
    pub split_per_leaf: f64,
}

/// A subtree built on one thread: node 0 is its root; child and ball indices are local.
struct Chunk {
    nodes: Vec<Node>,
    balls: Vec<u32>,
}

/// The parallel top of the tree: joins of chunks, flattened once at the end.
enum Built {
    Chunk(Chunk),
    Join(Aabb, Box<(Built, Built)>),
}

const BLANK: Node = Node {
    bounds: Aabb::EMPTY,
    first: u32::MAX,
    count: 0,
    owned: 0,
};

/// A ball as the build moves it around: the owned balls of a node are a contiguous slice of
/// these, partitioned in place, so the passes over them read memory in order.
#[derive(Clone, Copy, Debug)]
struct Prim {
    center: Vec3,
    radius: f32,
    strength: f32,
    id: u32,
}

/// What one side of a split plane holds, gathered while binning.
#[derive(Clone, Copy, Debug)]
struct Side {
    /// Box of the side's own balls (radii `min(R, r_max)` with the parent's `r_max`, which
    /// is at least the child's: safe).
    bounds: Aabb,
    positive: u32,
    max_radius: f32,
}

/// The best split of a node.
#[derive(Clone, Copy, Debug)]
struct Choice {
    axis: usize,
    plane: f32,
    cost: f32,
    sides: [Side; 2],
}

/// A node's box, its `r_max` and the bounds of its owned balls' centres.
#[derive(Clone, Copy, Debug)]
struct Geom {
    bounds: Aabb,
    r_max: f32,
    centroids: (Vec3, Vec3),
}

/// A node's split balls and geometry.
struct NodeInput {
    split: Vec<u32>,
    geom: Geom,
}

/// Bounds of the centres of `prims`.
fn centroid_bounds(prims: &[Prim]) -> (Vec3, Vec3) {
    prims.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p.center), hi.max(p.center)),
    )
}

struct Ctx {
    centers: Vec<Vec3>,
    radii: Vec<f32>,
    strengths: Vec<f32>,
    kernel: Kernel,
    opts: BuildOptions,
    /// Algorithm 1: overlapping-sphere neighbours (CSR).
    neighbour_start: Vec<u32>,
    neighbours: Vec<u32>,
    /// The largest positive strength of the whole set: a node's `q_max` is at most this.
    q_max: f32,
    /// `sqrt(s*)` for `n = 0..S_TABLE` positive balls of strength `q_max`.
    root_s_star: Vec<f32>,
    /// Whether the build may fork on rayon.
    parallel: bool,
}

/// Per-thread buffers of the sequential build.
#[derive(Default)]
struct Scratch {
    /// The split lists of the nodes on the recursion path, each on top of its parent's.
    arena: Vec<u32>,
    /// A copy of the parent's split list while a child's is pushed.
    parent: Vec<u32>,
    /// Sorted ids of a BVH child's own balls (membership tests).
    sorted: Vec<u32>,
    keep: Vec<bool>,
    bins: Bins,
}

/// One SAH bin, and the difference-array entries of the plane at its left edge.
#[derive(Clone, Copy, Debug)]
struct Bin {
    count: u32,
    side: Side,
    cross_left: i32,
    cross_right: i32,
    split_left: i32,
    split_right: i32,
}

const EMPTY_SIDE: Side = Side {
    bounds: Aabb::EMPTY,
    positive: 0,
    max_radius: 0.0,
};

const EMPTY_BIN: Bin = Bin {
    count: 0,
    side: EMPTY_SIDE,
    cross_left: 0,
    cross_right: 0,
    split_left: 0,
    split_right: 0,
};

/// The binned SAH's arrays; a node clears only the bins it uses (small nodes use few, and
/// clearing sixteen of everything for every two-ball node was much of the build).
struct Bins {
    bins: [Bin; MAX_BINS + 1],
    right: [(u32, Side); MAX_BINS],
}

impl Default for Bins {
    fn default() -> Bins {
        Bins {
            bins: [EMPTY_BIN; MAX_BINS + 1],
            right: [(0, EMPTY_SIDE); MAX_BINS],
        }
    }
}

/// Node sizes whose `r_max` comes from a table rather than a bisection.
const S_TABLE: usize = 4096;
/// Split-metaball discarding (§5.3.2) costs `split × (owned + split)` per leaf; larger
/// leaves (rare: the SAH splits them) keep their lists.
const DISCARD_MAX_BALLS: usize = 96;

const MAX_DEPTH: usize = 64;
/// Nodes owning this many balls or fewer stay leaves: splitting them changed render work by
/// about 2% (Pool, counted instructions) and cost a seventh of the build.
const MIN_SPLIT_OWNED: usize = 2;
/// Most SAH bins per axis.
const MAX_BINS: usize = 16;
/// Nodes with more owned balls than this build their children in parallel; smaller ones are
/// built sequentially into one chunk.
const PARALLEL_BALLS: usize = 3072;

impl Tree {
    /// Builds the structure over `balls`.
    pub fn build(balls: &[TreeBall], kernel: Kernel, opts: BuildOptions) -> Tree {
        Tree::build_with(balls, kernel, opts, true)
    }

    /// [`Tree::build`] without forking: for a build inside a wait that other threads of the
    /// same pool may block on (a lazily built fallback), where a fork could make this thread
    /// run one of theirs, and so wait on itself.
    pub fn build_on_this_thread(balls: &[TreeBall], kernel: Kernel, opts: BuildOptions) -> Tree {
        Tree::build_with(balls, kernel, opts, false)
    }

    fn build_with(balls: &[TreeBall], kernel: Kernel, opts: BuildOptions, parallel: bool) -> Tree {
        let q_max = balls.iter().fold(0.0f32, |m, b| m.max(b.strength));
        let root_s_star = if opts.depends_on_isovalue() && opts.isovalue > 0.0 && q_max > 0.0 {
            (0..S_TABLE)
                .map(|n| {
                    kernel
                        .s_at_value(opts.isovalue / (n.max(1) as f32 * q_max))
                        .sqrt()
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut ctx = Ctx {
            centers: balls.iter().map(|b| b.center).collect(),
            radii: balls.iter().map(|b| b.radius).collect(),
            strengths: balls.iter().map(|b| b.strength).collect(),
            kernel,
            opts,
            neighbour_start: Vec::new(),
            neighbours: Vec::new(),
            q_max,
            root_s_star,
            parallel,
        };
        if opts.kind == TreeKind::Bvh {
            (ctx.neighbour_start, ctx.neighbours) = neighbour_lists(balls, parallel);
        }
        let mut prims: Vec<Prim> = balls
            .iter()
            .enumerate()
            .map(|(i, b)| Prim {
                center: b.center,
                radius: b.radius,
                strength: b.strength,
                id: i as u32,
            })
            .collect();
        let (positive, max_radius) = prims.iter().fold((0u32, 0.0f32), |(n, r), p| {
            (n + (p.strength > 0.0) as u32, r.max(p.radius))
        });
        let r_max = match opts.kind {
            TreeKind::Bvh => f32::INFINITY,
            TreeKind::Fitted => ctx.r_max_of(positive, max_radius),
        };
        let bounds = prims
            .iter()
            .fold(Aabb::EMPTY, |b, p| b.union(ctx.prim_box(p, r_max)));
        let root = NodeInput {
            split: Vec::new(),
            geom: Geom {
                bounds,
                r_max,
                centroids: centroid_bounds(&prims),
            },
        };
        let built = ctx.build_par(&mut prims, root, 0);
        let mut tree = Tree {
            kind: opts.kind,
            nodes: vec![BLANK],
            balls: Vec::with_capacity(balls.len() * 4),
        };
        tree.emit(built, 0);
        tree
    }

    /// Writes a built subtree with its root at `at`.
    fn emit(&mut self, built: Built, at: usize) {
        match built {
            Built::Join(bounds, children) => {
                let c = self.nodes.len();
                self.nodes.push(BLANK);
                self.nodes.push(BLANK);
                self.nodes[at] = Node {
                    bounds,
                    first: c as u32,
                    count: 0,
                    owned: 0,
                };
                let (left, right) = *children;
                self.emit(left, c);
                self.emit(right, c + 1);
            }
            Built::Chunk(chunk) => {
                // Chunk node 0 goes to `at`, node k ≥ 1 to `base + k - 1`.
                let base = self.nodes.len() as u32;
                let ball_base = self.balls.len() as u32;
                self.nodes[at] = remap(&chunk.nodes[0], base, ball_base);
                self.nodes
                    .extend(chunk.nodes[1..].iter().map(|n| remap(n, base, ball_base)));
                self.balls.extend_from_slice(&chunk.balls);
            }
        }
    }

    /// The balls of a leaf: owned first, then split.
    pub fn leaf_balls(&self, node: &Node) -> &[u32] {
        if node.count == 0 {
            return &[];
        }
        &self.balls[node.first as usize..(node.first + node.count) as usize]
    }

    /// Counts nodes, leaves, depth and balls per leaf.
    pub fn stats(&self) -> TreeStats {
        let mut s = TreeStats {
            nodes: self.nodes.len(),
            ..TreeStats::default()
        };
        let mut stack = vec![(0usize, 1usize)];
        let (mut owned, mut split) = (0usize, 0usize);
        while let Some((i, depth)) = stack.pop() {
            let n = &self.nodes[i];
            s.max_depth = s.max_depth.max(depth);
            if n.is_leaf() {
                s.leaves += 1;
                s.mean_leaf_depth += depth as f64;
                owned += n.owned as usize;
                split += (n.count - n.owned) as usize;
            } else {
                stack.push((n.first as usize, depth + 1));
                stack.push((n.first as usize + 1, depth + 1));
            }
        }
        s.mean_leaf_depth /= s.leaves.max(1) as f64;
        s.owned_per_leaf = owned as f64 / s.leaves.max(1) as f64;
        s.split_per_leaf = split as f64 / s.leaves.max(1) as f64;
        s
    }

    /// Checks the structure's invariants: children after their parent and in range, child
    /// boxes inside the parent's, Fitted siblings disjoint, every ball owned by exactly one
    /// leaf, leaf ranges in bounds.
    pub fn validate(&self, ball_count: usize) -> Result<(), TreeError> {
        let err = |node: usize, problem: String| Err(TreeError { node, problem });
        if self.nodes.is_empty() {
            return err(0, "no root".into());
        }
        let mut owners = vec![0u32; ball_count];
        let mut stack = vec![0usize];
        let mut visited = 0usize;
        while let Some(i) = stack.pop() {
            visited += 1;
            if visited > self.nodes.len() {
                return err(i, "cycle".into());
            }
            let n = &self.nodes[i];
            if n.is_leaf() {
                if n.count == 0 {
                    continue;
                }
                let end = n.first as usize + n.count as usize;
                if end > self.balls.len() || n.owned > n.count {
                    return err(i, format!("leaf range {}..{end} out of bounds", n.first));
                }
                for (k, &b) in self.leaf_balls(n).iter().enumerate() {
                    if b as usize >= ball_count {
                        return err(i, format!("ball index {b} out of range"));
                    }
                    if k < n.owned as usize {
                        owners[b as usize] += 1;
                    }
                }
                continue;
            }
            let c = n.first as usize;
            if c <= i || c + 1 >= self.nodes.len() {
                return err(i, format!("children {c} out of order or range"));
            }
            let slack = 1e-4 * (1.0 + n.bounds.max.abs().max(n.bounds.min.abs()).max_element());
            for child in [c, c + 1] {
                if !n.bounds.contains_box(&self.nodes[child].bounds, slack) {
                    return err(child, "box escapes its parent".into());
                }
            }
            if self.kind == TreeKind::Fitted {
                let overlap = self.nodes[c].bounds.intersection(self.nodes[c + 1].bounds);
                let extent = overlap.max - overlap.min;
                if !overlap.is_empty() && extent.min_element() > slack {
                    return err(i, "fitted siblings overlap".into());
                }
            }
            stack.push(c);
            stack.push(c + 1);
        }
        if let Some(b) = owners.iter().position(|&k| k != 1) {
            return err(0, format!("ball {b} is owned by {} leaves", owners[b]));
        }
        Ok(())
    }
}

impl Ctx {
    /// A ball's box with radius `min(R_i, r_max)` when tight boxes are on.
    #[inline]
    fn ball_box(&self, center: Vec3, radius: f32, r_max: f32) -> Aabb {
        let r = if self.opts.tight_boxes && self.opts.kind == TreeKind::Fitted {
            radius.min(r_max)
        } else {
            radius
        };
        Aabb::around(center, r)
    }

    #[inline]
    fn prim_box(&self, p: &Prim, r_max: f32) -> Aabb {
        self.ball_box(p.center, p.radius, r_max)
    }

    /// The largest box radius of any ball: `r_max` with tight boxes, unbounded otherwise.
    #[inline]
    fn radius_cap(&self, r_max: f32) -> f32 {
        if self.opts.tight_boxes && self.opts.kind == TreeKind::Fitted {
            r_max
        } else {
            f32::INFINITY
        }
    }

    /// §5.3.1: no surface made by `positive` balls of strength at most `q_max` and radius at
    /// most `max_radius` lies farther than `r_max` from all their centres.
    fn r_max_of(&self, positive: u32, max_radius: f32) -> f32 {
        if !self.opts.depends_on_isovalue() || self.opts.isovalue <= 0.0 {
            return f32::INFINITY;
        }
        if positive == 0 || self.q_max <= 0.0 {
            return 0.0;
        }
        let n = positive as usize;
        let root = match self.root_s_star.get(n) {
            Some(&r) => r,
            None => self
                .kernel
                .s_at_value(self.opts.isovalue / (n as f32 * self.q_max))
                .sqrt(),
        };
        // A hair of margin against rounding in the inverse.
        max_radius * root * 1.0001 + 1e-6
    }

    fn leaf_cost(&self, n: f32) -> f32 {
        match self.opts.leaf_cost {
            LeafCost::Squared => n * n,
            LeafCost::Linear => n,
        }
    }

    /// Binned SAH over the owned centroids along their longest axis (Wald 2007, as the
    /// paper). A child's ball count is its owned balls plus the split balls it will get: the
    /// parent's split balls that reach its side of the plane and the other side's owned balls
    /// whose spheres cross the plane (both counted along the axis only).
    fn best_split(
        &self,
        owned: &[Prim],
        centroids: (Vec3, Vec3),
        split: &[u32],
        bounds: &Aabb,
        r_max: f32,
        scratch: &mut Bins,
    ) -> Option<Choice> {
        let (cmin, cmax) = centroids;
        let extent = cmax - cmin;
        let axis = extent.max_position();
        let (lo, hi) = (cmin[axis], cmax[axis]);
        if !(hi - lo > 1e-6 * (1.0 + hi.abs().max(lo.abs()))) {
            return None;
        }
        // Small nodes need few bins: two per ball separates every pair of centres' halves.
        let bins = self.opts.bins.min(2 * owned.len()).clamp(2, MAX_BINS);
        let scale = bins as f32 / (hi - lo);
        let top = (bins - 1) as f32;
        let bin = |x: f32| ((x - lo) * scale).max(0.0).min(top) as usize;
        let cap = self.radius_cap(r_max);
        let Bins { bins: table, right } = scratch;
        let table = &mut table[..=bins];
        table.fill(EMPTY_BIN);
        // `cross_*` and `split_*` are difference arrays over the plane index p (plane p lies
        // between bins p-1 and p).
        for p in owned {
            let c = p.center.to_array()[axis];
            let k = bin(c);
            let b = &mut table[k];
            b.count += 1;
            b.side.bounds = b
                .side
                .bounds
                .union(Aabb::around(p.center, p.radius.min(cap)));
            b.side.positive += (p.strength > 0.0) as u32;
            b.side.max_radius = b.side.max_radius.max(p.radius);
            // Reaches left of plane p for p in (bin(c - r), k]; right for p in (k, bin(c + r)].
            table[bin(c - p.radius) + 1].cross_left += 1;
            table[k + 1].cross_left -= 1;
            table[k + 1].cross_right += 1;
            table[bin(c + p.radius) + 1].cross_right -= 1;
        }
        for &i in split {
            let c = self.centers[i as usize].to_array()[axis];
            let r = self.radii[i as usize];
            // Goes left for p > bin(c - r), right for p ≤ bin(c + r).
            table[bin(c - r) + 1].split_left += 1;
            table[0].split_right += 1;
            table[bin(c + r) + 1].split_right -= 1;
        }
        let merge = |a: Side, b: Side| Side {
            bounds: a.bounds.union(b.bounds),
            positive: a.positive + b.positive,
            max_radius: a.max_radius.max(b.max_radius),
        };
        let mut acc = (0u32, EMPTY_SIDE);
        for k in (1..bins).rev() {
            acc = (acc.0 + table[k].count, merge(acc.1, table[k].side));
            right[k] = acc;
        }
        let parent_area = bounds.area().max(1e-20);
        let mut best: Option<Choice> = None;
        let mut left = (0u32, EMPTY_SIDE);
        let (mut xl, mut xr) = (0i32, 0i32);
        let (mut sl, mut sr) = (0i32, table[0].split_right);
        for p in 1..bins {
            left = (
                left.0 + table[p - 1].count,
                merge(left.1, table[p - 1].side),
            );
            xl += table[p].cross_left;
            xr += table[p].cross_right;
            sl += table[p].split_left;
            sr += table[p].split_right;
            let (nr_owned, rs) = right[p];
            if left.0 == 0 || nr_owned == 0 {
                continue;
            }
            let plane = lo + p as f32 / scale;
            let (al, ar) = match self.opts.kind {
                TreeKind::Bvh => (left.1.bounds.area(), rs.bounds.area()),
                TreeKind::Fitted => (
                    clipped_area(bounds, &left.1.bounds, axis, plane, true),
                    clipped_area(bounds, &rs.bounds, axis, plane, false),
                ),
            };
            let nl = (left.0 as i32 + xl + sl) as f32;
            let nr = (nr_owned as i32 + xr + sr) as f32;
            let cost = self.opts.traversal_cost
                + (al / parent_area) * self.leaf_cost(nl)
                + (ar / parent_area) * self.leaf_cost(nr);
            if best.is_none_or(|b| cost < b.cost) {
                best = Some(Choice {
                    axis,
                    plane,
                    cost,
                    sides: [left.1, rs],
                });
            }
        }
        best
    }

    /// Moves the balls with centres below `plane` to the front; returns how many there are
    /// and the bounds of each side's centres.
    fn partition(owned: &mut [Prim], axis: usize, plane: f32) -> (usize, [(Vec3, Vec3); 2]) {
        let empty = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let mut sides = [empty; 2];
        let (mut i, mut j) = (0, owned.len());
        while i < j {
            let c = owned[i].center;
            let right = !(c.to_array()[axis] < plane);
            let s = &mut sides[usize::from(right)];
            s.0 = s.0.min(c);
            s.1 = s.1.max(c);
            if right {
                j -= 1;
                owned.swap(i, j);
            } else {
                i += 1;
            }
        }
        (i, sides)
    }

    /// A leaf's split list after §5.3.2 (Fitted BVH with discarding on).
    fn finish_leaf(
        &self,
        owned: &[Prim],
        split: &mut Vec<u32>,
        from: usize,
        geom: &Geom,
        keep: &mut Vec<bool>,
    ) {
        let n_split = split.len() - from;
        if self.opts.kind == TreeKind::Fitted
            && self.opts.discard_split
            && n_split > 0
            && owned.len() + n_split <= DISCARD_MAX_BALLS
        {
            self.discard(owned, split, from, &geom.bounds, geom.r_max, keep);
        }
    }

    /// §5.3.2 on the split list `split` (in place, in `keep`'s order): drops the positive
    /// split balls whose `r_max` sphere misses `bounds` and whose centre lies at least
    /// `R_i + r_max` from every other ball of the node. Any surface point in the box lies
    /// within `r_max` of a positive centre `j` of the node, `j ≠ i`, so such a ball is zero
    /// there; dropping several at once is safe for the same reason.
    fn discard(
        &self,
        owned: &[Prim],
        split: &mut Vec<u32>,
        from: usize,
        bounds: &Aabb,
        r_max: f32,
        keep: &mut Vec<bool>,
    ) {
        if !r_max.is_finite() {
            return;
        }
        keep.clear();
        for &i in &split[from..] {
            let (c, r) = (self.centers[i as usize], self.radii[i as usize]);
            let kept = self.strengths[i as usize] <= 0.0 || bounds.overlaps_sphere(c, r_max) || {
                let reach2 = (r + r_max) * (r + r_max);
                owned
                    .iter()
                    .any(|p| (c - p.center).length_squared() < reach2)
                    || split[from..].iter().any(|&j| {
                        j != i && (c - self.centers[j as usize]).length_squared() < reach2
                    })
            };
            keep.push(kept);
        }
        let mut w = from;
        for k in 0..keep.len() {
            if keep[k] {
                split[w] = split[from + k];
                w += 1;
            }
        }
        split.truncate(w);
    }

    /// Decides whether the node with these owned balls and split list `split[from..]` is
    /// split.
    fn choose(
        &self,
        owned: &[Prim],
        split: &[u32],
        from: usize,
        geom: &Geom,
        depth: usize,
        bins: &mut Bins,
    ) -> Option<Choice> {
        let fitted = self.opts.kind == TreeKind::Fitted;
        let n = (owned.len() + split.len() - from) as f32;
        if owned.len() <= MIN_SPLIT_OWNED
            || depth >= MAX_DEPTH
            || (fitted && geom.bounds.is_empty())
        {
            return None;
        }
        let choice = self.best_split(
            owned,
            geom.centroids,
            &split[from..],
            &geom.bounds,
            geom.r_max,
            bins,
        )?;
        (choice.cost < self.leaf_cost(n)).then_some(choice)
    }

    /// Pushes onto `out` the split balls of the child that owns `own` (side `side` of the
    /// plane), and returns its box and `r_max`: Algorithm 2, lines 11–18, for the Fitted
    /// BVH; Algorithm 1, lines 14–19, for the BVH.
    #[allow(clippy::too_many_arguments)]
    fn child(
        &self,
        out: &mut Vec<u32>,
        sorted: &mut Vec<u32>,
        parent_split: &[u32],
        own: &[Prim],
        other: &[Prim],
        choice: &Choice,
        parent_bounds: &Aabb,
        left: bool,
    ) -> (Aabb, f32) {
        let side = choice.sides[usize::from(!left)];
        let (axis, plane) = (choice.axis, choice.plane);
        let start = out.len();
        match self.opts.kind {
            TreeKind::Fitted => {
                let (lh, rh) = split_box(parent_bounds, axis, plane);
                let half = if left { lh } else { rh };
                let (mut positive, mut max_radius) = (side.positive, side.max_radius);
                for &i in parent_split {
                    let (c, r) = (self.centers[i as usize], self.radii[i as usize]);
                    if half.overlaps_sphere(c, r) {
                        out.push(i);
                        positive += (self.strengths[i as usize] > 0.0) as u32;
                        max_radius = max_radius.max(r);
                    }
                }
                for p in other {
                    let c = p.center.to_array()[axis];
                    let crosses = if left {
                        c - p.radius <= plane
                    } else {
                        c + p.radius >= plane
                    };
                    if crosses && half.overlaps_sphere(p.center, p.radius) {
                        out.push(p.id);
                        positive += (p.strength > 0.0) as u32;
                        max_radius = max_radius.max(p.radius);
                    }
                }
                let r_child = self.r_max_of(positive, max_radius);
                let bounds = if self.opts.fit_boxes {
                    let cap = self.radius_cap(r_child);
                    let balls = out[start..].iter().fold(side.bounds, |b, &i| {
                        let r = self.radii[i as usize].min(cap);
                        b.union(Aabb::around(self.centers[i as usize], r))
                    });
                    half.intersection(balls)
                } else {
                    half
                };
                (bounds, r_child)
            }
            TreeKind::Bvh => {
                let bounds = side.bounds;
                sorted.clear();
                sorted.extend(own.iter().map(|p| p.id));
                sorted.sort_unstable();
                let candidates = parent_split
                    .iter()
                    .copied()
                    .chain(other.iter().map(|p| p.id));
                for i in candidates {
                    if bounds.overlaps_sphere(self.centers[i as usize], self.radii[i as usize])
                        && self
                            .neighbours_of(i)
                            .iter()
                            .any(|j| sorted.binary_search(j).is_ok())
                    {
                        out.push(i);
                    }
                }
                (bounds, f32::INFINITY)
            }
        }
    }

    fn neighbours_of(&self, i: u32) -> &[u32] {
        let s = self.neighbour_start[i as usize] as usize;
        let e = self.neighbour_start[i as usize + 1] as usize;
        &self.neighbours[s..e]
    }

    /// The top of the tree, forking on rayon; small subtrees are built sequentially.
    fn build_par(&self, owned: &mut [Prim], node: NodeInput, depth: usize) -> Built {
        let mut scratch = Scratch::default();
        let geom = node.geom;
        if !self.parallel || owned.len() <= PARALLEL_BALLS {
            let mut chunk = Chunk {
                nodes: vec![BLANK],
                balls: Vec::with_capacity(owned.len() * 4),
            };
            scratch.arena = node.split;
            self.build_seq(&mut chunk, &mut scratch, 0, owned, 0, &geom, depth);
            return Built::Chunk(chunk);
        }
        let mut split = node.split;
        let choice = self.choose(owned, &split, 0, &geom, depth, &mut scratch.bins);
        let parts = choice.map(|c| (c, Ctx::partition(owned, c.axis, c.plane)));
        let Some((choice, (mid, centroids))) =
            parts.filter(|(_, (m, _))| *m > 0 && *m < owned.len())
        else {
            let mut chunk = Chunk {
                nodes: vec![BLANK],
                balls: Vec::new(),
            };
            self.finish_leaf(owned, &mut split, 0, &geom, &mut scratch.keep);
            chunk.nodes[0] = leaf(&mut chunk.balls, geom.bounds, owned, &split);
            return Built::Chunk(chunk);
        };
        let (lo, ro) = owned.split_at_mut(mid);
        let make = |own: &[Prim], other: &[Prim], left: bool| {
            let mut out = Vec::new();
            let (bounds, r_max) = self.child(
                &mut out,
                &mut Vec::new(),
                &split,
                own,
                other,
                &choice,
                &geom.bounds,
                left,
            );
            NodeInput {
                split: out,
                geom: Geom {
                    bounds,
                    r_max,
                    centroids: centroids[usize::from(!left)],
                },
            }
        };
        let (l, r) = rayon::join(|| make(lo, ro, true), || make(ro, lo, false));
        let (left, right) = rayon::join(
            || self.build_par(lo, l, depth + 1),
            || self.build_par(ro, r, depth + 1),
        );
        Built::Join(geom.bounds, Box::new((left, right)))
    }

    /// Builds the subtree whose split list is `scratch.arena[from..]` into `chunk` at `at`;
    /// on return the arena is back to `from` entries.
    #[allow(clippy::too_many_arguments)]
    fn build_seq(
        &self,
        chunk: &mut Chunk,
        scratch: &mut Scratch,
        at: usize,
        owned: &mut [Prim],
        from: usize,
        geom: &Geom,
        depth: usize,
    ) {
        let choice = self.choose(owned, &scratch.arena, from, geom, depth, &mut scratch.bins);
        let parts = choice.map(|c| (c, Ctx::partition(owned, c.axis, c.plane)));
        let Some((choice, (mid, centroids))) =
            parts.filter(|(_, (m, _))| *m > 0 && *m < owned.len())
        else {
            self.finish_leaf(owned, &mut scratch.arena, from, geom, &mut scratch.keep);
            chunk.nodes[at] = leaf(&mut chunk.balls, geom.bounds, owned, &scratch.arena[from..]);
            scratch.arena.truncate(from);
            return;
        };
        let c = chunk.nodes.len();
        chunk.nodes.push(BLANK);
        chunk.nodes.push(BLANK);
        chunk.nodes[at] = Node {
            bounds: geom.bounds,
            first: c as u32,
            count: 0,
            owned: 0,
        };
        let (lo, ro) = owned.split_at_mut(mid);
        for (left, slot) in [(true, c), (false, c + 1)] {
            let (own, other) = if left {
                (&mut *lo, &*ro)
            } else {
                (&mut *ro, &*lo)
            };
            scratch.parent.clear();
            let end = scratch.arena.len();
            scratch.parent.extend_from_slice(&scratch.arena[from..end]);
            let (bounds, r_max) = self.child(
                &mut scratch.arena,
                &mut scratch.sorted,
                &scratch.parent,
                own,
                other,
                &choice,
                &geom.bounds,
                left,
            );
            let child = Geom {
                bounds,
                r_max,
                centroids: centroids[usize::from(!left)],
            };
            self.build_seq(chunk, scratch, slot, own, end, &child, depth + 1);
        }
        scratch.arena.truncate(from);
    }
}

/// A chunk's node moved into the tree: children from local index `k ≥ 1` to `base + k - 1`,
/// leaf balls shifted by `ball_base`.
fn remap(n: &Node, base: u32, ball_base: u32) -> Node {
    if n.count > 0 {
        Node {
            first: n.first + ball_base,
            ..*n
        }
    } else if n.first == u32::MAX {
        *n
    } else {
        Node {
            first: base + n.first - 1,
            ..*n
        }
    }
}

/// A leaf node over `owned` then `split`, its balls appended to `balls`.
fn leaf(balls: &mut Vec<u32>, bounds: Aabb, owned: &[Prim], split: &[u32]) -> Node {
    let count = (owned.len() + split.len()) as u32;
    if count == 0 {
        return Node { bounds, ..BLANK };
    }
    let first = balls.len() as u32;
    balls.extend(owned.iter().map(|p| p.id));
    balls.extend_from_slice(split);
    Node {
        bounds,
        first,
        count,
        owned: owned.len() as u32,
    }
}

/// The area of `b ∩ half`, `half` the side of `parent` below (`left`) or above `plane`.
#[inline]
fn clipped_area(parent: &Aabb, b: &Aabb, axis: usize, plane: f32, left: bool) -> f32 {
    let mut min = parent.min.max(b.min).to_array();
    let mut max = parent.max.min(b.max).to_array();
    if left {
        max[axis] = max[axis].min(plane);
    } else {
        min[axis] = min[axis].max(plane);
    }
    let d = [max[0] - min[0], max[1] - min[1], max[2] - min[2]];
    if d[0] < 0.0 || d[1] < 0.0 || d[2] < 0.0 {
        return 0.0;
    }
    2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
}

/// The box cut at `plane` along `axis`, the plane clamped into the box.
fn split_box(b: &Aabb, axis: usize, plane: f32) -> (Aabb, Aabb) {
    let plane = plane.clamp(b.min[axis], b.max[axis]);
    let mut left = *b;
    let mut right = *b;
    left.max[axis] = plane;
    right.min[axis] = plane;
    (left, right)
}

/// For every ball, the balls whose sphere overlaps its sphere, from a uniform grid of cell
/// size `2 R_max` (compressed rows, each sorted).
fn neighbour_lists(balls: &[TreeBall], parallel: bool) -> (Vec<u32>, Vec<u32>) {
    let n = balls.len();
    if n == 0 {
        return (vec![0], Vec::new());
    }
    let r_max = balls.iter().fold(0.0f32, |m, b| m.max(b.radius));
    let cell = (2.0 * r_max).max(1e-6);
    let lo = balls
        .iter()
        .fold(Vec3::splat(f32::INFINITY), |m, b| m.min(b.center));
    let key = |p: Vec3| -> [i32; 3] {
        let c = ((p - lo) / cell).floor();
        [c.x as i32, c.y as i32, c.z as i32]
    };
    let hash = |k: [i32; 3]| -> u64 {
        (k[0] as u64 & 0x1F_FFFF)
            | ((k[1] as u64 & 0x1F_FFFF) << 21)
            | ((k[2] as u64 & 0x1F_FFFF) << 42)
    };
    let keyed_of = |(i, b): (usize, &TreeBall)| (hash(key(b.center)), i as u32);
    let keyed: Vec<(u64, u32)> = if parallel {
        let mut k: Vec<(u64, u32)> = balls.par_iter().enumerate().map(keyed_of).collect();
        k.par_sort_unstable();
        k
    } else {
        let mut k: Vec<(u64, u32)> = balls.iter().enumerate().map(keyed_of).collect();
        k.sort_unstable();
        k
    };
    let list_of = |(i, b): (usize, &TreeBall)| {
        let k = key(b.center);
        let mut out = Vec::new();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let h = hash([k[0] + dx, k[1] + dy, k[2] + dz]);
                    let start = keyed.partition_point(|e| e.0 < h);
                    for &(kh, j) in &keyed[start..] {
                        if kh != h {
                            break;
                        }
                        let o = &balls[j as usize];
                        let reach = b.radius + o.radius;
                        if j as usize != i && (b.center - o.center).length_squared() < reach * reach
                        {
                            out.push(j);
                        }
                    }
                }
            }
        }
        out.sort_unstable();
        out
    };
    let lists: Vec<Vec<u32>> = if parallel {
        balls.par_iter().enumerate().map(list_of).collect()
    } else {
        balls.iter().enumerate().map(list_of).collect()
    };
    let mut start = Vec::with_capacity(n + 1);
    start.push(0u32);
    let mut flat = Vec::with_capacity(lists.iter().map(Vec::len).sum());
    for l in &lists {
        flat.extend_from_slice(l);
        start.push(flat.len() as u32);
    }
    (start, flat)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize) -> Vec<TreeBall> {
        let mut rng = crate::geom::rng::SplitMix64(7);
        (0..n)
            .map(|_| TreeBall {
                center: Vec3::new(
                    rng.range(-5.0, 5.0),
                    rng.range(-5.0, 5.0),
                    rng.range(-5.0, 5.0),
                ),
                radius: rng.range(0.3, 0.9),
                strength: 1.0,
            })
            .collect()
    }

    #[test]
    fn both_trees_validate_and_are_deterministic() {
        let balls = cloud(3000);
        for opts in [BuildOptions::bvh(), BuildOptions::fitted(0.5)] {
            let tree = Tree::build(&balls, Kernel::Wyvill, opts);
            tree.validate(balls.len()).expect("valid tree");
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .expect("pool")
                .install(|| Tree::build(&balls, Kernel::Wyvill, opts));
            assert_eq!(tree, one, "{:?} depends on the thread count", opts.kind);
            assert!(tree.stats().leaves > 10);
        }
    }

    #[test]
    fn validate_catches_a_doubly_owned_ball() {
        let balls = cloud(200);
        let mut tree = Tree::build(&balls, Kernel::Wyvill, BuildOptions::fitted(0.5));
        let leaf = tree
            .nodes
            .iter()
            .position(|n| n.is_leaf() && n.owned > 0)
            .expect("a leaf");
        let first = tree.nodes[leaf].first as usize;
        let other = (tree.balls[first] + 1) % 200;
        tree.balls[first] = other;
        assert!(tree.validate(balls.len()).is_err());
    }
}
