//! A four-wide view of a nested Fitted BVH for single rays: each node holds the boxes of up
//! to four descendants (a binary node's children, each inner child replaced by its own two),
//! as structure-of-arrays, so a ray tests them in one four-lane slab test and pops about half
//! as many nodes as the binary walk. Built from the binary tree after it (O(nodes)); the
//! leaves are the binary tree's, so a leaf search is unchanged.
//!
//! Why the leaf ranges are the binary walk's: [`Tree::walk`] clamps a child's range to its
//! parent's entry, and here a grandchild is clamped to its grandparent's instead. Where every
//! box lies inside its parent's ([`Tree::boxes_nest`]) a box's entry along a ray is at least
//! its parent's on every axis, so the clamp to the skipped parent changes nothing: each leaf
//! gets the same `[near, far]`, and the Fitted BVH's disjoint siblings are still visited front
//! to back. Empty leaves (no balls) are left out: their search finds nothing.

use crate::kinds::metaballs::tree::flat::{Node, Tree};
use glam::Vec3;

/// Marks a slot that names a binary leaf (the rest of the word is its node index).
const LEAF: u32 = 1 << 31;
/// An unused slot.
const EMPTY: u32 = u32::MAX;

/// Four boxes and what they hold.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(16))]
struct Node4 {
    lo: [[f32; 4]; 3],
    hi: [[f32; 4]; 3],
    /// A wide node's index, `LEAF | binary node` or [`EMPTY`].
    slot: [u32; 4],
}

/// The four-wide tree (node 0 is the root's children).
#[derive(Clone, Debug, PartialEq)]
pub struct Wide {
    nodes: Vec<Node4>,
}

impl Wide {
    /// The wide view of `tree`, or `None` where it would not give the binary walk's leaf
    /// ranges (boxes that do not nest) or there is nothing to widen (a root leaf).
    pub fn build(tree: &Tree) -> Option<Wide> {
        if !tree.boxes_nest() {
            return None;
        }
        Wide::of_nested(tree)
    }

    /// [`Wide::build`] for a caller that has already found `tree.boxes_nest()` true.
    pub fn of_nested(tree: &Tree) -> Option<Wide> {
        if tree.nodes.first().is_none_or(Node::is_leaf) {
            return None;
        }
        let mut nodes = vec![empty_node()];
        // (wide node to fill, binary inner node it stands for).
        let mut todo = vec![(0usize, 0u32)];
        while let Some((at, bin)) = todo.pop() {
            let mut filled = empty_node();
            for (k, slot) in descendants(tree, bin).enumerate() {
                let node = &tree.nodes[slot as usize];
                let (lo, hi) = (node.bounds.min.to_array(), node.bounds.max.to_array());
                for axis in 0..3 {
                    filled.lo[axis][k] = lo[axis];
                    filled.hi[axis][k] = hi[axis];
                }
                if node.is_leaf() {
                    filled.slot[k] = LEAF | slot;
                } else {
                    filled.slot[k] = nodes.len() as u32;
                    todo.push((nodes.len(), slot));
                    nodes.push(empty_node());
                }
            }
            nodes[at] = filled;
        }
        Some(Wide { nodes })
    }

    /// [`Tree::walk`] with `first_leaf` (the Fitted BVH's answer: the first leaf with a root),
    /// four boxes at a time: the same leaves with the same ranges, front to back. Each wide
    /// node and each leaf popped adds one to `node_traversals`.
    /// `ray`: the origin, the direction's reciprocal, `t_min` and `t_max`.
    #[inline]
    pub fn walk_first(
        &self,
        tree: &Tree,
        (origin, inv_dir, t_min, t_max): (Vec3, Vec3, f32, f32),
        stack: &mut Vec<(u32, f32, f32)>,
        node_traversals: &mut u64,
        mut leaf: impl FnMut(&Node, f32, f32, Option<f32>) -> Option<f32>,
    ) -> Option<f32> {
        stack.clear();
        if let Some((a, b)) = tree.nodes[0]
            .bounds
            .ray_range(origin, inv_dir, t_min, t_max)
        {
            stack.push((0, a, b));
        }
        let o = [origin.x, origin.y, origin.z];
        let inv = [inv_dir.x, inv_dir.y, inv_dir.z];
        while let Some((slot, near, far)) = stack.pop() {
            if near > t_max {
                continue;
            }
            *node_traversals += 1;
            if slot & LEAF != 0 {
                let node = &tree.nodes[(slot & !LEAF) as usize];
                if let Some(t) = leaf(node, near, far.min(t_max), None) {
                    return Some(t);
                }
                continue;
            }
            let node = &self.nodes[slot as usize];
            let (entry, exit) = slab4(node, o, inv, near.max(t_min), t_max);
            // The hit slots, nearest entry first (ties in slot order, the binary walk's).
            let mut order = [0usize; 4];
            let mut hits = 0;
            for k in 0..4 {
                if node.slot[k] != EMPTY && entry[k] <= exit[k] {
                    let mut j = hits;
                    while j > 0 && entry[order[j - 1]] > entry[k] {
                        order[j] = order[j - 1];
                        j -= 1;
                    }
                    order[j] = k;
                    hits += 1;
                }
            }
            for &k in order[..hits].iter().rev() {
                stack.push((node.slot[k], entry[k], exit[k]));
            }
        }
        None
    }
}

