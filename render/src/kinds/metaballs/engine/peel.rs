//! Depth peeling in one traversal: the successive crossings of the isosurface along a ray
//! (transparency's layers, shadow rays through transparent blobs) found by one front-to-back
//! walk of the Fitted BVH, each leaf's balls gathered once and searched again from each
//! crossing, instead of one query from the root per crossing.
//!
//! The answer is the one-query-per-crossing answer
//! ([`crossings_one_by_one`]): the Fitted BVH's leaves are disjoint and visited in ray order,
//! a fresh query from `t` would reach the same leaf with the same stretch `[max(near, t),
//! far]`, and the balls searched from `t` are the leaf's gathered balls whose support reaches
//! past `t`, in the leaf's order, exactly the list a fresh gather over that stretch makes. So
//! the two give the same crossings bit for bit (checked by
//! `peeling_in_one_walk_finds_the_crossings_of_one_query_each`).

use super::{Accel, PreparedMetaballs};
use crate::kinds::contract::crossings_one_by_one;
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::roots::{self, RayBall, RootFinder, Scratch};
use crate::kinds::metaballs::tree::{Node, TreeKind};
use crate::ray::{surface_offset, Hit, Ray, INSIDE_EPS};
use std::cell::RefCell;

/// Per-thread buffers of one peel: a leaf's balls over its whole stretch, the balls of one
/// search, the finder's scratch and the walk's stack.
type PeelScratch = (
    Vec<RayBall<f32>>,
    Vec<RayBall<f32>>,
    Scratch<f32>,
    Vec<(u32, f32, f32)>,
);

thread_local! {
    static PEEL: RefCell<PeelScratch> = RefCell::new(Default::default());
}

impl PreparedMetaballs {
    /// [`PreparedKind::crossings`](crate::kinds::contract::PreparedKind::crossings) in one
    /// walk of the Fitted BVH; other structures (and hits refined in `f64`) ask one query per
    /// crossing.
    #[allow(clippy::too_many_arguments)]
    pub fn crossings_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        out: &mut Vec<Hit>,
        counters: &mut MetaballCounters,
    ) {
        let span = (t_min, t_max, isovalue, inside, max);
        self.peel(ray, span, Crossings::Hits(out), counters);
    }

    /// [`PreparedKind::crossing_count`](crate::kinds::contract::PreparedKind::crossing_count):
    /// the peel of [`PreparedMetaballs::crossings_counted`] without the hits. A crossing whose
    /// search ends on an isolated piece (one sign change of the Bernstein coefficients: one
    /// root) is counted without solving it, and the walk goes on from the piece's end, past
    /// which the field stays on the crossing's far side; the search's direction (in or out)
    /// says which side that is. So the count is the crossings' but for roots closer together
    /// than [`surface_offset`], which the walk with hits steps over.
    #[allow(clippy::too_many_arguments)]
    pub fn crossing_count_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        counters: &mut MetaballCounters,
    ) -> usize {
        let span = (t_min, t_max, isovalue, inside, max);
        let mut count = 0;
        self.peel(ray, span, Crossings::Count(&mut count), counters);
        count
    }

    /// The walk of both: the crossings as hits or only their number.
    fn peel(
        &self,
        ray: &Ray,
        (t_min, t_max, isovalue, inside, max): (f32, f32, f32, bool, usize),
        mut out: Crossings,
        counters: &mut MetaballCounters,
    ) {
        let tree = match self.accel_for(isovalue) {
            Accel::Tree(tree) if tree.kind == TreeKind::Fitted && !self.options.refine_f64 => {
                Some(tree)
            }
            Accel::Tree(_) | Accel::BruteForce | Accel::ActiveList => None,
        };
        let Some(tree) = tree else {
            let span = (ray, t_min, t_max, isovalue, inside, max);
            return out.one_by_one(self, span, counters);
        };
        counters.rays += 1;
        if max == 0 || !(isovalue > 0.0) || !isovalue.is_finite() || !(t_min < t_max) {
            return;
        }
        let (entry, exit) = (self.params(isovalue), self.exit_params(isovalue));
        let finder = self.options.finder;
        let enough = out.len() + max;
        let mut state = Peel { t: t_min, inside };
        let spheres = self.spheres_of(tree);
        PEEL.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (leaf_balls, gathered, scratch, stack) = &mut *guard;
            let mut node_traversals = counters.node_traversals;
            let leaf = |node: &Node, near: f32, far: f32, _: Option<f32>| {
                if state.t >= far {
                    return None;
                }
                leaf_balls.clear();
                let leaf = tree.leaf_balls(node);
                let range = (near.max(state.t), far);
                match spheres {
                    Some(soa) => {
                        let (first, all) = (node.first as usize, (leaf.len(), false));
                        // Inside the solid most of a leaf's balls cover the ray.
                        let at = (range, state.inside);
                        soa.gather(&self.balls, leaf, first, all, ray, at, leaf_balls);
                    }
                    None => {
                        for &b in leaf {
                            self.gather(ray, b, true, range.0, range.1, leaf_balls);
                        }
                    }
                }
                while out.len() < enough {
                    let lo = near.max(state.t);
                    if !(lo < far) {
                        break;
                    }
                    // The balls a fresh query from `lo` would gather, in the same order: the
                    // leaf's own while `lo` is where they were gathered from.
                    let gathered: &[RayBall<f32>] = if lo == range.0 {
                        leaf_balls
                    } else {
                        gathered.clear();
                        gathered.extend(leaf_balls.iter().filter(|b| !(b.t1 < lo)));
                        gathered
                    };
                    if gathered.is_empty() {
                        break;
                    }
                    let (params, leaf_finder) = if state.inside {
                        (&exit, RootFinder::BezierClipping)
                    } else {
                        (&entry, finder)
                    };
                    let (found, piece) = if out.counting()
                        && leaf_finder == RootFinder::BezierClipping
                    {
                        roots::find_first_deferring(leaf_finder, params, gathered, lo, far, scratch)
                    } else {
                        (
                            roots::find_first(leaf_finder, params, gathered, lo, far, scratch),
                            None,
                        )
                    };
                    let Some(mut t) = found.counted(counters, gathered.len()) else {
                        break;
                    };
                    if let Some(piece) = piece {
                        let end = piece.a + piece.h * piece.hi;
                        let clear =
                            state.inside || piece.a + piece.h * piece.lo > state.t + INSIDE_EPS;
                        if clear && end > lo {
                            // One root inside the piece, none between it and the piece's end.
                            counters.hits += 1;
                            out.count_one();
                            state.inside = !state.inside;
                            state.t = end;
                            continue;
                        }
                        // The root may be the start itself: solved, as the walk with hits does.
                        let (root, iterations) = piece.solve_one();
                        counters.iterations += u64::from(iterations.saturating_sub(piece.iters));
                        let Some(root) = root else {
                            break;
                        };
                        t = root;
                    }
                    if !state.inside && !(t > state.t + INSIDE_EPS) {
                        // The stretch started inside: its way out is the next crossing.
                        state.inside = true;
                        continue;
                    }
                    counters.hits += 1;
                    let position = match &mut out {
                        Crossings::Hits(hits) => {
                            let hit = self.hit_at(ray, t, gathered);
                            state.inside = hit.normal.dot(ray.dir) < 0.0;
                            hits.push(hit);
                            hit.position
                        }
                        Crossings::Count(n) => {
                            **n += 1;
                            state.inside = !state.inside;
                            ray.at(t)
                        }
                    };
                    state.t = t + surface_offset(position);
                }
                // Stop the walk once enough crossings are found.
                (out.len() >= enough).then_some(state.t)
            };
            let walk = (ray.origin, ray.dir.recip(), t_min, t_max);
            self.walk_tree(tree, walk, true, stack, &mut node_traversals, leaf);
            counters.node_traversals = node_traversals;
        });
    }
}

