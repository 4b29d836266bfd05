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

pub mod build;
pub mod ctx;
pub mod flat;
pub mod neighbours;
pub mod sah;
pub mod walk;
pub mod wide;

pub use crate::geom::aabb::Aabb;
pub use flat::{
    BuildOptions, LeafCost, Node, Tree, TreeBall, TreeError, TreeKind, TreeStats,
    DEFAULT_TRAVERSAL_COST,
};
pub use wide::Wide;

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::kinds::metaballs::kernel::Kernel;
    use glam::Vec3;

    fn cloud(n: usize) -> Vec<TreeBall> {
        random_balls(n, 7, Vec3::splat(5.0), (0.3, 0.9))
    }

    /// `n` unit-strength balls, centres uniform in `[-half, half]`, radii uniform in `radii`.
    pub(crate) fn random_balls(
        n: usize,
        seed: u64,
        half: Vec3,
        radii: (f32, f32),
    ) -> Vec<TreeBall> {
        let mut rng = crate::geom::rng::SplitMix64(seed);
        (0..n)
            .map(|_| TreeBall {
                center: Vec3::new(
                    rng.range(-half.x, half.x),
                    rng.range(-half.y, half.y),
                    rng.range(-half.z, half.z),
                ),
                radius: rng.range(radii.0, radii.1),
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

    /// The `s*` table is computed once per kernel, isovalue and strength and then shared:
    /// the same entries as computing it afresh, the same `Arc` on the second call, and a
    /// different table for another isovalue.
    #[test]
    fn the_s_star_table_is_shared_and_equals_a_fresh_one() {
        use super::ctx::{root_s_star_table, S_TABLE};
        use std::sync::Arc;
        let (kernel, iso, q) = (Kernel::Wyvill, 0.4321, 1.25);
        let first = root_s_star_table(kernel, iso, q);
        let second = root_s_star_table(kernel, iso, q);
        assert!(Arc::ptr_eq(&first, &second));
        assert_eq!(first.len(), S_TABLE);
        for (n, &got) in first.iter().enumerate() {
            let fresh = kernel.s_at_value(iso / (n.max(1) as f32 * q)).sqrt();
            assert_eq!(got.to_bits(), fresh.to_bits(), "entry {n}");
        }
        let other = root_s_star_table(kernel, 0.5, q);
        assert!(!Arc::ptr_eq(&first, &other));
        assert_ne!(first[3], other[3]);
    }
}
