//! The flattened tree and its build options: what the build returns and the traversals
//! read (node 0 is the root), with its statistics and its `validate()` check.

use crate::geom::aabb::Aabb;
use glam::Vec3;

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

impl Tree {
    /// The balls of a leaf: owned first, then split.
    pub fn leaf_balls(&self, node: &Node) -> &[u32] {
        if node.count == 0 {
            return &[];
        }
        &self.balls[node.first as usize..(node.first + node.count) as usize]
    }

    /// Whether every non-empty child box lies inside its parent's (exact float comparisons;
    /// the Fitted BVH's build intersects half boxes of the parent, so it holds there). Packet
    /// traversal relies on it to give each ray the single ray's leaf ranges.
    pub fn boxes_nest(&self) -> bool {
        !self.nodes.is_empty()
            && self.nodes.iter().all(|n| {
                n.is_leaf()
                    || [n.first, n.first + 1].iter().all(|&c| {
                        let child = &self.nodes[c as usize];
                        (child.is_leaf() && child.count == 0)
                            || (child.bounds.min.cmpge(n.bounds.min).all()
                                && child.bounds.max.cmple(n.bounds.max).all())
                    })
            })
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