/// What a peel gives back: the crossings as hits, or their number.
enum Crossings<'a> {
    Hits(&'a mut Vec<Hit>),
    Count(&'a mut usize),
}

impl Crossings<'_> {
    /// Crossings so far (hits already in the list included).
    fn len(&self) -> usize {
        match self {
            Crossings::Hits(hits) => hits.len(),
            Crossings::Count(n) => **n,
        }
    }

    fn counting(&self) -> bool {
        matches!(self, Crossings::Count(_))
    }

    fn count_one(&mut self) {
        if let Crossings::Count(n) = self {
            **n += 1;
        }
    }

    /// The peel with one query per crossing (structures other than the Fitted BVH).
    fn one_by_one(
        self,
        k: &PreparedMetaballs,
        (ray, t_min, t_max, isovalue, inside, max): (&Ray, f32, f32, f32, bool, usize),
        counters: &mut MetaballCounters,
    ) {
        match self {
            Crossings::Hits(out) => {
                crossings_one_by_one(k, ray, t_min, t_max, isovalue, inside, max, out, counters)
            }
            Crossings::Count(n) => {
                let mut hits = Vec::new();
                let c = counters;
                crossings_one_by_one(k, ray, t_min, t_max, isovalue, inside, max, &mut hits, c);
                *n += hits.len();
            }
        }
    }
}

/// Where a peel stands: the stretch's start, and whether it starts inside the solid.
struct Peel {
    t: f32,
    inside: bool,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::rng::SplitMix64;
    use crate::kinds::metaballs::{MetaballScene, PrepareOptions};
    use crate::scene::Geometry;
    use crate::scenes::DemoScene;

    fn metaballs(demo: DemoScene) -> MetaballScene {
        match demo.state_at(1.0).geometry {
            Geometry::Metaballs(m) => m,
            Geometry::Tets(_) | Geometry::Surfels(_) => panic!("{demo:?} is a metaball scene"),
        }
    }

