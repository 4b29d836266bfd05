//! The queries secondary rays make of a prepared metaball state, besides the first hit:
//! - [`PreparedMetaballs::any_hit_counted`]: whether the surface crosses a segment at all,
//!   with early exit at the first leaf that holds a root and no normal or colour computed
//!   (shadow and occlusion rays; fitted-bvh-metaballs.txt Table 2 traces them through the same
//!   Fitted BVH as primary rays).
//! - [`PreparedMetaballs::exit_hit_counted`]: from a point inside the solid (`F ≥ T`), the
//!   first point where the field falls back to `T`: refraction and transparency rays leaving a
//!   blob, and rays starting inside a clipped solid. It searches `-F ≥ -T` with Bézier clipping
//!   (bezier-clipping-metaballs.txt §3.2 is sign-agnostic: it clips a Bernstein polynomial).
//!   The Fitted BVH's boxes hold the whole solid (a point with `F ≥ T` lies within `r_max` of
//!   some ball, §5.3.1), so the same front-to-back walk finds the exit.
//! - [`PreparedMetaballs::optical_depth`]: `∫ F dt` over a segment, exactly: each ball's field
//!   along the ray is a polynomial in `t` (ibid. eq. 13), integrated in closed form over its
//!   stretch of the segment. This is the absorption through the metaball density of
//!   bezier-clipping-metaballs.txt §5. It needs every ball's whole support, so it walks the
//!   Fitted BVH built without the §5.3 optimisations (the same fallback structure low
//!   isovalues use), whose disjoint leaves together hold the complete field.

use super::{build_fallback, Accel, AccelKind, PreparedMetaballs, NO_SKIP, SCRATCH};
use crate::kinds::contract::HINT_LEAVES;
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::roots::{self, FindParams, KernelPoly, RayBall, RootFinder, Scratch};
use crate::kinds::metaballs::tree::{BuildOptions, Node, Tree, TreeKind};
use crate::ray::{Hit, Ray};

impl PreparedMetaballs {
    /// The structure a query at `isovalue` may use (the fallback below the build's floor).
    pub(super) fn accel_for(&self, isovalue: f32) -> &Accel {
        match (&self.options.accel, &self.accel) {
            (AccelKind::Tree(opts), Accel::Tree(_))
                if opts.depends_on_isovalue() && isovalue < opts.isovalue =>
            {
                self.relaxed_accel(opts)
            }
            (_, accel) => accel,
        }
    }

    /// The tree a query at `isovalue` walks, if this state traces with one (what the GPU
    /// backend uploads).
    pub fn tree_for(&self, isovalue: f32) -> Option<&Tree> {
        match self.accel_for(isovalue) {
            Accel::Tree(tree) => Some(tree),
            Accel::BruteForce | Accel::ActiveList => None,
        }
    }

    fn relaxed_accel(&self, opts: &BuildOptions) -> &Accel {
        self.fallback
            .get_or_init(|| build_fallback(&self.scene, opts))
    }

    /// The search for the way out of the solid: `-F ≥ -T` (the kernel negated).
    pub(super) fn exit_params(&self, isovalue: f32) -> FindParams<f32> {
        let mut params = self.params(isovalue);
        for c in params.kernel.c.iter_mut() {
            *c = -*c;
        }
        params.isovalue = -isovalue;
        params
    }

    pub(super) fn params(&self, isovalue: f32) -> FindParams<f32> {
        FindParams {
            kernel: KernelPoly::new(self.scene.kernel),
            isovalue,
            tolerance: self.options.tolerance,
            owners_only: false,
            step: self.options.step,
            bounded: false,
        }
    }

