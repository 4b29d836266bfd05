//! A metaball state prepared for tracing: per-ball data for the `f32` hot path, the chosen
//! acceleration structure, and the traversal modes that feed the root finders.
//!
//! How it works: a traversal mode picks which balls a root finder sees on which stretch of
//! the ray, and counts what fitted-bvh-metaballs.txt Table 3 counts (node traversals, leaf
//! intersection tests, metaballs considered):
//! - [`Accel::BruteForce`]: every ball the ray crosses, one search over `[t_min, t_max]`.
//! - [`Accel::ActiveList`]: metaballs-tutorial.txt §III: all entries and exits sorted, and
//!   one search per stretch between them with only the balls active there.
//! - [`Accel::Tree`] with a BVH (fitted-bvh-metaballs.txt §4): every leaf the ray crosses,
//!   nearest first, searched over its box with its balls and split balls where one of its own
//!   balls covers the ray; the nearest hit wins and prunes farther nodes.
//! - [`Accel::Tree`] with a Fitted BVH (§5.2): leaves front to back; the first hit ends it.

use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::roots::{self, FindParams, KernelPoly, RayBall, RootFinder, Scratch};
use crate::kinds::metaballs::scene::{MetaballScene, Shape};
use crate::kinds::metaballs::tree::{BuildOptions, Tree, TreeBall, TreeKind, TreeStats, Wide};
use crate::ray::{Hit, Ray};
use glam::Mat3;
use std::cell::RefCell;
use std::sync::{Arc, OnceLock};

// Tiles of primary rays traced as one packet through the Fitted BVH.
mod packet;
#[cfg(test)]
mod packet_tests;
// The packets' vector steps against their single-ray operations.
#[cfg(test)]
mod lanes_tests;
// Shadow rays towards one point light traced as one packet.
mod shadows;

// A packet's rays against one box, eight at a time.
mod slabs;
mod soa;
use soa::Ball;
// Secondary-ray queries (any hit, exit from the solid, optical depth): the effects layer's.
mod occlusion;
mod queries;
// Successive crossings along a ray in one walk (depth peeling).
mod peel;

/// The closed set of acceleration modes.
#[derive(Clone, Debug, PartialEq)]
pub enum Accel {
    BruteForce,
    ActiveList,
    Tree(Tree),
}

/// Which acceleration mode to build.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AccelKind {
    BruteForce,
    ActiveList,
    Tree(BuildOptions),
}

/// How to prepare a state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrepareOptions {
    pub accel: AccelKind,
    pub finder: RootFinder,
    /// Absolute tolerance on hit distances, world units.
    pub tolerance: f32,
    /// The finder's step ([`roots::FindParams::step`]); [`PrepareOptions::with_finder`] sets
    /// the finder's default.
    pub step: f32,
    /// Refine each `f32` hit in `f64` (bisection on the exact field of the balls that hit,
    /// from the `f32` bracket to `1e-12` relative), at the price of an `f64` search per hit.
    pub refine_f64: bool,
    /// Trace a tile of primary rays as one packet through the Fitted BVH (the default;
    /// same hits ray for ray), or every ray alone (for comparison).
    pub packets: bool,
    /// Single rays that stop at the first leaf with a root (first hits, shadow and way-out
    /// queries) walk the Fitted BVH four boxes at a time ([`Wide`]: the same leaves, ranges
    /// and order as the binary walk; the default), or the binary tree node by node (the
    /// paper's Table 3 counts its node traversals).
    pub wide: bool,
}

impl PrepareOptions {
    /// The Fitted BVH with every optimisation, for `scene.min_isovalue`, and Bézier clipping.
    pub fn fitted(min_isovalue: f32) -> PrepareOptions {
        PrepareOptions {
            accel: AccelKind::Tree(BuildOptions::fitted(min_isovalue)),
            finder: RootFinder::BezierClipping,
            tolerance: 1e-4,
            step: RootFinder::BezierClipping.default_step(),
            refine_f64: false,
            packets: true,
            wide: true,
        }
    }

    pub fn with_accel(self, accel: AccelKind) -> PrepareOptions {
        PrepareOptions { accel, ..self }
    }

