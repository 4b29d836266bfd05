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
//! - §5.1: binned SAH with the leaf cost `n²` (or `n`, switchable), `n` counting split balls.
//! - §5.3.1: tighter boxes: a ball's box uses `min(R_i, r_max)` with
//!   `r_max = R_K · sqrt(s*)`, `f(s*) = T / (n q_max)` (the paper's `(1-(T/n)^{1/α})^{1/2}`
//!   for its kernel, generalised to any kernel and strength).
//! - §5.3.2: a positive split ball is discarded when its `r_max` sphere misses the node's box
//!   and it lies at least `max(R_i, R_j) + r_max` from every other ball `j` of the node.
//!
//! The recursion forks on rayon for large nodes; children are flattened in a fixed order, so
//! the tree is the same whatever the thread count.

use super::Kernel;
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
}

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

/// An axis-aligned box; empty when `min > max` on some axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn around(center: Vec3, radius: f32) -> Aabb {
        Aabb {
            min: center - Vec3::splat(radius),
            max: center + Vec3::splat(radius),
        }
    }

    pub fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    pub fn intersection(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.max(o.min),
            max: self.max.min(o.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    pub fn area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let d = self.max - self.min;
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }

    /// Whether the sphere overlaps the box (closed).
    pub fn overlaps_sphere(&self, center: Vec3, radius: f32) -> bool {
        let d = center - center.clamp(self.min, self.max);
        !self.is_empty() && d.length_squared() <= radius * radius
    }

    pub fn contains_box(&self, o: &Aabb, slack: f32) -> bool {
        o.is_empty()
            || (o.min.cmpge(self.min - Vec3::splat(slack)).all()
                && o.max.cmple(self.max + Vec3::splat(slack)).all())
    }

    /// The ray's parameter range inside the box, given `1/dir`.
    #[inline]
    pub fn ray_range(
        &self,
        origin: Vec3,
        inv_dir: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32)> {
        let t0 = (self.min - origin) * inv_dir;
        let t1 = (self.max - origin) * inv_dir;
        let near = t0.min(t1).max_element().max(t_min);
        let far = t0.max(t1).min_element().min(t_max);
        (near <= far).then_some((near, far))
    }
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
    /// Mean owned and split balls per leaf.
    pub owned_per_leaf: f64,
    pub split_per_leaf: f64,
}

enum BuildNode {
    Leaf {
        bounds: Aabb,
        owned: Vec<u32>,
        split: Vec<u32>,
    },
    Interior {
        bounds: Aabb,
        children: Box<[BuildNode; 2]>,
    },
}

struct Ctx<'a> {
    balls: &'a [TreeBall],
    kernel: Kernel,
    opts: BuildOptions,
    /// Algorithm 1: overlapping-sphere neighbours (CSR).
    neighbour_start: Vec<u32>,
    neighbours: Vec<u32>,
    /// The largest positive strength of the whole set: a node's `q_max` is at most this.
    q_max: f32,
    /// `sqrt(s*)` for `n = 0..S_TABLE` positive balls of strength `q_max`.
    root_s_star: Vec<f32>,
}

/// Node sizes whose `r_max` comes from a table rather than a bisection.
const S_TABLE: usize = 4096;
/// Split-metaball discarding (§5.3.2) costs `n × split` per node; it runs on nodes up to this
/// size, where leaves form and it pays.
const DISCARD_MAX_BALLS: usize = 512;

const MAX_DEPTH: usize = 64;
/// Most SAH bins per axis.
const MAX_BINS: usize = 16;
/// Nodes with more balls than this build their children in parallel.
const PARALLEL_BALLS: usize = 2048;
/// Cost of one traversal step relative to one field term, for the SAH.
const TRAVERSAL_COST: f32 = 2.0;