    /// A point of `[t_min, t_max]` of `ray` where `F ≥ T` starts, stopping at the first leaf
    /// with a root (`t_min` itself when the segment starts inside the solid).
    pub fn any_hit_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut MetaballCounters,
    ) -> Option<f32> {
        self.any_hit_leaf(ray, (t_min, t_max), isovalue, NO_SKIP, counters)
            .0
    }

    /// [`PreparedMetaballs::any_hit_counted`]'s root, and the tree leaf it was found in (none
    /// without a tree); `skip` as [`PreparedMetaballs::leaf_walk`]'s.
    pub(super) fn any_hit_leaf(
        &self,
        ray: &Ray,
        (t_min, t_max): (f32, f32),
        isovalue: f32,
        skip: [u32; HINT_LEAVES],
        counters: &mut MetaballCounters,
    ) -> (Option<f32>, Option<Node>) {
        counters.rays += 1;
        if !(isovalue > 0.0) || !isovalue.is_finite() || !(t_min < t_max) {
            return (None, None);
        }
        let accel = self.accel_for(isovalue);
        let params = self.params(isovalue);
        let finder = self.options.finder;
        let hit = SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (gathered, scratch, stack) = &mut *guard;
            match accel {
                Accel::Tree(tree) => match self.leaf_walk(
                    tree,
                    ray,
                    t_min,
                    t_max,
                    &params,
                    finder,
                    (true, skip),
                    gathered,
                    scratch,
                    stack,
                    counters,
                ) {
                    Some((t, leaf)) => (Some(t), Some(leaf)),
                    None => (None, None),
                },
                _ => {
                    let t = self.trace(
                        accel, ray, t_min, t_max, &params, gathered, scratch, stack, counters,
                    );
                    (t, None)
                }
            }
        });
        counters.hits += hit.0.is_some() as u64;
        hit
    }

    /// From a start inside the solid, the first point of `[t_min, t_max]` where the field
    /// falls to `isovalue`; its normal points out of the solid (along the ray).
    pub fn exit_hit_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut MetaballCounters,
    ) -> Option<Hit> {
        counters.rays += 1;
        if !(isovalue > 0.0) || !isovalue.is_finite() || !(t_min < t_max) {
            return None;
        }
        let accel = self.accel_for(isovalue);
        let params = self.exit_params(isovalue);
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (gathered, scratch, stack) = &mut *guard;
            let t = match accel {
                Accel::Tree(tree) => {
                    let first_leaf = tree.kind == TreeKind::Fitted;
                    self.leaf_walk(
                        tree,
                        ray,
                        t_min,
                        t_max,
                        &params,
                        RootFinder::BezierClipping,
                        (first_leaf, NO_SKIP),
                        gathered,
                        scratch,
                        stack,
                        counters,
                    )?
                    .0
                }
                _ => {
                    gathered.clear();
                    for i in 0..self.balls.len() as u32 {
                        self.gather(ray, i, true, t_min, t_max, gathered);
                    }
                    let found = roots::find_first(
                        RootFinder::BezierClipping,
                        &params,
                        gathered,
                        t_min,
                        t_max,
                        scratch,
                    );
                    found.counted(counters, gathered.len())?
                }
            };
            counters.hits += 1;
            Some(self.hit_at(ray, t, gathered))
        })
    }

    /// Leaves front to back; in each, the balls whose support the stretch crosses and one
    /// search. `first_leaf`: the first leaf with a root answers (the Fitted BVH's disjoint
    /// leaves, or any hit at all); otherwise the nearest root over every leaf (the BVH's
    /// overlapping leaves, searched only where an owner covers the ray). `skip`: the leaves
    /// starting at these indices of the tree's ball list are not searched (their searches on
    /// the walk's ranges are known to find no root; `u32::MAX` names none). Returns the root and the leaf it was found in;
    /// `gathered` then holds the balls of that leaf's search. The walk is
    /// [`PreparedMetaballs::walk_tree`]'s.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn leaf_walk(
        &self,
        tree: &Tree,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        params: &FindParams<f32>,
        finder: RootFinder,
        (first_leaf, skip): (bool, [u32; HINT_LEAVES]),
        gathered: &mut Vec<RayBall<f32>>,
        scratch: &mut Scratch<f32>,
        stack: &mut Vec<(u32, f32, f32)>,
        counters: &mut MetaballCounters,
    ) -> Option<(f32, Node)> {
        let leaf_params = self.leaf_params(tree, params);
        let inv_dir = ray.dir.recip();
        let mut best_balls: Vec<RayBall<f32>> = Vec::new();
        let mut answered: Option<Node> = None;
        let mut node_traversals = counters.node_traversals;
        let leaf = |node: &Node, near: f32, far: f32, best: Option<f32>| {
            if node.count > 0 && skip.contains(&node.first) {
                return None;
            }
            let search = (near, far, &leaf_params, finder);
            let t = self.search_node(tree, node, ray, search, gathered, scratch, counters)?;
            if first_leaf {
                answered = Some(*node);
                return Some(t);
            }
            if best.is_none_or(|b| t < b) {
                std::mem::swap(&mut best_balls, gathered);
                answered = Some(*node);
                return Some(t);
            }
            None
        };
        let walk = (ray.origin, inv_dir, t_min, t_max);
        let best = self.walk_tree(tree, walk, first_leaf, stack, &mut node_traversals, leaf);
        counters.node_traversals = node_traversals;
        // The first leaf's root left its balls in `gathered`; the nearest of several swapped
        // them out.
        if best.is_some() && !first_leaf {
            *gathered = best_balls;
        }
        Some((best?, answered?))
    }

    /// The search parameters of `tree`'s leaves: owners only in the BVH's overlapping leaves.
    #[inline]
    pub(super) fn leaf_params(&self, tree: &Tree, params: &FindParams<f32>) -> FindParams<f32> {
        FindParams {
            owners_only: tree.kind != TreeKind::Fitted,
            ..*params
        }
    }

    /// One leaf of `tree` searched on `[near, far]` of `ray` with `params` (from
    /// [`PreparedMetaballs::leaf_params`]) and `finder`: its balls gathered from the tree's
    /// structure-of-arrays where it has them, else ball by ball, then one root search.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn search_node(
        &self,
        tree: &Tree,
        node: &Node,
        ray: &Ray,
        (near, far, params, finder): (f32, f32, &FindParams<f32>, RootFinder),
        gathered: &mut Vec<RayBall<f32>>,
        scratch: &mut Scratch<f32>,
        counters: &mut MetaballCounters,
    ) -> Option<f32> {
        let leaf = tree.leaf_balls(node);
        match self.spheres_of(tree) {
            Some(soa) => {
                gathered.clear();
                let owners = (node.owned as usize, params.owners_only);
                let first = node.first as usize;
                // A way-out search (negated isovalue) runs inside the solid.
                let at = ((near, far), params.isovalue < 0.0);
                soa.gather(&self.balls, leaf, first, owners, ray, at, gathered);
                search_gathered(params, finder, near, far, gathered, scratch, counters)
            }
            None => self.search_leaf(
                leaf,
                node.owned as usize,
                ray,
                near,
                far,
                params,
                finder,
                gathered,
                scratch,
                counters,
            ),
        }
    }

    /// [`Tree::walk`] of `tree`, or, where `first_leaf` holds and `tree` is this state's main
    /// tree with a four-wide view ([`Wide`](crate::kinds::metaballs::tree::Wide), built unless `PrepareOptions::wide` is off), the
    /// view's walk: the same leaves with the same ranges in the same order, fewer nodes popped.
    /// `ray`: the origin, the direction's reciprocal, `t_min` and `t_max`.
    #[inline]
    pub(super) fn walk_tree(
        &self,
        tree: &Tree,
        ray: (glam::Vec3, glam::Vec3, f32, f32),
        first_leaf: bool,
        stack: &mut Vec<(u32, f32, f32)>,
        node_traversals: &mut u64,
        leaf: impl FnMut(&Node, f32, f32, Option<f32>) -> Option<f32>,
    ) -> Option<f32> {
        match (&self.accel, &self.wide) {
            (Accel::Tree(main), Some(w)) if first_leaf && std::ptr::eq(main, tree) => {
                w.walk_first(tree, ray, stack, node_traversals, leaf)
            }
            _ => {
                let (origin, inv_dir, t_min, t_max) = ray;
                tree.walk(
                    origin,
                    inv_dir,
                    t_min,
                    t_max,
                    first_leaf,
                    stack,
                    node_traversals,
                    leaf,
                )
            }
        }
    }

    /// `tree`'s leaf lists as structure-of-arrays, when `tree` is this state's main tree and
    /// the scene is all spheres.
    #[inline]
    pub(super) fn spheres_of(&self, tree: &Tree) -> Option<&super::soa::TreeSpheres> {
        match (&self.accel, &self.spheres) {
            (Accel::Tree(main), Some(s)) if std::ptr::eq(main, tree) => Some(s),
            _ => None,
        }
    }

    /// A leaf searched on `[near, far]` of `ray`: of `balls` (a leaf's list, owned balls
    /// first, `owned` of them), those whose support the stretch crosses (owners only where
    /// `params.owners_only`), then one root search. On return `gathered` holds those balls.
    /// The single-ray walk and the packet walks all call this (a packet with its leaf's list
    /// less balls no ray of it can gather: the same gathered balls in the same order), so a
    /// packet's per-ray arithmetic is the single ray's.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn search_leaf(
        &self,
        balls: &[u32],
        owned: usize,
        ray: &Ray,
        near: f32,
        far: f32,
        params: &FindParams<f32>,
        finder: RootFinder,
        gathered: &mut Vec<RayBall<f32>>,
        scratch: &mut Scratch<f32>,
        counters: &mut MetaballCounters,
    ) -> Option<f32> {
        gathered.clear();
        for (k, &b) in balls.iter().enumerate() {
            let owner = !params.owners_only || k < owned;
            self.gather(ray, b, owner, near, far, gathered);
        }
        search_gathered(params, finder, near, far, gathered, scratch, counters)
    }

    /// The tree [`PreparedMetaballs::optical_depth`] walks: only a Fitted BVH has one here (one
    /// built for a higher isovalue is swapped for its relaxed twin, whose leaves hold every
    /// ball's whole support); `None`: every other mode integrates over all balls.
    pub fn optical_depth_tree(&self) -> Option<&Tree> {
        if let (AccelKind::Tree(opts), Accel::Tree(tree)) = (&self.options.accel, &self.accel) {
            if opts.kind != TreeKind::Fitted {
                None
            } else if opts.depends_on_isovalue() {
                match self.relaxed_accel(opts) {
                    Accel::Tree(t) => Some(t),
                    _ => None,
                }
            } else {
                Some(tree)
            }
        } else {
            None
        }
    }

    /// `∫ F dt` over `[t_min, t_max]` of `ray`: the summed field integrated exactly.
    pub fn optical_depth(&self, ray: &Ray, t_min: f32, t_max: f32) -> f32 {
        if !(t_min < t_max) || self.balls.is_empty() {
            return 0.0;
        }
        let kernel = self.scene.kernel.w_coefficients();
        let degree = self.scene.kernel.w_degree();
        let tree = self.optical_depth_tree();
        let t_max = t_max.min(1.0e30);
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (gathered, _, stack) = &mut *guard;
            let mut sum = 0.0f64;
            let mut integrate = |gathered: &[RayBall<f32>], lo: f32, hi: f32| {
                for b in gathered {
                    let (a, z) = (b.t0.max(lo), b.t1.min(hi));
                    if a < z {
                        sum += b.q as f64 * ball_integral(b, &kernel, degree, a, z);
                    }
                }
            };
            match tree {
                None => {
                    gathered.clear();
                    for i in 0..self.balls.len() as u32 {
                        self.gather(ray, i, true, t_min, t_max, gathered);
                    }
                    integrate(gathered, t_min, t_max);
                }
                Some(tree) => {
                    // Every leaf the segment crosses: the leaves are disjoint and together
                    // hold every ball's support, each with its complete field.
                    let inv_dir = ray.dir.recip();
                    stack.clear();
                    if let Some((a, b)) = tree.nodes[0]
                        .bounds
                        .ray_range(ray.origin, inv_dir, t_min, t_max)
                    {
                        stack.push((0, a, b));
                    }
                    while let Some((i, near, far)) = stack.pop() {
                        let node = &tree.nodes[i as usize];
                        if node.is_leaf() {
                            gathered.clear();
                            for &b in tree.leaf_balls(node) {
                                self.gather(ray, b, true, near, far, gathered);
                            }
                            integrate(gathered, near, far);
                            continue;
                        }
                        for c in [node.first, node.first + 1] {
                            if let Some((a, b)) = tree.nodes[c as usize]
                                .bounds
                                .ray_range(ray.origin, inv_dir, near, far)
                            {
                                stack.push((c, a, b));
                            }
                        }
                    }
                }
            }
            sum as f32
        })
    }
}