    /// `finder`, with its default step.
    pub fn with_finder(self, finder: RootFinder) -> PrepareOptions {
        PrepareOptions {
            finder,
            step: finder.default_step(),
            ..self
        }
    }
}

/// A metaball state ready to trace.
#[derive(Debug)]
pub struct PreparedMetaballs {
    scene: MetaballScene,
    balls: Vec<Ball>,
    frames: Vec<Mat3>,
    options: PrepareOptions,
    accel: Accel,
    build_ms: f64,
    /// Built on first use when a query's isovalue is below the one the §5.3 optimisations
    /// were built for: the same structure without them.
    fallback: OnceLock<Accel>,
    /// Whether `accel` is a Fitted BVH whose every box lies inside its parent's, the
    /// condition under which a packet's per-ray leaf ranges equal the single ray's.
    nested: bool,
    /// The main tree's leaf lists as structure-of-arrays (scenes of spheres only).
    spheres: Option<soa::TreeSpheres>,
    /// The main tree four boxes at a time, for single rays that stop at the first leaf with
    /// a root (a nested Fitted BVH only).
    wide: Option<Wide>,
    /// The balls' mean support radius: the length a shadow packet's spread is measured in.
    mean_radius: f32,
    /// This state among every state prepared in the process, so that an occlusion hint
    /// names a leaf of this state's tree and no other's.
    id: u64,
    /// Whether no term of the field is ever negative (every strength positive, the kernel's
    /// coefficients `≥ 0`): then the field is at least any one ball's term, and a ray through
    /// a ball's core is inside the solid there (`occlusion`'s witnesses).
    terms_positive: bool,
}

/// Per-thread buffers of a ray query: the balls along the ray, the root finder's scratch and
/// the (ball, entry, exit) intervals.
type RayScratch = (Vec<RayBall<f32>>, Scratch<f32>, Vec<(u32, f32, f32)>);

/// The rays of a tile's first shadow packet towards a light
/// ([`crate::kinds::contract::PreparedKind::any_hits_towards`]): their roots leave the
/// witnesses that answer rays of the second packet, the rest of the tile's rays, before it is
/// traced. At 1920×1080 (`isoray-bench metaballs`, two rounds, ms) against the tile in packets
/// of 64 with witnesses: Pool 74.6/75.0 against 80.3/77.8, Molecule 90.5/91.3 against
/// 96.0/94.9, Scattered-30k and Tornado-128k even; against one packet without witnesses, Molecule
/// 90.5/91.3 against 111.7/116.0 and Pool 74.6/75.0 against 69.1/69.5 (performance log).
pub const FIRST_SHADOW_PACKET: usize = 64;

/// The `skip` of a leaf walk (`PreparedMetaballs::leaf_walk`) that skips no leaf.
const NO_SKIP: [u32; crate::kinds::contract::HINT_LEAVES] =
    [u32::MAX; crate::kinds::contract::HINT_LEAVES];

/// The next [`PreparedMetaballs::id`].
static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

thread_local! {
    static SCRATCH: RefCell<RayScratch> =
        RefCell::new(Default::default());
}

