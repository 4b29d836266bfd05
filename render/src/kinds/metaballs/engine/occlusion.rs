//! Occlusion queries, asked one after another by a tile's tracer: whether the isosurface
//! blocks a segment ([`PreparedMetaballs::occluded_counted`]), searching first the leaves that
//! blocked the tile's latest blocked rays.
//!
//! Neighbouring pixels' shadow rays are mostly blocked by the same few leaves, many of them
//! only at the second to fifth leaf their walk reaches (55% of Scattered-30k's single shadow
//! rays at 1920×1080 are blocked, 69% of Tornado-128k's; one of the last 8 blocking leaves
//! blocks 91% and 72% of those). The leaves of a Fitted BVH are disjoint and each holds the
//! whole field within its box, so a root that a leaf's search finds more than [`INSIDE_EPS`]
//! past the leaf's entry (at or past the segment's start) is a crossing from outside the solid
//! into it within the segment: the segment is blocked, which is what the full query
//! ([`settle`] of the any-hit root) answers, whichever root its walk meets first. Any other
//! outcome falls back to the full query, whose walk skips a hinted leaf only where it found
//! no root on the very range the walk gives it (nested boxes), so the answer never depends on
//! the hint, only its cost.

use super::{Accel, PreparedMetaballs, NO_SKIP, SCRATCH};
use crate::kinds::contract::{settle, OcclusionHint};
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::roots::FindParams;
use crate::kinds::metaballs::tree::flat::Node;
use crate::kinds::metaballs::tree::{Tree, TreeKind};
use crate::ray::{Ray, INSIDE_EPS};

/// What a hinted leaf's search found.
enum Hinted {
    /// A crossing from outside: the segment is blocked.
    Blocked,
    /// No root on the range the walk would search it on: the walk may skip the leaf.
    Empty,
    /// No overlap, or a root the full query must settle.
    Unknown,
}

/// What the searches of one query's hinted leaves share: the tree (the Fitted BVH the query
/// at its isovalue walks), the leaves' search parameters, the ray's inverse direction, and
/// whether a leaf found empty may be skipped by the walk (the main tree, with nested boxes).
struct HintedSearch<'a> {
    tree: &'a Tree,
    params: FindParams<f32>,
    inv_dir: glam::Vec3,
    may_skip: bool,
}

impl PreparedMetaballs {
    /// Whether the surface at `isovalue` blocks `[t_min, t_max]` of `ray`: the leaves `hint`
    /// names searched first, the latest first, then [`settle`] of
    /// [`PreparedMetaballs::any_hit_counted`]'s root, its walk skipping the leaves found
    /// empty. The leaf that answers "blocked" goes to the front of `hint`.
    pub fn occluded_counted(
        &self,
        ray: &Ray,
        span: (f32, f32),
        isovalue: f32,
        hint: &mut OcclusionHint,
        counters: &mut MetaballCounters,
    ) -> bool {
        let mut skip = NO_SKIP;
        let ours = hint.metaball_state == (self.id, isovalue);
        let search = if ours && hint.metaball_leaves[0].is_some() {
            self.hinted_search(ray, span, isovalue)
        } else {
            None
        };
        if let Some(search) = search {
            for (k, skip) in skip.iter_mut().enumerate() {
                let Some(node) = hint.metaball_leaves[k] else {
                    break;
                };
                match self.search_hinted_leaf(&search, ray, span, &node, counters) {
                    Hinted::Blocked => {
                        counters.rays += 1;
                        counters.hits += 1;
                        hint.metaball_leaves[..=k].rotate_right(1);
                        return true;
                    }
                    Hinted::Empty => *skip = node.first,
                    Hinted::Unknown => {}
                }
            }
        }
        let (root, leaf) = self.any_hit_leaf(ray, span, isovalue, skip, counters);
        let blocked = settle(self, ray, span, isovalue, root, counters);
        if let (true, Some(leaf)) = (blocked, leaf) {
            if !ours {
                *hint = OcclusionHint {
                    metaball_state: (self.id, isovalue),
                    ..OcclusionHint::default()
                };
            }
            hint.metaball_leaves.rotate_right(1);
            hint.metaball_leaves[0] = Some(leaf);
        }
        blocked
    }