/// `∫ f(s(t)) dt` over `[lo, hi]` for one ball (strength not applied), with
/// `f = Σ c_k w^k`, `w = 1 - s` and `s(t) = a (t - tc)² + s_min`, in closed form in `f64`.
fn ball_integral(
    ball: &RayBall<f32>,
    kernel: &[f64; crate::kinds::metaballs::kernel::MAX_W_DEGREE + 1],
    degree: usize,
    lo: f32,
    hi: f32,
) -> f64 {
    const N: usize = 2 * crate::kinds::metaballs::kernel::MAX_W_DEGREE + 1;
    let (a, tc, s_min) = (ball.a as f64, ball.tc as f64, ball.s_min as f64);
    let h = hi as f64 - lo as f64;
    // s(t) = a (t - tc)² + s_min; with d = lo - tc, s(lo + u) = s0 + s1 u + a u², so
    // w = (1 - s0) - s1 u - a u².
    let d = lo as f64 - tc;
    let s0 = a * d * d + s_min;
    let s1 = 2.0 * a * d;
    let w = [1.0 - s0, -s1, -a];
    let mut wk = [0.0f64; N];
    wk[0] = 1.0;
    let mut len = 1;
    let mut poly = [0.0f64; N];
    poly[0] = kernel[0];
    for &ck in kernel.iter().take(degree + 1).skip(1) {
        let mut next = [0.0f64; N];
        for (j, &x) in wk.iter().enumerate().take(len) {
            for (l, &y) in w.iter().enumerate() {
                next[j + l] += x * y;
            }
        }
        wk = next;
        len += 2;
        for j in 0..len {
            poly[j] += ck * wk[j];
        }
    }
    // ∫_0^h Σ p_j u^j du, by Horner on h.
    let mut acc = 0.0;
    for j in (0..len).rev() {
        acc = acc * h + poly[j] / (j + 1) as f64;
    }
    acc * h
}

