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
//!
//! Cheaper still, before any leaf: witnesses. Where no term of the field is negative, the
//! field is at least any one ball's term, so a point where one ball's term alone exceeds the
//! isovalue (its core, shrunk by [`WITNESS_MARGIN`]) lies inside the solid. A segment that
//! passes through a core and ends outside the tree's box (outside every leaf, where the field
//! is 0) has the surface between the two, which is what the full query answers "blocked" for,
//! whether it starts inside the solid or not. The hint keeps the balls whose cores the latest
//! blocked rays crossed; testing one is a ray–sphere test, where a leaf's search gathers all
//! its balls and finds a root.

use super::{Accel, PreparedMetaballs, NO_SKIP, SCRATCH};
use crate::kinds::contract::{settle, OcclusionHint};
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::one_ball;
use crate::kinds::metaballs::roots::{FindParams, KernelPoly, RayBall};
use crate::kinds::metaballs::tree::flat::Node;
use crate::kinds::metaballs::tree::{Tree, TreeKind};
use crate::ray::{Ray, INSIDE_EPS};

/// How far inside a ball's isosurface its core ends: where its term alone is
/// `(1 + WITNESS_MARGIN)·T`, so that the field the root finder sums there in `f32` (every
/// other term `≥ 0`) stands clear of `T` by far more than its rounding.
const WITNESS_MARGIN: f64 = 1e-2;

/// What a hinted leaf's search found.
enum Hinted {
    /// A crossing from outside: the segment is blocked; the ball whose core it crosses, if
    /// any, as a witness for the next rays.
    Blocked(Option<(u32, f32)>),
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
    /// Whether witnesses may answer: no negative term, and the segment ends outside the tree's
    /// box.
    witnesses: bool,
}