impl Tree {
    /// Builds the structure over `balls`.
    pub fn build(balls: &[TreeBall], kernel: Kernel, opts: BuildOptions) -> Tree {
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
            balls,
            kernel,
            opts,
            neighbour_start: Vec::new(),
            neighbours: Vec::new(),
            q_max,
            root_s_star,
        };
        if opts.kind == TreeKind::Bvh {
            (ctx.neighbour_start, ctx.neighbours) = neighbour_lists(balls);
        }
        let owned: Vec<u32> = (0..balls.len() as u32).collect();
        let bounds = owned
            .iter()
            .fold(Aabb::EMPTY, |b, &i| b.union(ctx.ball_box(i, f32::INFINITY)));
        let root = match opts.kind {
            TreeKind::Bvh => ctx.build_bvh(owned, Vec::new(), bounds, 0),
            TreeKind::Fitted => {
                let r_max = ctx.r_max(&owned, &[]);
                let bounds = owned
                    .iter()
                    .fold(Aabb::EMPTY, |b, &i| b.union(ctx.ball_box(i, r_max)));
                ctx.build_fitted(owned, Vec::new(), bounds, r_max, 0)
            }
        };
        let mut tree = Tree {
            kind: opts.kind,
            nodes: vec![Node {
                bounds: Aabb::EMPTY,
                first: 0,
                count: 0,
                owned: 0,
            }],
            balls: Vec::with_capacity(balls.len() * 2),
        };
        tree.flatten(root, 0);
        tree
    }

    fn flatten(&mut self, node: BuildNode, at: usize) {
        match node {
            BuildNode::Leaf {
                bounds,
                owned,
                split,
            } => {
                let first = self.balls.len() as u32;
                self.balls.extend_from_slice(&owned);
                self.balls.extend_from_slice(&split);
                self.nodes[at] = Node {
                    bounds,
                    first,
                    count: (owned.len() + split.len()) as u32,
                    owned: owned.len() as u32,
                };
                if self.nodes[at].count == 0 {
                    // An empty leaf: mark it so it is not read as an interior node.
                    self.nodes[at].first = u32::MAX;
                }
            }
            BuildNode::Interior { bounds, children } => {
                let first = self.nodes.len();
                let blank = self.nodes[at];
                self.nodes.push(blank);
                self.nodes.push(blank);
                self.nodes[at] = Node {
                    bounds,
                    first: first as u32,
                    count: 0,
                    owned: 0,
                };
                let [left, right] = *children;
                self.flatten(left, first);
                self.flatten(right, first + 1);
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
                owned += n.owned as usize;
                split += (n.count - n.owned) as usize;
            } else {
                stack.push((n.first as usize, depth + 1));
                stack.push((n.first as usize + 1, depth + 1));
            }
        }
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

impl Ctx<'_> {
    /// A ball's box with radius `min(R_i, r_max)` when tight boxes are on.
    fn ball_box(&self, i: u32, r_max: f32) -> Aabb {
        let b = &self.balls[i as usize];
        let r = if self.opts.tight_boxes && self.opts.kind == TreeKind::Fitted {
            b.radius.min(r_max)
        } else {
            b.radius
        };
        Aabb::around(b.center, r)
    }

    /// §5.3.1: no surface made by these balls lies farther than `r_max` from all centres.
    /// Uses the whole set's largest strength, which only makes `r_max` larger (safe).
    fn r_max(&self, owned: &[u32], split: &[u32]) -> f32 {
        if !self.opts.depends_on_isovalue() || self.opts.isovalue <= 0.0 {
            return f32::INFINITY;
        }
        let (mut n, mut r_k) = (0usize, 0.0f32);
        for &i in owned.iter().chain(split) {
            let b = &self.balls[i as usize];
            n += (b.strength > 0.0) as usize;
            r_k = r_k.max(b.radius);
        }
        if n == 0 || self.q_max <= 0.0 {
            return 0.0;
        }
        let root = match self.root_s_star.get(n) {
            Some(&r) => r,
            None => self
                .kernel
                .s_at_value(self.opts.isovalue / (n as f32 * self.q_max))
                .sqrt(),
        };
        // A hair of margin against rounding in the inverse.
        r_k * root * 1.0001 + 1e-6
    }

    fn leaf_cost_f(&self, n: f32) -> f32 {
        match self.opts.leaf_cost {
            LeafCost::Squared => n * n,
            LeafCost::Linear => n,
        }
    }

    fn leaf_cost(&self, n: usize) -> f32 {
        match self.opts.leaf_cost {
            LeafCost::Squared => (n * n) as f32,
            LeafCost::Linear => n as f32,
        }
    }

    /// Binned SAH over the owned centroids: `(axis, plane, cost)` of the best split.
    fn best_split(
        &self,
        owned: &[u32],
        split_count: usize,
        bounds: &Aabb,
        r_max: f32,
    ) -> Option<(usize, f32, f32)> {
        // Small nodes need few bins: two per ball separates every pair of centres' halves.
        let bins = self.opts.bins.min(2 * owned.len()).clamp(2, MAX_BINS);
        let (cmin, cmax) = owned.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &i| {
                let c = self.balls[i as usize].center;
                (lo.min(c), hi.max(c))
            },
        );
        let parent_area = bounds.area().max(1e-20);
        let mut best: Option<(usize, f32, f32)> = None;
        let extent = cmax - cmin;
        let scale = Vec3::splat(bins as f32) / extent.max(Vec3::splat(1e-30));
        // As in Wald 2007, which the paper follows: bin along the centroids' longest axis.
        let axis = extent.max_position();
        let mut count = [0usize; MAX_BINS];
        let mut boxes = [Aabb::EMPTY; MAX_BINS];
        let k_max = bins - 1;
        for &i in owned {
            let c = self.balls[i as usize].center[axis];
            let k = (((c - cmin[axis]) * scale[axis]) as usize).min(k_max);
            count[k] += 1;
            boxes[k] = boxes[k].union(self.ball_box(i, r_max));
        }
        {
            let (lo, hi) = (cmin[axis], cmax[axis]);
            if !(hi - lo > 1e-6 * (1.0 + hi.abs().max(lo.abs()))) {
                return None;
            }
            let scale = scale[axis];
            // Sweep from the right, then from the left.
            let mut right = [(0usize, Aabb::EMPTY); MAX_BINS];
            let mut acc = (0usize, Aabb::EMPTY);
            for k in (1..bins).rev() {
                acc = (acc.0 + count[k], acc.1.union(boxes[k]));
                right[k] = acc;
            }
            let mut left = (0usize, Aabb::EMPTY);
            for k in 1..bins {
                left = (left.0 + count[k - 1], left.1.union(boxes[k - 1]));
                let (nr, br) = right[k];
                if left.0 == 0 || nr == 0 {
                    continue;
                }
                let plane = lo + k as f32 / scale;
                let (al, ar) = match self.opts.kind {
                    TreeKind::Bvh => (left.1.area(), br.area()),
                    TreeKind::Fitted => {
                        let (hl, hr) = split_box(bounds, axis, plane);
                        (hl.intersection(left.1).area(), hr.intersection(br).area())
                    }
                };
                let (pl, pr) = (al / parent_area, ar / parent_area);
                // Split balls of each child, estimated as the parent's share by area.
                let nl = left.0 as f32 + split_count as f32 * pl;
                let nr = nr as f32 + split_count as f32 * pr;
                let cost = TRAVERSAL_COST + pl * self.leaf_cost_f(nl) + pr * self.leaf_cost_f(nr);
                if best.is_none_or(|b| cost < b.2) {
                    best = Some((axis, plane, cost));
                }
            }
        }
        best
    }

    fn partition(&self, owned: Vec<u32>, axis: usize, plane: f32) -> (Vec<u32>, Vec<u32>) {
        owned
            .into_iter()
            .partition(|&i| self.balls[i as usize].center[axis] < plane)
    }

    fn fork<A: Send, B: Send>(
        &self,
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

    /// Algorithm 1.
    fn build_bvh(&self, owned: Vec<u32>, split: Vec<u32>, bounds: Aabb, depth: usize) -> BuildNode {
        let n = owned.len() + split.len();
        let leaf = |owned: Vec<u32>, split: Vec<u32>| BuildNode::Leaf {
            bounds,
            owned,
            split,
        };
        if owned.len() <= 1 || depth >= MAX_DEPTH {
            return leaf(owned, split);
        }
        let Some((axis, plane, cost)) =
            self.best_split(&owned, split.len(), &bounds, f32::INFINITY)
        else {
            return leaf(owned, split);
        };
        if cost >= self.leaf_cost(n) {
            return leaf(owned, split);
        }
        // `owned` stays sorted by index through the stable partition.
        let (lo, ro) = self.partition(owned, axis, plane);
        let bbox = |set: &[u32]| {
            set.iter().fold(Aabb::EMPTY, |b, &i| {
                b.union(self.ball_box(i, f32::INFINITY))
            })
        };
        let (lb, rb) = (bbox(&lo), bbox(&ro));
        let child_split = |own: &[u32], own_box: &Aabb, other: &[u32]| -> Vec<u32> {
            split
                .iter()
                .chain(other)
                .copied()
                .filter(|&i| {
                    let b = &self.balls[i as usize];
                    own_box.overlaps_sphere(b.center, b.radius)
                        && self
                            .neighbours_of(i)
                            .iter()
                            .any(|j| own.binary_search(j).is_ok())
                })
                .collect()
        };
        let big = n > PARALLEL_BALLS;
        let (ls, rs) = self.fork(
            big,
            || child_split(&lo, &lb, &ro),
            || child_split(&ro, &rb, &lo),
        );
        let (left, right) = self.fork(
            big,
            || self.build_bvh(lo, ls, lb, depth + 1),
            || self.build_bvh(ro, rs, rb, depth + 1),
        );
        BuildNode::Interior {
            bounds,
            children: Box::new([left, right]),
        }
    }

    fn neighbours_of(&self, i: u32) -> &[u32] {
        let s = self.neighbour_start[i as usize] as usize;
        let e = self.neighbour_start[i as usize + 1] as usize;
        &self.neighbours[s..e]
    }

    /// Algorithm 2 with §5.3.
    fn build_fitted(
        &self,
        owned: Vec<u32>,
        split: Vec<u32>,
        bounds: Aabb,
        r_max: f32,
        depth: usize,
    ) -> BuildNode {
        let n = owned.len() + split.len();
        let leaf = |owned: Vec<u32>, split: Vec<u32>| BuildNode::Leaf {
            bounds,
            owned,
            split,
        };
        if owned.len() <= 1 || depth >= MAX_DEPTH || bounds.is_empty() {
            return leaf(owned, split);
        }
        let Some((axis, plane, cost)) = self.best_split(&owned, split.len(), &bounds, r_max) else {
            return leaf(owned, split);
        };
        if cost >= self.leaf_cost(n) {
            return leaf(owned, split);
        }
        let (lo, ro) = self.partition(owned, axis, plane);
        let (lh, rh) = split_box(&bounds, axis, plane);
        let big = n > PARALLEL_BALLS;
        let child = |own: &[u32], half: Aabb, other: &[u32]| -> (Vec<u32>, Aabb, f32) {
            let mut child_split: Vec<u32> = split
                .iter()
                .chain(other)
                .copied()
                .filter(|&i| {
                    let b = &self.balls[i as usize];
                    half.overlaps_sphere(b.center, b.radius)
                })
                .collect();
            let mut fitted = half;
            let r_child = self.r_max(own, &child_split);
            if self.opts.fit_boxes {
                let balls_box = own
                    .iter()
                    .chain(&child_split)
                    .fold(Aabb::EMPTY, |b, &i| b.union(self.ball_box(i, r_child)));
                fitted = half.intersection(balls_box);
            }
            if self.opts.discard_split
                && !child_split.is_empty()
                && own.len() + child_split.len() <= DISCARD_MAX_BALLS
            {
                child_split = self.discard(own, child_split, &fitted, r_child);
            }
            (child_split, fitted, r_child)
        };
        let ((ls, lb, lr), (rs, rb, rr)) =
            self.fork(big, || child(&lo, lh, &ro), || child(&ro, rh, &lo));
        let (left, right) = self.fork(
            big,
            || self.build_fitted(lo, ls, lb, lr, depth + 1),
            || self.build_fitted(ro, rs, rb, rr, depth + 1),
        );
        BuildNode::Interior {
            bounds,
            children: Box::new([left, right]),
        }
    }

    /// §5.3.2: drop positive split balls that cannot shape the surface inside `bounds`.
    fn discard(&self, owned: &[u32], split: Vec<u32>, bounds: &Aabb, r_max: f32) -> Vec<u32> {
        if !r_max.is_finite() {
            return split;
        }
        split
            .iter()
            .copied()
            .filter(|&i| {
                let b = &self.balls[i as usize];
                if b.strength <= 0.0 || bounds.overlaps_sphere(b.center, r_max) {
                    return true;
                }
                owned.iter().chain(&split).any(|&j| {
                    if j == i {
                        return false;
                    }
                    let o = &self.balls[j as usize];
                    let reach = b.radius.max(o.radius) + r_max;
                    (b.center - o.center).length_squared() < reach * reach
                })
            })
            .collect()
    }
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
fn neighbour_lists(balls: &[TreeBall]) -> (Vec<u32>, Vec<u32>) {
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
    let mut keyed: Vec<(u64, u32)> = balls
        .par_iter()
        .enumerate()
        .map(|(i, b)| (hash(key(b.center)), i as u32))
        .collect();
    keyed.par_sort_unstable();
    let lists: Vec<Vec<u32>> = balls
        .par_iter()
        .enumerate()
        .map(|(i, b)| {
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
                            if j as usize != i
                                && (b.center - o.center).length_squared() < reach * reach
                            {
                                out.push(j);
                            }
                        }
                    }
                }
            }
            out.sort_unstable();
            out
        })
        .collect();
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
        let mut rng = crate::scenes::SplitMix64(7);
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