    #[test]
    fn peeling_in_one_walk_finds_the_crossings_of_one_query_each() {
        let mut deep = 0;
        for demo in [DemoScene::Molecule, DemoScene::Blobs, DemoScene::Tornado4k] {
            let scene = metaballs(demo);
            let iso = demo.default_isovalue();
            let p =
                PreparedMetaballs::new(scene.clone(), PrepareOptions::fitted(scene.min_isovalue));
            let eye = demo.default_camera().eye;
            let mut rng = SplitMix64(7);
            let all: Vec<u32> = (0..scene.balls.len() as u32).collect();
            let (mut peeled, mut one) = (Vec::new(), Vec::new());
            for i in 0..400 {
                let ball = &scene.balls[(rng.next_u64() % scene.balls.len() as u64) as usize];
                let aim = ball.center + rng.in_unit_ball() * ball.radius;
                // Camera rays from outside, and rays from a ball's centre that start inside.
                let (ray, inside) = if i % 4 == 3 {
                    (
                        Ray::new(ball.center, rng.in_unit_ball().normalize_or(glam::Vec3::X)),
                        true,
                    )
                } else {
                    (Ray::new(eye, aim - eye), false)
                };
                if inside && !(scene.field_at(&all, ball.center) > iso) {
                    continue;
                }
                for max in [1, 3, 9] {
                    peeled.clear();
                    one.clear();
                    let mut c = MetaballCounters::default();
                    p.crossings_counted(&ray, 0.0, 1e4, iso, inside, max, &mut peeled, &mut c);
                    crossings_one_by_one(&p, &ray, 0.0, 1e4, iso, inside, max, &mut one, &mut c);
                    assert_eq!(peeled, one, "{demo:?} ray {i} ({ray:?}), at most {max}");
                    assert!(peeled.len() <= max);
                    deep += (peeled.len() >= 3) as usize;
                }
            }
        }
        assert!(deep > 100, "only {deep} rays met 3 crossings or more");
    }

    #[test]
    fn counting_the_crossings_gives_the_peels_number() {
        // The count sets an isolated piece's root aside unsolved and goes on from the piece's
        // end; it may differ from the peel only where two roots are closer than the peel's
        // step past a crossing. Over these rays it never does.
        let mut many = 0;
        for demo in [
            DemoScene::Molecule,
            DemoScene::Pool,
            DemoScene::Blobs,
            DemoScene::Tornado4k,
        ] {
            let scene = metaballs(demo);
            let iso = demo.default_isovalue();
            let p =
                PreparedMetaballs::new(scene.clone(), PrepareOptions::fitted(scene.min_isovalue));
            let eye = demo.default_camera().eye;
            let mut rng = SplitMix64(11);
            let mut hits = Vec::new();
            for i in 0..400 {
                let ball = &scene.balls[(rng.next_u64() % scene.balls.len() as u64) as usize];
                let aim = ball.center + rng.in_unit_ball() * ball.radius;
                // Camera rays, and rays leaving a point near a ball towards a "light".
                let ray = if i % 2 == 0 {
                    Ray::new(eye, aim - eye)
                } else {
                    Ray::new(aim, rng.in_unit_ball().normalize_or(glam::Vec3::Y))
                };
                for max in [1, 2, 5, 50] {
                    hits.clear();
                    let mut c = MetaballCounters::default();
                    p.crossings_counted(&ray, 0.0, 1e4, iso, false, max, &mut hits, &mut c);
                    let n = p.crossing_count_counted(&ray, 0.0, 1e4, iso, false, max, &mut c);
                    assert_eq!(n, hits.len(), "{demo:?} ray {i} ({ray:?}), at most {max}");
                    many += (n >= 4) as usize;
                }
            }
        }
        assert!(many > 100, "only {many} rays crossed 4 surfaces or more");
    }

    #[test]
    fn shadows_through_one_opacity_are_the_same_counted_or_shaded() {
        // A material group of no primitive with another opacity makes the transmittance
        // shade every crossing (the opacities differ); without it the crossings are only
        // counted. Nothing else differs, so the images must be the same, pixel for pixel,
        // and different from the opaque scene's.
        use crate::effects::Effects;
        use crate::shade::MaterialGroup;
        use crate::CpuBackend;
        use std::sync::Arc;
        let backend = CpuBackend::new(2).expect("pool");
        let effects = Effects {
            shadows: true,
            transparency: true,
            layers: 4,
            ..Effects::OFF
        };
        for demo in [DemoScene::Molecule, DemoScene::Pool, DemoScene::Blobs] {
            let opaque = demo.state_at(1.0);
            let mut counted = opaque.clone();
            counted.lighting.materials[0].opacity = 0.5;
            let mut shaded = counted.clone();
            let mut other = shaded.lighting.materials[0];
            other.opacity = 0.8;
            shaded.lighting.materials.push(other);
            shaded.lighting.groups.push(MaterialGroup {
                first: 0,
                count: 0,
                material: 1,
            });
            assert!(counted.lighting.uniform_opacity().is_some());
            assert!(shaded.lighting.uniform_opacity().is_none());
            let view = demo.default_view(96, 72);
            let render = |s: crate::scene::Scene| {
                let (fb, _) = backend.render_effects(&Arc::new(s).prepare(), &view, &effects);
                fb.rgb
            };
            let (a, b) = (render(counted), render(shaded));
            assert!(a == b, "{demo:?}: the counted and shaded shadows differ");
            assert!(
                a != render(opaque),
                "{demo:?}: transparency changed nothing"
            );
        }
    }
}