impl PreparedMetaballs {
    /// Prepares `scene` (already validated) with `options`.
    pub fn new(scene: MetaballScene, options: PrepareOptions) -> PreparedMetaballs {
        let started = std::time::Instant::now();
        let slope = scene.kernel.max_slope();
        let mut frames = Vec::new();
        let balls: Vec<Ball> = scene
            .balls
            .iter()
            .map(|b| {
                let frame = match b.shape {
                    Shape::Sphere => u32::MAX,
                    Shape::Ellipsoid { .. } => {
                        frames.push(b.normalizing());
                        (frames.len() - 1) as u32
                    }
                };
                Ball {
                    center: b.center,
                    inv_r: 1.0 / b.radius,
                    strength: b.strength,
                    lipschitz: b.strength.abs() * slope / b.min_semi_axis(),
                    min_radius: b.min_semi_axis(),
                    frame,
                }
            })
            .collect();
        let accel = build_accel(&scene, options.accel);
        let nested = match &accel {
            Accel::Tree(tree) => tree.kind == TreeKind::Fitted && tree.boxes_nest(),
            Accel::BruteForce | Accel::ActiveList => false,
        };
        let spheres = match &accel {
            Accel::Tree(tree) => soa::TreeSpheres::build(&balls, tree),
            Accel::BruteForce | Accel::ActiveList => None,
        };
        let wide = match &accel {
            // `nested` is `boxes_nest()`, the one condition `Wide::build` checks.
            Accel::Tree(tree) if nested && options.wide => Wide::of_nested(tree),
            _ => None,
        };
        let mean_radius = if scene.balls.is_empty() {
            0.0
        } else {
            (scene.balls.iter().map(|b| b.radius as f64).sum::<f64>() / scene.balls.len() as f64)
                as f32
        };
        let terms_positive = scene.balls.iter().all(|b| b.strength > 0.0)
            && KernelPoly::<f64>::new(scene.kernel)
                .c
                .iter()
                .all(|&c| c >= 0.0);
        PreparedMetaballs {
            mean_radius,
            terms_positive,
            scene,
            balls,
            frames,
            options,
            accel,
            build_ms: started.elapsed().as_secs_f64() * 1e3,
            fallback: OnceLock::new(),
            nested,
            spheres,
            wide,
            id: NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        }
    }

    pub fn scene(&self) -> &MetaballScene {
        &self.scene
    }

    pub fn options(&self) -> &PrepareOptions {
        &self.options
    }

    pub fn accel(&self) -> &Accel {
        &self.accel
    }

    /// Wall time of [`PreparedMetaballs::new`], milliseconds.
    pub fn build_ms(&self) -> f64 {
        self.build_ms
    }

    pub fn tree_stats(&self) -> Option<TreeStats> {
        match &self.accel {
            Accel::Tree(t) => Some(t.stats()),
            _ => None,
        }
    }

    /// The first hit along `ray` in `[t_min, t_max]`.
    pub fn first_hit(&self, ray: &Ray, t_min: f32, t_max: f32, isovalue: f32) -> Option<Hit> {
        let mut counters = MetaballCounters::default();
        self.first_hit_counted(ray, t_min, t_max, isovalue, &mut counters)
    }