impl PreparedMetaballs {
    /// Whether the surface at `isovalue` blocks `[t_min, t_max]` of `ray`: the witnesses
    /// `hint` names tried first, then its leaves searched, the latest first, then [`settle`]
    /// of [`PreparedMetaballs::any_hit_counted`]'s root, its walk skipping the leaves found
    /// empty. The witness or leaf that answers "blocked" goes to the front of `hint`, and a
    /// blocked ray's search leaves a witness where it crossed a core.
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
        let hinted = hint.metaball_leaves[0].is_some() || hint.metaball_witnesses[0].is_some();
        let search = if ours && hinted {
            self.hinted_search(ray, span, isovalue)
        } else {
            None
        };
        if let Some(search) = &search {
            if search.witnesses && self.first_witness(ray, span, hint).is_some() {
                counters.rays += 1;
                counters.hits += 1;
                return true;
            }
            for (k, skip) in skip.iter_mut().enumerate() {
                let Some(node) = hint.metaball_leaves[k] else {
                    break;
                };
                match self.search_hinted_leaf(search, ray, span, &node, hint, counters) {
                    Hinted::Blocked(witness) => {
                        counters.rays += 1;
                        counters.hits += 1;
                        hint.metaball_leaves[..=k].rotate_right(1);
                        remember(hint, witness);
                        return true;
                    }
                    Hinted::Empty => *skip = node.first,
                    Hinted::Unknown => {}
                }
            }
        }
        let (root, leaf) = self.any_hit_leaf(ray, span, isovalue, skip, counters);
        // The walk left the answering leaf's balls in the scratch; settling a root at the
        // start may search again.
        let witness = match (ours, root, &search) {
            (true, Some(t), Some(search)) if search.witnesses && t > span.0 + INSIDE_EPS => SCRATCH
                .with(|cell| {
                    let gathered = &cell.borrow().0;
                    self.witness_in(gathered, span, isovalue, hint)
                }),
            _ => None,
        };
        let blocked = settle(self, ray, span, isovalue, root, counters);
        if let (true, Some(leaf)) = (blocked, leaf) {
            self.own_hint(hint, isovalue);
            hint.metaball_leaves.rotate_right(1);
            hint.metaball_leaves[0] = Some(leaf);
            remember(hint, witness);
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
            witnesses: self.terms_positive && ends_outside(tree, ray, t_max),
        })
    }

    /// The ball of `gathered` (a blocking leaf's balls along `ray`) whose core the segment
    /// passes deepest into, with the largest `s` inside that core; `None` where it crosses
    /// none. `hint` keeps the last strength's core.
    fn witness_in(
        &self,
        gathered: &[RayBall<f32>],
        (t_min, t_max): (f32, f32),
        isovalue: f32,
        hint: &mut OcclusionHint,
    ) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32, f32)> = None;
        for b in gathered {
            let s_limit = match hint.metaball_core {
                Some((q, s_limit)) if q == b.q => s_limit,
                _ => {
                    let s_limit = core_limit(&KernelPoly::new(self.scene.kernel), isovalue, b.q);
                    hint.metaball_core = Some((b.q, s_limit));
                    s_limit
                }
            };
            let Some(s_limit) = s_limit else {
                continue;
            };
            let depth = s_limit - b.s_min;
            if best.is_some_and(|(_, _, d)| d >= depth) {
                continue;
            }
            if core_point((b.a, b.tc, b.s_min), s_limit, (t_min, t_max)).is_some() {
                best = Some((b.ball, s_limit, depth));
            }
        }
        best.map(|(ball, s_limit, _)| (ball, s_limit))
    }

    /// Makes `hint` this state's at `isovalue`, emptied if it was another's.
    pub(super) fn own_hint(&self, hint: &mut OcclusionHint, isovalue: f32) {
        if hint.metaball_state != (self.id, isovalue) {
            *hint = OcclusionHint {
                metaball_state: (self.id, isovalue),
                ..OcclusionHint::default()
            };
        }
    }

    /// A point of `[t_min, t_max]` of `ray` inside the solid, from one of `hint`'s witnesses
    /// (this state's, at the isovalue `tree` was built for), where the segment ends outside
    /// `tree`'s box and no term is negative: the segment is then blocked. The witness goes to
    /// the front.
    pub(super) fn witness_point(
        &self,
        tree: &Tree,
        ray: &Ray,
        span: (f32, f32),
        hint: &mut OcclusionHint,
    ) -> Option<f32> {
        if !(self.terms_positive && ends_outside(tree, ray, span.1)) {
            return None;
        }
        self.first_witness(ray, span, hint)
    }

    /// [`PreparedMetaballs::witness_point`] where the caller has checked that witnesses may
    /// answer.
    fn first_witness(&self, ray: &Ray, span: (f32, f32), hint: &mut OcclusionHint) -> Option<f32> {
        for k in 0..hint.metaball_witnesses.len() {
            let (ball, s_limit) = hint.metaball_witnesses[k]?;
            let Some((_, _, a, tc, s_min)) = self.along(ray, ball) else {
                continue; // the ray misses this ball's support
            };
            if let Some(t) = core_point((a, tc, s_min), s_limit, span) {
                hint.metaball_witnesses[..=k].rotate_right(1);
                return Some(t);
            }
        }
        None
    }

    /// Leaves in `hint` a witness for a ray that found a root among `gathered` (its balls in
    /// a leaf of `tree`), where witnesses can answer such a ray.
    pub(super) fn learn_witness(
        &self,
        tree: &Tree,
        ray: &Ray,
        span: (f32, f32),
        gathered: &[RayBall<f32>],
        isovalue: f32,
        hint: &mut OcclusionHint,
    ) {
        if self.terms_positive && ends_outside(tree, ray, span.1) {
            let witness = self.witness_in(gathered, span, isovalue, hint);
            remember(hint, witness);
        }
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
        hint: &mut OcclusionHint,
        counters: &mut MetaballCounters,
    ) -> Hinted {
        let Some((near, far)) = node
            .bounds
            .ray_range(ray.origin, search.inv_dir, t_min, t_max)
        else {
            return Hinted::Unknown;
        };
        let leaf = (near, far, &search.params, self.options.finder);
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (gathered, scratch, _) = &mut *guard;
            let t = self.search_node(search.tree, node, ray, leaf, gathered, scratch, counters);
            match t {
                Some(t) if t > near + INSIDE_EPS => Hinted::Blocked(if search.witnesses {
                    self.witness_in(gathered, (t_min, t_max), search.params.isovalue, hint)
                } else {
                    None
                }),
                None if search.may_skip => Hinted::Empty,
                _ => Hinted::Unknown,
            }
        })
    }
}