    /// What the hinted leaves' searches share, where the query is valid and walks a tree of
    /// disjoint leaves (the Fitted BVH's), each with the whole field in its box.
    fn hinted_search(
        &self,
        ray: &Ray,
        (t_min, t_max): (f32, f32),
        isovalue: f32,
    ) -> Option<HintedSearch<'_>> {
        if !(isovalue > 0.0 && isovalue.is_finite() && t_min < t_max) {
            return None;
        }
        let Accel::Tree(tree) = self.accel_for(isovalue) else {
            return None;
        };
        if tree.kind != TreeKind::Fitted {
            return None;
        }
        let main = matches!(&self.accel, Accel::Tree(main) if std::ptr::eq(main, tree));
        Some(HintedSearch {
            tree,
            params: self.leaf_params(tree, &self.params(isovalue)),
            inv_dir: ray.dir.recip(),
            may_skip: main && self.nested,
        })
    }

    /// The search of `node`, a leaf of `search.tree`: blocked where it has a root on the
    /// segment more than [`INSIDE_EPS`] past the leaf's entry (which is at or past `t_min`);
    /// empty where it has none and `search.may_skip`, so that the walk would search it on the
    /// same range with the same balls.
    fn search_hinted_leaf(
        &self,
        search: &HintedSearch<'_>,
        ray: &Ray,
        (t_min, t_max): (f32, f32),
        node: &Node,
        counters: &mut MetaballCounters,
    ) -> Hinted {
        let Some((near, far)) = node
            .bounds
            .ray_range(ray.origin, search.inv_dir, t_min, t_max)
        else {
            return Hinted::Unknown;
        };
        let leaf = (near, far, &search.params, self.options.finder);
        let t = SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (gathered, scratch, _) = &mut *guard;
            self.search_node(search.tree, node, ray, leaf, gathered, scratch, counters)
        });
        match t {
            Some(t) if t > near + INSIDE_EPS => Hinted::Blocked,
            None if search.may_skip => Hinted::Empty,
            _ => Hinted::Unknown,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::metaballs::{Kernel, Metaball, MetaballScene, PrepareOptions};
    use glam::Vec3;

    /// A Wyvill ball of radius 2 at `T = 0.5` is the unit sphere (analytic). After a ray from
    /// outside leaves its leaf in the hint, a second ray from outside is answered by that
    /// leaf alone, while rays starting inside the solid (the leaf's root at its entry) are
    /// left to the full query: blocked only if they leave the sphere within the segment.
    #[test]
    fn the_hinted_leaf_answers_only_crossings_from_outside() {
        let scene = MetaballScene::new(
            Kernel::Wyvill,
            vec![Metaball::sphere(Vec3::ZERO, 2.0, 1.0, Vec3::ONE)],
        );
        let m = PreparedMetaballs::new(scene, PrepareOptions::fitted(0.05));
        let mut hint = OcclusionHint::default();
        let ask = |origin: Vec3, dir: Vec3, t_max: f32, hint: &mut OcclusionHint| {
            let mut c = MetaballCounters::default();
            let ray = Ray::new(origin, dir);
            let blocked = m.occluded_counted(&ray, (0.0, t_max), 0.5, hint, &mut c);
            (blocked, c.node_traversals)
        };
        let (blocked, walked) = ask(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 10.0, &mut hint);
        assert!(blocked && walked > 0, "the first ray walks the tree");
        assert!(hint.metaball_leaves[0].is_some(), "and leaves its leaf");
        assert_eq!(
            ask(Vec3::new(0.0, 5.0, 0.3), Vec3::NEG_Y, 10.0, &mut hint),
            (true, 0),
            "a crossing from outside is answered by the hinted leaf"
        );
        assert!(
            !ask(Vec3::new(0.0, 5.0, 0.3), Vec3::NEG_Y, 3.0, &mut hint).0,
            "the segment ends before the sphere"
        );
        let (blocked, walked) = ask(Vec3::new(0.2, 0.1, 0.0), Vec3::X, 0.5, &mut hint);
        assert!(
            !blocked,
            "starting inside, the segment never leaves the sphere"
        );
        assert!(
            walked > 0,
            "a root at the leaf's entry is the full query's to settle"
        );
        let (blocked, walked) = ask(Vec3::new(0.2, 0.1, 0.0), Vec3::X, 5.0, &mut hint);
        assert!(
            blocked && walked > 0,
            "starting inside, the ray leaves the sphere at 0.79"
        );
    }
}
