//! The build: Algorithms 1 and 2 of fitted-bvh-metaballs.txt (§4, §5) with the §5.3
//! optimisations, forking on rayon at the top and sequential below; see the module doc of
//! [`crate::kinds::metaballs::tree`].

use crate::geom::aabb::Aabb;
use crate::kinds::metaballs::kernel::Kernel;
use crate::kinds::metaballs::tree::ctx::*;
use crate::kinds::metaballs::tree::flat::*;
use crate::kinds::metaballs::tree::neighbours::neighbour_lists;
use crate::kinds::metaballs::tree::sah::*;
use glam::Vec3;
use std::sync::Arc;

/// Per-thread buffers of the sequential build.
#[derive(Default)]
pub(super) struct Scratch {
    /// The split lists of the nodes on the recursion path, each on top of its parent's.
    pub(super) arena: Vec<u32>,
    /// A copy of the parent's split list while a child's is pushed.
    pub(super) parent: Vec<u32>,
    /// Sorted ids of a BVH child's own balls (membership tests).
    pub(super) sorted: Vec<u32>,
    pub(super) keep: Vec<bool>,
    pub(super) bins: Bins,
}

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

    pub(super) fn build_with(
        balls: &[TreeBall],
        kernel: Kernel,
        opts: BuildOptions,
        parallel: bool,
    ) -> Tree {
        let q_max = balls.iter().fold(0.0f32, |m, b| m.max(b.strength));
        let root_s_star = if opts.depends_on_isovalue() && opts.isovalue > 0.0 && q_max > 0.0 {
            root_s_star_table(kernel, opts.isovalue, q_max)
        } else {
            Arc::from(Vec::new())
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
    pub(super) fn emit(&mut self, built: Built, at: usize) {
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
}

impl Ctx {
    /// A ball's box with radius `min(R_i, r_max)` when tight boxes are on.
    #[inline]
    pub(super) fn ball_box(&self, center: Vec3, radius: f32, r_max: f32) -> Aabb {
        let r = if self.opts.tight_boxes && self.opts.kind == TreeKind::Fitted {
            radius.min(r_max)
        } else {
            radius
        };
        Aabb::around(center, r)
    }

    #[inline]
    pub(super) fn prim_box(&self, p: &Prim, r_max: f32) -> Aabb {
        self.ball_box(p.center, p.radius, r_max)
    }

    /// The largest box radius of any ball: `r_max` with tight boxes, unbounded otherwise.
    #[inline]
    pub(super) fn radius_cap(&self, r_max: f32) -> f32 {
        if self.opts.tight_boxes && self.opts.kind == TreeKind::Fitted {
            r_max
        } else {
            f32::INFINITY
        }
    }

    /// §5.3.1: no surface made by `positive` balls of strength at most `q_max` and radius at
    /// most `max_radius` lies farther than `r_max` from all their centres.
    pub(super) fn r_max_of(&self, positive: u32, max_radius: f32) -> f32 {
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

    pub(super) fn leaf_cost(&self, n: f32) -> f32 {
        match self.opts.leaf_cost {
            LeafCost::Squared => n * n,
            LeafCost::Linear => n,
        }
    }

    /// A leaf's split list after §5.3.2 (Fitted BVH with discarding on).
    pub(super) fn finish_leaf(
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
    pub(super) fn discard(
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
    pub(super) fn choose(
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
    pub(super) fn child(
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

    pub(super) fn neighbours_of(&self, i: u32) -> &[u32] {
        let s = self.neighbour_start[i as usize] as usize;
        let e = self.neighbour_start[i as usize + 1] as usize;
        &self.neighbours[s..e]
    }

    /// The top of the tree, forking on rayon; small subtrees are built sequentially.
    pub(super) fn build_par(&self, owned: &mut [Prim], node: NodeInput, depth: usize) -> Built {
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
    pub(super) fn build_seq(
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
pub(super) fn remap(n: &Node, base: u32, ball_base: u32) -> Node {
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
pub(super) fn leaf(balls: &mut Vec<u32>, bounds: Aabb, owned: &[Prim], split: &[u32]) -> Node {
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