/// The leaf search over balls already gathered (none: no search, nothing counted, as
/// [`PreparedMetaballs::search_leaf`] does).
#[inline]
pub(super) fn search_gathered(
    params: &FindParams<f32>,
    finder: RootFinder,
    near: f32,
    far: f32,
    gathered: &[RayBall<f32>],
    scratch: &mut Scratch<f32>,
    counters: &mut MetaballCounters,
) -> Option<f32> {
    if gathered.is_empty() {
        return None;
    }
    roots::find_first(finder, params, gathered, near, far, scratch)
        .counted(counters, gathered.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::rng::SplitMix64;
    use crate::kinds::metaballs::{Kernel, Metaball, MetaballScene, PrepareOptions};
    use crate::scenes::DemoScene;
    use glam::Vec3;

    fn blobs() -> MetaballScene {
        match DemoScene::Blobs.state_at(2.0).geometry {
            crate::scene::Geometry::Metaballs(m) => m,
            crate::scene::Geometry::Tets(_) | crate::scene::Geometry::Surfels(_) => {
                panic!("Blobs is a metaball scene")
            }
        }
    }

    fn prepared(scene: &MetaballScene, accel: AccelKind) -> PreparedMetaballs {
        let options = PrepareOptions::fitted(scene.min_isovalue).with_accel(accel);
        PreparedMetaballs::new(scene.clone(), options)
    }

    fn random_ray(rng: &mut SplitMix64, spread: f32) -> Ray {
        let origin = rng.in_unit_ball() * spread;
        Ray::new(origin, rng.in_unit_ball().normalize_or(Vec3::X))
    }

    #[test]
    fn exit_of_a_single_ball_is_its_analytic_sphere() {
        // A Wyvill ball of radius 2 at T = 0.5 is the unit sphere.
        let scene = MetaballScene::new(
            Kernel::Wyvill,
            vec![Metaball::sphere(Vec3::ZERO, 2.0, 1.0, Vec3::ONE)],
        );
        for accel in [
            AccelKind::BruteForce,
            AccelKind::Tree(BuildOptions::fitted(0.05)),
        ] {
            let p = prepared(&scene, accel);
            let ray = Ray::new(Vec3::new(0.2, 0.1, 0.0), Vec3::X);
            let hit = p
                .exit_hit_counted(&ray, 0.0, 100.0, 0.5, &mut MetaballCounters::default())
                .expect("leaves the unit sphere");
            let expected = (1.0f32 - 0.1 * 0.1).sqrt() - 0.2;
            assert!((hit.t - expected).abs() < 1e-4, "{accel:?}: {}", hit.t);
            assert!(hit.normal.dot(hit.position.normalize()) > 0.999);
            assert_eq!(
                p.any_hit_counted(&ray, 0.0, 100.0, 0.5, &mut MetaballCounters::default()),
                Some(0.0),
                "any hit from inside reports the start"
            );
            let outside = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
            let t = p
                .any_hit_counted(&outside, 0.0, 100.0, 0.5, &mut MetaballCounters::default())
                .expect("hits");
            assert!((t - 4.0).abs() < 1e-3);
        }
    }

    #[test]
    fn fitted_queries_agree_with_brute_force_on_blobs() {
        let scene = blobs();
        let brute = prepared(&scene, AccelKind::BruteForce);
        let fitted = prepared(&scene, AccelKind::Tree(BuildOptions::fitted(0.05)));
        let bvh = prepared(&scene, AccelKind::Tree(BuildOptions::bvh()));
        let mut rng = SplitMix64(7);
        let mut c = MetaballCounters::default();
        let (mut inside, mut any) = (0, 0);
        for _ in 0..400 {
            let ray = random_ray(&mut rng, 3.0);
            let isovalue = 0.5;
            let first = brute.first_hit_counted(&ray, 0.0, 50.0, isovalue, &mut c);
            for p in [&fitted, &bvh] {
                let a = p.any_hit_counted(&ray, 0.0, 50.0, isovalue, &mut c);
                assert_eq!(a.is_some(), first.is_some(), "{ray:?}");
            }
            let Some(first) = first else { continue };
            any += 1;
            if first.t > 0.0 {
                continue;
            }
            // The ray starts inside the solid: every structure finds the same exit.
            inside += 1;
            let want = brute
                .exit_hit_counted(&ray, 0.0, 50.0, isovalue, &mut c)
                .expect("a finite solid is left");
            for p in [&fitted, &bvh] {
                let got = p
                    .exit_hit_counted(&ray, 0.0, 50.0, isovalue, &mut c)
                    .expect("exit");
                assert!((got.t - want.t).abs() < 2e-3, "{} vs {}", got.t, want.t);
            }
        }
        assert!(inside > 20 && any > 100, "inside {inside}, any {any}");
    }

    #[test]
    fn optical_depth_is_the_integral_of_the_field() {
        let scene = blobs();
        let brute = prepared(&scene, AccelKind::BruteForce);
        let fitted = prepared(&scene, AccelKind::Tree(BuildOptions::fitted(0.5)));
        let mut rng = SplitMix64(11);
        let mut nonzero = 0;
        for _ in 0..60 {
            let ray = random_ray(&mut rng, 4.0);
            let (a, b) = (rng.range(0.0, 2.0), rng.range(3.0, 12.0));
            // Simpson's rule on the f32 field, 4000 intervals.
            let all: Vec<u32> = (0..scene.balls.len() as u32).collect();
            let n = 4000;
            let h = (b - a) as f64 / n as f64;
            let f = |k: usize| scene.field_at(&all, ray.at(a + (k as f64 * h) as f32)) as f64;
            let mut simpson = f(0) + f(n);
            for k in 1..n {
                simpson += if k % 2 == 1 { 4.0 } else { 2.0 } * f(k);
            }
            simpson *= h / 3.0;
            let exact = brute.optical_depth(&ray, a, b) as f64;
            let tree = fitted.optical_depth(&ray, a, b) as f64;
            assert!(
                (exact - simpson).abs() < 1e-3 * (1.0 + simpson),
                "{exact} vs {simpson}"
            );
            assert!(
                (tree - exact).abs() < 1e-4 * (1.0 + exact),
                "{tree} vs {exact}"
            );
            nonzero += (exact > 0.1) as u32;
        }
        assert!(nonzero >= 10, "{nonzero} rays crossed the blobs");
    }
}