/// The binary nodes a wide node over inner node `bin` holds: its children, each inner child
/// replaced by its two children; empty leaves left out.
fn descendants(tree: &Tree, bin: u32) -> impl Iterator<Item = u32> + '_ {
    let c = tree.nodes[bin as usize].first;
    [c, c + 1]
        .into_iter()
        .flat_map(move |child| {
            let node = &tree.nodes[child as usize];
            if node.is_leaf() {
                [Some(child), None]
            } else {
                [Some(node.first), Some(node.first + 1)]
            }
        })
        .flatten()
        .filter(move |&n| {
            let node = &tree.nodes[n as usize];
            !(node.is_leaf() && node.count == 0)
        })
}

fn empty_node() -> Node4 {
    Node4 {
        lo: [[f32::INFINITY; 4]; 3],
        hi: [[f32::NEG_INFINITY; 4]; 3],
        slot: [EMPTY; 4],
    }
}

/// `geom::aabb::slab` on four boxes at once, operation for operation (glam's `min`, `max`,
/// `min_element` and `max_element` as selects, then `f32::max`/`f32::min` with the clamps),
/// so each lane's range is the scalar test's bit for bit. A lane whose entry exceeds its exit
/// is a miss.
#[inline(always)]
fn slab4(n: &Node4, o: [f32; 3], inv: [f32; 3], t_min: f32, t_max: f32) -> ([f32; 4], [f32; 4]) {
    let sel_min = |a: f32, b: f32| if a < b { a } else { b };
    let sel_max = |a: f32, b: f32| if a > b { a } else { b };
    let mut near_axis = [[0f32; 4]; 3];
    let mut far_axis = [[0f32; 4]; 3];
    for axis in 0..3 {
        for k in 0..4 {
            let t0 = (n.lo[axis][k] - o[axis]) * inv[axis];
            let t1 = (n.hi[axis][k] - o[axis]) * inv[axis];
            near_axis[axis][k] = sel_min(t0, t1);
            far_axis[axis][k] = sel_max(t0, t1);
        }
    }
    let mut entry = [0f32; 4];
    let mut exit = [0f32; 4];
    for k in 0..4 {
        let near = sel_max(near_axis[0][k], sel_max(near_axis[1][k], near_axis[2][k]));
        let far = sel_min(far_axis[0][k], sel_min(far_axis[1][k], far_axis[2][k]));
        entry[k] = near.max(t_min);
        exit[k] = far.min(t_max);
    }
    (entry, exit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::metaballs::kernel::Kernel;
    use crate::kinds::metaballs::tree::tests::random_balls;
    use crate::kinds::metaballs::tree::{BuildOptions, TreeBall};
    use crate::scene::PreparedGeometry;
    use crate::scenes::DemoScene;

    /// The leaves a walk hands its closure, as (binary node, near bits, far bits); the closure
    /// answers at the `stop`-th leaf.
    fn visits(
        tree: &Tree,
        wide: Option<&Wide>,
        (origin, dir): (Vec3, Vec3),
        stop: usize,
    ) -> (Vec<(usize, u32, u32)>, Option<f32>) {
        let mut seen = Vec::new();
        let leaf = |node: &Node, near: f32, far: f32, _: Option<f32>| {
            if node.count == 0 {
                return None; // the binary walk hands over empty leaves; they hold nothing
            }
            // Its index in `tree.nodes` (both walks hand out elements of it).
            let base = tree.nodes.as_ptr() as usize;
            let index = (node as *const Node as usize - base) / std::mem::size_of::<Node>();
            seen.push((index, near.to_bits(), far.to_bits()));
            (seen.len() == stop).then_some(near + 0.25 * (far - near))
        };
        let (mut stack, mut count) = (Vec::new(), 0);
        let inv = dir.recip();
        let answer = match wide {
            Some(w) => w.walk_first(tree, (origin, inv, 0.0, 1e4), &mut stack, &mut count, leaf),
            None => tree.walk(origin, inv, 0.0, 1e4, true, &mut stack, &mut count, leaf),
        };
        (seen, answer)
    }

    fn rays(tree: &Tree, n: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
        let mut rng = crate::geom::rng::SplitMix64(seed);
        let b = tree.nodes[0].bounds;
        let (lo, hi) = (b.min - (b.max - b.min) * 0.3, b.max + (b.max - b.min) * 0.3);
        (0..n)
            .map(|i| {
                let o = Vec3::new(
                    rng.range(lo.x, hi.x),
                    rng.range(lo.y, hi.y),
                    rng.range(lo.z, hi.z),
                );
                let mut d = Vec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                );
                // Every fourth ray parallel to a plane or an axis (infinite reciprocals).
                match i % 8 {
                    1 => d.x = 0.0,
                    3 => (d.y, d.z) = (0.0, 0.0),
                    _ => {}
                }
                (o, d.normalize_or(Vec3::X))
            })
            .collect()
    }

    /// Through demo and random Fitted BVHs, the wide walk hands the closure the binary walk's
    /// leaves with the same ranges bit for bit in the same order, and stops where it does.
    #[test]
    fn the_wide_walk_visits_the_binary_walks_leaves_in_order() {
        let mut trees = Vec::new();
        for demo in [DemoScene::Pool, DemoScene::Blobs, DemoScene::Molecule] {
            let prepared = std::sync::Arc::new(demo.state_at(0.5)).prepare();
            if let PreparedGeometry::Metaballs(m) = prepared.geometry() {
                trees.push(m.tree_for(demo.default_isovalue()).expect("a tree").clone());
            }
        }
        let cloud = random_balls(4000, 11, Vec3::new(6.0, 6.0, 1.0), (0.2, 0.9));
        trees.push(Tree::build(
            &cloud,
            Kernel::Wyvill,
            BuildOptions::fitted(0.5),
        ));
        assert_eq!(trees.len(), 4);
        let mut compared = 0;
        for tree in &trees {
            let wide = Wide::build(tree).expect("a nested Fitted BVH widens");
            for ray in rays(tree, 3000, 5) {
                let (all, none) = visits(tree, None, ray, usize::MAX);
                assert_eq!(
                    visits(tree, Some(&wide), ray, usize::MAX),
                    (all.clone(), none)
                );
                if all.len() >= 2 {
                    let stop = 1 + all.len() / 2;
                    let binary = visits(tree, None, ray, stop);
                    assert_eq!(visits(tree, Some(&wide), ray, stop), binary);
                    compared += all.len();
                }
            }
        }
        assert!(compared > 20_000, "only {compared} leaf visits compared");
    }

    #[test]
    fn a_tree_that_does_not_nest_or_is_one_leaf_is_not_widened() {
        let one = TreeBall {
            center: Vec3::ZERO,
            radius: 1.0,
            strength: 1.0,
        };
        let tree = Tree::build(&[one], Kernel::Wyvill, BuildOptions::fitted(0.5));
        assert!(tree.nodes[0].is_leaf());
        assert!(Wide::build(&tree).is_none());
        let cloud = random_balls(500, 3, Vec3::splat(5.0), (0.5, 0.5));
        let mut tree = Tree::build(&cloud, Kernel::Wyvill, BuildOptions::fitted(0.5));
        assert!(Wide::build(&tree).is_some());
        let child = tree.nodes[0].first as usize;
        tree.nodes[child].bounds.max.x = tree.nodes[0].bounds.max.x + 1.0;
        assert!(Wide::build(&tree).is_none());
    }
}