/// A point of `[t_min, t_max]` where a ball seen along the ray as `(a, tc, s_min)` (a
/// [`RayBall`]'s) has `s` at most `s_limit`, the nearest to its centre, if the segment passes
/// there.
fn core_point(
    (a, tc, s_min): (f32, f32, f32),
    s_limit: f32,
    (t_min, t_max): (f32, f32),
) -> Option<f32> {
    let depth = s_limit - s_min;
    if !(depth >= 0.0) {
        return None;
    }
    let half = (depth / a).sqrt();
    let (lo, hi) = ((tc - half).max(t_min), (tc + half).min(t_max));
    (lo <= hi).then(|| tc.clamp(lo, hi))
}

/// Whether `ray` at `t_max` lies outside `tree`'s box, where no leaf holds a term.
fn ends_outside(tree: &Tree, ray: &Ray, t_max: f32) -> bool {
    let (end, root) = (ray.at(t_max), &tree.nodes[0].bounds);
    end.cmplt(root.min).any() || end.cmpgt(root.max).any()
}

/// Puts `witness` at the front of `hint`'s witnesses (if it is not there already).
fn remember(hint: &mut OcclusionHint, witness: Option<(u32, f32)>) {
    let Some(witness) = witness else {
        return;
    };
    let list = &mut hint.metaball_witnesses;
    let k = list
        .iter()
        .position(|w| w.is_none_or(|(ball, _)| ball == witness.0))
        .unwrap_or(list.len() - 1);
    list[..=k].rotate_right(1);
    list[0] = Some(witness);
}