    /// [`PreparedMetaballs::first_hit`], adding to `counters`.
    pub fn first_hit_counted(
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
        let params = self.params(isovalue);
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (gathered, scratch, stack) = &mut *guard;
            let mut t = self.trace(
                accel, ray, t_min, t_max, &params, gathered, scratch, stack, counters,
            )?;
            if self.options.refine_f64 {
                t = self.refine_f64(ray, t, t_min, t_max, isovalue, gathered);
            }
            counters.hits += 1;
            Some(self.hit_at(ray, t, gathered))
        })
    }

    /// The hit at distance `t` along `ray`, shaded from `gathered`, the balls of the search
    /// that found it.
    #[inline]
    pub(super) fn hit_at(&self, ray: &Ray, t: f32, gathered: &[RayBall<f32>]) -> Hit {
        self.hit_at_balls(ray, t, gathered.iter().map(|b| b.ball))
    }

    /// [`PreparedMetaballs::hit_at`] from the gathered balls' indices.
    #[inline]
    pub(super) fn hit_at_balls(&self, ray: &Ray, t: f32, balls: impl Iterator<Item = u32>) -> Hit {
        let position = ray.at(t);
        let (normal, albedo, primitive) = self.scene.surface_detail(balls, position);
        Hit {
            t,
            position,
            normal,
            albedo,
            primitive,
        }
    }

    /// The hit distance; on return `gathered` holds the balls of the search that hit.
    #[allow(clippy::too_many_arguments)]
    fn trace(
        &self,
        accel: &Accel,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        params: &FindParams<f32>,
        gathered: &mut Vec<RayBall<f32>>,
        scratch: &mut Scratch<f32>,
        stack: &mut Vec<(u32, f32, f32)>,
        counters: &mut MetaballCounters,
    ) -> Option<f32> {
        let finder = self.options.finder;
        match accel {
            Accel::BruteForce => {
                gathered.clear();
                for i in 0..self.balls.len() as u32 {
                    self.gather(ray, i, true, t_min, t_max, gathered);
                }
                let found = roots::find_first(finder, params, gathered, t_min, t_max, scratch);
                found.counted(counters, gathered.len())
            }
            Accel::ActiveList => {
                gathered.clear();
                for i in 0..self.balls.len() as u32 {
                    self.gather(ray, i, true, t_min, t_max, gathered);
                }
                // Sorted entries and exits; each stretch searched with its active balls.
                let mut events: Vec<(f32, u32)> = Vec::with_capacity(gathered.len() * 2);
                for (k, b) in gathered.iter().enumerate() {
                    events.push((b.t0.max(t_min), (k as u32) << 1));
                    events.push((b.t1.min(t_max), ((k as u32) << 1) | 1));
                }
                events.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
                let mut active: Vec<u32> = Vec::new();
                let mut section: Vec<RayBall<f32>> = Vec::new();
                let mut e = 0;
                while e < events.len() {
                    let t = events[e].0;
                    while e < events.len() && events[e].0 <= t {
                        let k = events[e].1 >> 1;
                        if events[e].1 & 1 == 0 {
                            active.push(k);
                        } else if let Some(p) = active.iter().position(|&a| a == k) {
                            active.swap_remove(p);
                        }
                        e += 1;
                    }
                    if e >= events.len() || active.is_empty() {
                        continue;
                    }
                    section.clear();
                    // Ball order fixed by index, so the sum is the same whatever the sort.
                    active.sort_unstable();
                    section.extend(active.iter().map(|&k| gathered[k as usize]));
                    let found =
                        roots::find_first(finder, params, &section, t, events[e].0, scratch);
                    if let Some(t) = found.counted(counters, section.len()) {
                        *gathered = section;
                        return Some(t);
                    }
                }
                None
            }
            Accel::Tree(tree) => self
                .leaf_walk(
                    tree,
                    ray,
                    t_min,
                    t_max,
                    params,
                    finder,
                    (tree.kind == TreeKind::Fitted, NO_SKIP),
                    gathered,
                    scratch,
                    stack,
                    counters,
                )
                .map(|(t, _)| t),
        }
    }

    /// `t`, an `f32` hit of `ray` found among `gathered`, refined in `f64`: the same balls along
    /// the ray recomputed in `f64`, a bracket `g(lo) < 0 ≤ g(hi)` grown from the tolerance
    /// about `t`, and bisection to `1e-12` relative. Without a bracket `t` is kept.
    fn refine_f64(
        &self,
        ray: &Ray,
        t: f32,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        gathered: &[RayBall<f32>],
    ) -> f32 {
        let kernel = KernelPoly::<f64>::new(self.scene.kernel);
        let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
        let balls: Vec<RayBall<f64>> = gathered
            .iter()
            .filter_map(|rb| {
                let b = &self.balls[rb.ball as usize];
                let (e, g) = if b.frame == u32::MAX {
                    let inv_r = 1.0 / self.scene.balls[rb.ball as usize].radius as f64;
                    ((o - b.center.as_dvec3()) * inv_r, d * inv_r)
                } else {
                    let m = self.frames[b.frame as usize].as_dmat3();
                    (m * (o - b.center.as_dvec3()), m * d)
                };
                let (t0, t1, a, tc, s_min) = RayBall::along(e.to_array(), g.to_array())?;
                Some(RayBall {
                    t0,
                    t1,
                    a,
                    tc,
                    s_min,
                    q: b.strength as f64,
                    ..RayBall::default()
                })
            })
            .collect();
        let g = |t: f64| balls.iter().map(|b| b.term(&kernel, t)).sum::<f64>() - isovalue as f64;
        let step = (self.options.tolerance as f64).max(1e-7 * (t as f64).abs());
        let (lo_limit, hi_limit) = (t_min as f64, t_max as f64);
        let (mut lo, mut hi) = (t as f64, t as f64);
        let mut grow = step;
        for _ in 0..8 {
            if g(hi) >= 0.0 {
                break;
            }
            hi = (hi + grow).min(hi_limit);
            grow *= 2.0;
        }
        grow = step;
        for _ in 0..8 {
            if lo <= lo_limit || g(lo) < 0.0 {
                break;
            }
            lo = (lo - grow).max(lo_limit);
            grow *= 2.0;
        }
        if lo <= lo_limit && g(lo) >= 0.0 {
            return lo_limit as f32; // the segment starts inside
        }
        if !(g(lo) < 0.0 && g(hi) >= 0.0) {
            return t;
        }
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if hi - lo <= 1e-12 * hi.abs().max(1.0) || !(lo < mid && mid < hi) {
                break;
            }
            if g(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi as f32
    }

    /// Appends ball `i` if the ray's stretch `[lo, hi]` crosses its support.
    #[inline]
    fn gather(
        &self,
        ray: &Ray,
        i: u32,
        owner: bool,
        lo: f32,
        hi: f32,
        out: &mut Vec<RayBall<f32>>,
    ) {
        let Some((t0, t1, a, tc, s_min)) = self.along(ray, i) else {
            return;
        };
        if t1 < lo || t0 > hi {
            return;
        }
        out.push(self.balls[i as usize].seen(i, (t0, t1, a, tc, s_min), owner));
    }

    /// Ball `i` as `ray` sees it: [`RayBall::along`] in the ball's unit frame.
    #[inline]
    fn along(&self, ray: &Ray, i: u32) -> Option<(f32, f32, f32, f32, f32)> {
        let b = &self.balls[i as usize];
        let (e, g) = if b.frame == u32::MAX {
            let inv_r = b.inv_r;
            ((ray.origin - b.center) * inv_r, ray.dir * inv_r)
        } else {
            let m = self.frames[b.frame as usize];
            (m * (ray.origin - b.center), m * ray.dir)
        };
        RayBall::along(e.to_array(), g.to_array())
    }
}

