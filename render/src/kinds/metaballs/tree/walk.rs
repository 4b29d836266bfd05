//! The one traversal loop of the tree: front to back, the nearer child first, each leaf
//! handed to a closure that searches it (fitted-bvh-metaballs.txt §4 and §5: the BVH's
//! overlapping leaves are all visited and the nearest root kept; the Fitted BVH's disjoint
//! leaves stop at the first leaf with a root).

use crate::kinds::metaballs::tree::flat::{Node, Tree};
use glam::Vec3;

impl Tree {
    /// Visits the leaves whose boxes the ray `origin + t·dir` (given `inv_dir = 1/dir`)
    /// crosses within `[t_min, t_max]`, nearest first, skipping those beyond the best root so
    /// far. `leaf(node, near, far, best)` searches one leaf on `[near, far]` (`far` already
    /// clamped to the best root) and returns a root only if it beats `best`. With
    /// `first_leaf` the first root answers; otherwise the nearest over every leaf. Each node
    /// popped adds one to `node_traversals`.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn walk(
        &self,
        origin: Vec3,
        inv_dir: Vec3,
        t_min: f32,
        t_max: f32,
        first_leaf: bool,
        stack: &mut Vec<(u32, f32, f32)>,
        node_traversals: &mut u64,
        mut leaf: impl FnMut(&Node, f32, f32, Option<f32>) -> Option<f32>,
    ) -> Option<f32> {
        let mut best: Option<f32> = None;
        stack.clear();
        if let Some((a, b)) = self.nodes[0]
            .bounds
            .ray_range(origin, inv_dir, t_min, t_max)
        {
            stack.push((0, a, b));
        }
        while let Some((i, near, far)) = stack.pop() {
            let limit = best.unwrap_or(t_max);
            if near > limit {
                continue;
            }
            *node_traversals += 1;
            let node = &self.nodes[i as usize];
            if node.is_leaf() {
                if let Some(t) = leaf(node, near, far.min(limit), best) {
                    if first_leaf {
                        return Some(t);
                    }
                    best = Some(t);
                }
                continue;
            }
            let c = node.first;
            let lo = near.max(t_min);
            let l = self.nodes[c as usize]
                .bounds
                .ray_range(origin, inv_dir, lo, limit);
            let r = self.nodes[c as usize + 1]
                .bounds
                .ray_range(origin, inv_dir, lo, limit);
            // Push the farther child first so the nearer one is popped first.
            match (l, r) {
                (Some(l), Some(r)) => {
                    let (first, second) = if l.0 <= r.0 {
                        ((c, l), (c + 1, r))
                    } else {
                        ((c + 1, r), (c, l))
                    };
                    stack.push((second.0, second.1 .0, second.1 .1));
                    stack.push((first.0, first.1 .0, first.1 .1));
                }
                (Some(l), None) => stack.push((c, l.0, l.1)),
                (None, Some(r)) => stack.push((c + 1, r.0, r.1)),
                (None, None) => {}
            }
        }
        best
    }
}