/// The largest `s` where a ball of strength `q` alone reaches `(1 + WITNESS_MARGIN)·T` under
/// `kernel`, rounded down into `f32`; `None` where even its centre does not.
fn core_limit(kernel: &KernelPoly<f64>, isovalue: f32, q: f32) -> Option<f32> {
    let mut iters = 0;
    let level = isovalue as f64 * (1.0 + WITNESS_MARGIN);
    let w = one_ball::level(kernel, level, q as f64, &mut iters).ok()??;
    // Newton's iterates come down onto the root from above; a millionth keeps the `f32`
    // rounding on the inner side too.
    Some(((1.0 - w) * (1.0 - 1e-6)) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::metaballs::{Kernel, Metaball, MetaballScene, PrepareOptions};
    use glam::Vec3;

    /// A Wyvill ball of radius 2 at `T = 0.5`: the unit sphere (analytic).
    fn unit_sphere() -> PreparedMetaballs {
        let scene = MetaballScene::new(
            Kernel::Wyvill,
            vec![Metaball::sphere(Vec3::ZERO, 2.0, 1.0, Vec3::ONE)],
        );
        PreparedMetaballs::new(scene, PrepareOptions::fitted(0.05))
    }

    /// Whether `m`'s surface at `T = 0.5` blocks `[0, t_max]` of the ray, asked with `hint`,
    /// and the query's counters; the answer checked against the full query's.
    fn ask(
        m: &PreparedMetaballs,
        (origin, dir, t_max): (Vec3, Vec3, f32),
        hint: &mut OcclusionHint,
    ) -> (bool, MetaballCounters) {
        let mut c = MetaballCounters::default();
        let ray = Ray::new(origin, dir);
        let blocked = m.occluded_counted(&ray, (0.0, t_max), 0.5, hint, &mut c);
        let mut full = MetaballCounters::default();
        let root = m.any_hit_counted(&ray, 0.0, t_max, 0.5, &mut full);
        assert_eq!(blocked, settle(m, &ray, (0.0, t_max), 0.5, root, &mut full));
        (blocked, c)
    }

    /// The unit sphere. After a ray from outside leaves its leaf in the hint, a second ray
    /// from outside is answered by that leaf alone, while rays starting inside the solid (the
    /// leaf's root at its entry) are left to the full query: blocked only if they leave the
    /// sphere within the segment.
    #[test]
    fn the_hinted_leaf_answers_only_crossings_from_outside() {
        let m = unit_sphere();
        let mut hint = OcclusionHint::default();
        let mut ask = |ray: (Vec3, Vec3, f32)| {
            let (blocked, c) = ask(&m, ray, &mut hint);
            (blocked, c.node_traversals)
        };
        let (blocked, walked) = ask((Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 10.0));
        assert!(blocked && walked > 0, "the first ray walks the tree");
        assert_eq!(
            ask((Vec3::new(0.0, 5.0, 0.3), Vec3::NEG_Y, 10.0)),
            (true, 0),
            "a crossing from outside is answered by the hinted leaf"
        );
        assert!(
            !ask((Vec3::new(0.0, 5.0, 0.3), Vec3::NEG_Y, 3.0)).0,
            "the segment ends before the sphere"
        );
        let (blocked, walked) = ask((Vec3::new(0.2, 0.1, 0.0), Vec3::X, 0.5));
        assert!(
            !blocked,
            "starting inside, the segment never leaves the sphere"
        );
        assert!(
            walked > 0,
            "a root at the leaf's entry is the full query's to settle"
        );
        // The hinted leaf's answer above left the ball as a witness: this segment passes
        // through its core and ends outside the tree's box.
        let (blocked, walked) = ask((Vec3::new(0.2, 0.1, 0.0), Vec3::X, 5.0));
        assert!(
            blocked && walked == 0,
            "starting inside, the ray leaves the sphere at 0.79"
        );
    }

    /// The unit sphere. Once a blocked ray has left the ball as a witness, a segment through
    /// its core that ends outside the tree's box is answered without a leaf search; one that
    /// ends inside the box (here inside the solid, which the full query does not call
    /// blocked), one that passes beside the core and one whose line crosses the core only
    /// behind its start are not.
    #[test]
    fn a_witness_answers_only_segments_through_a_core_that_end_outside_the_tree() {
        let m = unit_sphere();
        let mut hint = OcclusionHint::default();
        let mut ask = |ray: (Vec3, Vec3, f32)| {
            let (blocked, c) = ask(&m, ray, &mut hint);
            (blocked, c.leaf_tests + c.node_traversals)
        };
        assert!(ask((Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 10.0)).0);
        assert!(ask((Vec3::new(0.0, 5.0, 0.3), Vec3::NEG_Y, 10.0)).0);
        assert_eq!(
            ask((Vec3::new(5.0, 0.2, 0.0), Vec3::NEG_X, 10.0)),
            (true, 0),
            "through the core, ending outside the box"
        );
        let (blocked, searched) = ask((Vec3::new(-0.5, 0.0, 0.0), Vec3::X, 1.0));
        assert!(!blocked && searched > 0, "inside the solid all along");
        let (blocked, searched) = ask((Vec3::new(5.0, 0.9, 0.9), Vec3::NEG_X, 10.0));
        assert!(!blocked && searched > 0, "beside the core");
        let (blocked, _) = ask((Vec3::new(0.0, 1.5, 0.0), Vec3::Y, 10.0));
        assert!(!blocked, "leaving the ball behind");
    }

    /// Random blobs (spheres and ellipsoids, positive strengths, Wyvill's and the quartic
    /// kernel), shadow rays in groups from nearby points asked in sequence with one hint,
    /// towards a light outside the scene (witnesses may answer) and one inside it (they may
    /// not): every answer is the full query's, and witnesses answered some.
    #[test]
    fn witnesses_answer_as_the_full_query_on_random_blobs() {
        use crate::geom::rng::SplitMix64;
        use crate::kinds::metaballs::scene::Shape;
        let mut witnessed = 0;
        for seed in 0..16u64 {
            let mut rng = SplitMix64(seed);
            let kernel = if seed % 2 == 0 {
                Kernel::Wyvill
            } else {
                Kernel::Quartic
            };
            let balls = (0..40)
                .map(|i| {
                    let centre = Vec3::new(
                        rng.range(-3.0, 3.0),
                        rng.range(-3.0, 3.0),
                        rng.range(-3.0, 3.0),
                    );
                    let mut ball = Metaball::sphere(
                        centre,
                        rng.range(0.8, 1.6),
                        rng.range(0.6, 1.5),
                        Vec3::ONE,
                    );
                    if i % 3 == 0 {
                        let axes = Vec3::new(1.0, rng.range(0.5, 1.0), rng.range(0.5, 1.0));
                        let rotation = glam::Quat::from_axis_angle(
                            (rng.in_unit_ball() + Vec3::X * 0.1).normalize(),
                            rng.range(0.0, 3.0),
                        );
                        ball.shape = Shape::Ellipsoid { axes, rotation };
                    }
                    ball
                })
                .collect();
            let m = PreparedMetaballs::new(
                MetaballScene::new(kernel, balls),
                PrepareOptions::fitted(0.05),
            );
            for light in [Vec3::new(20.0, 30.0, 10.0), Vec3::new(0.3, 0.2, 0.1)] {
                let mut hint = OcclusionHint::default();
                for _ in 0..24 {
                    let base = Vec3::new(
                        rng.range(-4.0, 4.0),
                        rng.range(-4.0, 4.0),
                        rng.range(-4.0, 4.0),
                    );
                    for _ in 0..8 {
                        let origin = base + rng.in_unit_ball() * 0.2;
                        let to = light - origin;
                        let ray = Ray::new(origin, to);
                        let span = (0.0, to.length());
                        let mut c = MetaballCounters::default();
                        let got = m.occluded_counted(&ray, span, 0.5, &mut hint, &mut c);
                        let mut full = MetaballCounters::default();
                        let root = m.any_hit_counted(&ray, span.0, span.1, 0.5, &mut full);
                        let want = settle(&m, &ray, span, 0.5, root, &mut full);
                        assert_eq!(got, want, "seed {seed}, light {light}, ray {ray:?}");
                        witnessed += (got && c.leaf_tests + c.node_traversals == 0) as usize;
                    }
                }
            }
        }
        assert!(witnessed > 0, "no ray was answered by a witness");
    }

    /// Where a term can be negative the field may stay below one ball's term, so a witness is
    /// not used: a positive ball cancelled by a negative one of the same support (no surface
    /// anywhere), with the positive ball put in the hint as a witness by hand.
    #[test]
    fn no_witness_where_a_term_can_be_negative() {
        let scene = MetaballScene::new(
            Kernel::Wyvill,
            vec![
                Metaball::sphere(Vec3::ZERO, 2.0, 1.0, Vec3::ONE),
                Metaball::sphere(Vec3::ZERO, 2.0, -0.9, Vec3::ONE),
            ],
        );
        let m = PreparedMetaballs::new(scene, PrepareOptions::fitted(0.05));
        let Accel::Tree(tree) = &m.accel else {
            unreachable!("the Fitted BVH")
        };
        let kernel = KernelPoly::new(Kernel::Wyvill);
        let mut hint = OcclusionHint {
            metaball_state: (m.id, 0.5),
            ..OcclusionHint::default()
        };
        hint.metaball_leaves[0] = tree.nodes.iter().find(|n| n.is_leaf()).copied();
        hint.metaball_witnesses[0] = Some((0, core_limit(&kernel, 0.5, 1.0).expect("a core")));
        let ray = Ray::new(Vec3::new(5.0, 0.0, 0.0), Vec3::NEG_X);
        let mut c = MetaballCounters::default();
        assert!(!m.occluded_counted(&ray, (0.0, 10.0), 0.5, &mut hint, &mut c));
    }

    /// A core's limit against `f64` bisection on the kernel's own value (Wyvill and the
    /// quartic kernel, several strengths): the ball's term there is `(1 + WITNESS_MARGIN)·T`
    /// within a part in 10⁵, never less; `None` where the centre stays below.
    #[test]
    fn the_core_limit_is_where_one_term_clears_the_isovalue() {
        for kernel in [Kernel::Wyvill, Kernel::Quartic] {
            let poly = KernelPoly::new(kernel);
            for (q, isovalue) in [(1.0f32, 0.5f32), (2.5, 0.5), (0.7, 0.3), (1.0, 0.05)] {
                let want = isovalue as f64 * (1.0 + WITNESS_MARGIN);
                let term = |s: f64| q as f64 * kernel.value_f64(s);
                let (mut lo, mut hi) = (0.0f64, 1.0f64);
                for _ in 0..100 {
                    let mid = 0.5 * (lo + hi);
                    if term(mid) >= want {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                let s = core_limit(&poly, isovalue, q).expect("the centre clears T") as f64;
                assert!(
                    term(s) >= want,
                    "{kernel:?} q {q} T {isovalue}: {s} against {lo}"
                );
                assert!(
                    (s - lo).abs() < 1e-5 * lo.max(1e-3),
                    "{kernel:?} q {q}: {s} against {lo}"
                );
            }
            assert_eq!(
                core_limit(&poly, 0.5, 0.4),
                None,
                "{kernel:?}: a weak ball has no core"
            );
        }
    }
}