fn build_accel(scene: &MetaballScene, kind: AccelKind) -> Accel {
    match kind {
        AccelKind::BruteForce => Accel::BruteForce,
        AccelKind::ActiveList => Accel::ActiveList,
        AccelKind::Tree(opts) => Accel::Tree(Tree::build(&tree_balls(scene), scene.kernel, opts)),
    }
}

/// The tree for isovalues below the one the §5.3 optimisations were built for: the same
/// structure without them. Built lazily inside a `OnceLock` that other render threads may
/// wait on, so it never forks (a forking thread may run one of those waiting frames and wait
/// on itself).
fn build_fallback(scene: &MetaballScene, opts: &BuildOptions) -> Accel {
    let relaxed = BuildOptions {
        tight_boxes: false,
        discard_split: false,
        ..*opts
    };
    Accel::Tree(Tree::build_on_this_thread(
        &tree_balls(scene),
        scene.kernel,
        relaxed,
    ))
}

/// What a tree build needs of each ball.
fn tree_balls(scene: &MetaballScene) -> Vec<TreeBall> {
    scene
        .balls
        .iter()
        .map(|b| TreeBall {
            center: b.center,
            radius: b.radius,
            strength: b.strength,
        })
        .collect()
}

/// Brute force and Bézier clipping on an unprepared scene.
/// (Defined here, beside the engine it builds, so that the scene's module needs no engine.)
impl MetaballScene {
    /// The first crossing of the isosurface along `ray` within `[t_min, t_max]`, by brute
    /// force and Bézier clipping, without preparing anything (tests, one-off queries).
    pub fn first_hit(&self, ray: &Ray, t_min: f32, t_max: f32, isovalue: f32) -> Option<Hit> {
        first_hit_unprepared(self, ray, t_min, t_max, isovalue)
    }
}

pub fn first_hit_unprepared(
    scene: &MetaballScene,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
) -> Option<Hit> {
    let opts = PrepareOptions::fitted(scene.min_isovalue).with_accel(AccelKind::BruteForce);
    PreparedMetaballs::new(scene.clone(), opts).first_hit(ray, t_min, t_max, isovalue)
}

/// Shares a prepared state.
pub type SharedMetaballs = Arc<PreparedMetaballs>;
