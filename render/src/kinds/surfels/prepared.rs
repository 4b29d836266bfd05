//! A surfel step ready to trace: its hierarchy updated lazily, eagerly or rebuilt
//! (deforming-point-sampled-surfaces.txt §4.1.2, §4.4, §5's baseline, §6's heuristic).
//!
//! How it works: preparing a step computes only the optimal rigid frame and the per-node
//! relative terms (linear in the simulation nodes). In lazy mode every inner sphere has a
//! [`LazyNode`] record (its children, centre and radius together) and every surfel a
//! once-only slot for this step, filled by whichever ray touches it first; a filled value is
//! a pure function of the step (eq. 4 and 9 for spheres, eq. 1 for surfels), so it is the
//! same whatever thread computes it, and no lock is taken. A traversal that has updated both
//! children of a sphere tightens it by eq. 11 (the radius kept by `fetch_min`); which rays
//! see the tighter radius depends on timing, but every radius in use is a conservative
//! bound, so the set of hits, and the image, do not (the traversal returns the
//! nearest hit, ties to the lower surfel).

use crate::kinds::contract::RayStart;
use crate::kinds::surfels::cones::Widening;
use crate::kinds::surfels::deform::{
    deform_surfel, node_centre, node_sphere, radius_from_children, sphere_around, DeformedSurfel,
    LeafSpheres, StepFrame,
};
use crate::kinds::surfels::model::SurfelModel;
use crate::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, SurfelScene, UpdateMode};
use crate::kinds::surfels::tree::{SphereTree, TreeNode, MIXED};
use glam::{Mat3, Vec3};
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::atomic::{fence, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

/// A step with a node whose Jacobian relative to its body's rigid frame has a Frobenius norm
/// above this (a stretch or shear of several times), or that moved more than
/// `LOOSE_MOVE` root radii away from where its body's rigid motion puts it, falls back to a
/// rebuild: eq. 9's bounds would be too loose to prune anything (the documented fallback).
pub const LOOSE_GRADIENT: f32 = 4.0;
pub const LOOSE_MOVE: f32 = 2.0;
/// Auto mode refits eagerly when the previous step touched more than this share of surfels.
/// `isoray-bench surfels` at 512×384 with shadows (lazy against eager ms a frame, surfels a
/// lazy frame deforms): `surfel-impact` 115.7 against 125.1 (54%), `surfel-heads` 48.0
/// against 58.1 (67%), `surfel-balls` at full detail about even (126–131 against 127, 72%,
/// two runs); the refit's tighter tree (45 sphere tests a ray against 61 on
/// `surfel-impact`) pays for deforming every surfel only when a frame touches most of them.
pub const EAGER_SHARE: f32 = 0.7;
/// A [`LazyNode`]'s radius before the node is updated (above every positive `f32`'s bits).
const EMPTY: u32 = u32::MAX;
/// The next [`PreparedSurfels::id`].
static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// One sphere of a lazy step, with the node's children alongside so that a traversal reads
/// one 24-byte record per node: empty until a ray first touches it, then its eq. 4 centre
/// and eq. 9 radius (the sphere around its children for a small subtree,
/// `traverse::SMALL_SUBTREE`); once both children are updated, the smallest sphere around them where
/// that is tighter (eq. 11's bound with the parent's centre free to move,
/// [`sphere_around`]); a leaf's is its deformed surfel's sphere.
///
/// Lock-free and deterministic. The sphere is a sequence lock that never waits: a writer
/// claims the record (`CLAIMED`), writes the centre and publishes a radius strictly smaller
/// than the one it replaced; a reader that finds the record claimed, or its radius changed
/// while it read the centre, takes `None` and computes the node's eq. 4 and 9 sphere itself
/// (a pure function of the step). Radii only decrease, so a radius read twice the same is
/// the same publication. Every sphere the record ever holds bounds the surfels below, so
/// which one a ray sees changes its work, never its hits (the traversal returns the nearest
/// hit, ties to the lower surfel).
#[derive(Debug)]
pub struct LazyNode {
    pub kids: [u32; 2],
    centre: [AtomicU32; 3],
    radius: AtomicU32,
}

/// A [`LazyNode`]'s radius while one thread writes it (above every positive `f32`'s bits).
const CLAIMED: u32 = u32::MAX - 1;

impl LazyNode {
    fn new(kids: [u32; 2]) -> LazyNode {
        LazyNode {
            kids,
            centre: [AtomicU32::new(0), AtomicU32::new(0), AtomicU32::new(0)],
            radius: AtomicU32::new(EMPTY),
        }
    }

    /// The sphere in use, if the node is updated and not being written.
    #[inline]
    pub fn get(&self) -> Option<(Vec3, f32)> {
        let r = self.radius.load(Ordering::Acquire);
        if r >= CLAIMED {
            return None;
        }
        let c = load3(&self.centre);
        fence(Ordering::Acquire);
        (self.radius.load(Ordering::Relaxed) == r).then(|| (c, f32::from_bits(r)))
    }

    /// Publishes `(centre, radius)` if its radius is below the one held (or none is held) and
    /// no other thread is writing; otherwise leaves the record as it is.
    #[inline]
    pub fn set(&self, centre: Vec3, radius: f32) {
        let bits = radius.to_bits();
        let now = self.radius.load(Ordering::Relaxed);
        if now == CLAIMED || (now != EMPTY && now <= bits) {
            return;
        }
        if (self.radius)
            .compare_exchange(now, CLAIMED, Ordering::Acquire, Ordering::Relaxed)
            .is_err()
        {
            return;
        }
        fence(Ordering::Release);
        for (a, v) in self.centre.iter().zip(centre.to_array()) {
            a.store(v.to_bits(), Ordering::Relaxed);
        }
        self.radius.store(bits, Ordering::Release);
    }

    /// Given both children's spheres of an updated node whose sphere in use has `radius`:
    /// keeps the sphere around the children if that is tighter.
    #[inline]
    pub fn tighten(&self, radius: f32, kids: [(Vec3, f32); 2]) {
        let (centre, around) = sphere_around(kids[0], kids[1]);
        if around < radius {
            self.set(centre, around);
        }
    }
}

#[inline]
fn load3(a: &[AtomicU32; 3]) -> Vec3 {
    Vec3::from_array(
        a.each_ref()
            .map(|v| f32::from_bits(v.load(Ordering::Relaxed))),
    )
}

/// The tighter of a parent's eq. 4 sphere lowered by eq. 11 and the sphere around its two
/// children (what a lazy node settles on once its children are final).
#[inline]
pub fn parent_sphere(centre: Vec3, radius: f32, kids: [(Vec3, f32); 2]) -> (Vec3, f32) {
    let r = radius.min(radius_from_children(centre, kids));
    let around = sphere_around(kids[0], kids[1]);
    if around.1 < r {
        around
    } else {
        (centre, r)
    }
}

/// The hierarchy of one step.
pub enum Accel {
    /// The model's hierarchy, spheres filled on first touch.
    Lazy(Vec<LazyNode>),
    /// Every sphere known before tracing (eager refit on the model's topology, or a rebuilt
    /// tree); leaves carry their surfel's deformed sphere.
    Fixed(Vec<TreeNode>),
}

/// A step prepared for tracing.
pub struct PreparedSurfels {
    pub model: Arc<SurfelModel>,
    pub u: Arc<[Vec3]>,
    pub g: Arc<[Mat3]>,
    pub step: StepFrame,
    pub surfels: Vec<OnceLock<DeformedSurfel>>,
    pub accel: Accel,
    pub runtime: Arc<SurfelRuntime>,
    pub options: SurfelOptions,
    /// The mode this step actually used (never `Auto`).
    pub used: UpdateMode,
    /// The root's eq. 9 bound over its rest radius.
    pub root_growth: f32,
    /// This step's widening of the model's normal cones, where shadow rays from outside may
    /// skip nodes by them: closed objects traced on the model's own hierarchy (lazy or eager;
    /// a rebuilt tree has other nodes).
    pub cull: Option<Widening>,
    build_ms: f64,
    id: u64,
}

impl std::fmt::Debug for PreparedSurfels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PreparedSurfels")
            .field("surfels", &self.surfels.len())
            .field("used", &self.used)
            .field("root_growth", &self.root_growth)
            .finish_non_exhaustive()
    }
}

impl PreparedSurfels {
    pub fn new(scene: SurfelScene) -> PreparedSurfels {
        let start = Instant::now();
        let SurfelScene {
            model,
            displacement: u,
            gradient: g,
            options,
            runtime,
        } = scene;
        let step = StepFrame::new(&model, &u, &g);
        let root_growth = if model.tree.nodes[0].is_leaf() {
            1.0
        } else {
            node_sphere(&model, &step, 0).1 / model.tree.nodes[0].radius.max(1e-20)
        };
        let (g_max, u_max) = step.extremes();
        let loose = !(g_max <= LOOSE_GRADIENT && u_max <= LOOSE_MOVE * model.tree.nodes[0].radius);
        let used = if loose {
            UpdateMode::Rebuild
        } else {
            match options.mode {
                UpdateMode::Auto if runtime.touched_share() > EAGER_SHARE => UpdateMode::Eager,
                UpdateMode::Auto => UpdateMode::Lazy,
                m @ (UpdateMode::Lazy | UpdateMode::Eager | UpdateMode::Rebuild) => m,
            }
        };
        let mut p = PreparedSurfels {
            surfels: (0..model.len()).map(|_| OnceLock::new()).collect(),
            accel: Accel::Fixed(Vec::new()),
            model,
            u,
            g,
            step,
            runtime,
            options,
            used,
            root_growth,
            cull: None,
            build_ms: 0.0,
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
        };
        p.accel = match used {
            UpdateMode::Lazy | UpdateMode::Auto => Accel::Lazy(
                (p.model.tree.nodes.iter())
                    .map(|n| LazyNode::new(n.kids))
                    .collect(),
            ),
            UpdateMode::Eager => Accel::Fixed(p.eager_refit()),
            UpdateMode::Rebuild => Accel::Fixed(p.rebuild()),
        };
        if !p.model.cones.cone.is_empty() && matches!(used, UpdateMode::Lazy | UpdateMode::Eager) {
            let rotation = p.step.frames.iter().map(|f| f.rotation).collect();
            p.cull = Some(Widening::new(rotation, &p.step.own.g_norm, &p.model.cones));
        }
        p.build_ms = start.elapsed().as_secs_f64() * 1e3;
        p
    }

    /// Node `n`'s normal cone this step and its body: `(axis, sin, body)` such that a unit
    /// direction `d` with `axis · d > sin` meets only hits below `n` that face away from it
    /// ([`crate::kinds::surfels::cones`]); `None` where nothing is known.
    #[inline]
    pub fn cone(&self, n: u32) -> Option<(Vec3, f32, u16)> {
        let cones = &self.model.cones;
        let (axis, sin) = self.cull.as_ref()?.cone(cones, n as usize)?;
        Some((axis, sin, cones.body[n as usize]))
    }

    /// The body a ray starting at `start` starts outside of, where this step skips nodes by
    /// their cones ([`crate::kinds::surfels::cones`]): the body of the surfel it leaves.
    #[inline]
    pub fn outside_of(&self, start: RayStart) -> Option<u16> {
        match start {
            RayStart::Leaving(s) if self.cull.is_some() => {
                let body = *self.model.cones.surfel_body.get(s as usize)?;
                (body != MIXED).then_some(body)
            }
            _ => None,
        }
    }

    pub fn build_ms(&self) -> f64 {
        self.build_ms
    }

    /// A number no other prepared step of this process has (what the GPU backend keys its
    /// uploaded arrays by: an address can be reused once a step is dropped, this cannot).
    pub fn id(&self) -> u64 {
        self.id
    }

    /// Every sphere of this step up to date, leaves carrying their deformed surfels' spheres:
    /// the tree an eager or rebuilt step traces, or for a lazy step the eager refit of the
    /// model's tree (every surfel by eq. 1, every sphere fitted to the surfels below it).
    /// The GPU backend uploads this (it does no lazy updates); every radius, like every
    /// radius the lazy path uses, holds every surfel disc below it, so a lazy trace and a
    /// trace of these spheres find the same hits.
    pub fn eager_spheres(&self) -> Cow<'_, [TreeNode]> {
        match &self.accel {
            Accel::Fixed(nodes) => Cow::Borrowed(nodes),
            Accel::Lazy(_) => Cow::Owned(self.eager_refit()),
        }
    }

    /// Surfel `s` deformed (eq. 1), computed on first use; `fresh` is set if this call
    /// computed it.
    #[inline]
    pub fn surfel(&self, s: usize, fresh: &mut bool) -> &DeformedSurfel {
        self.surfels[s].get_or_init(|| {
            *fresh = true;
            deform_surfel(&self.model, &self.u, &self.g, s)
        })
    }

    fn deform_all(&self) {
        self.surfels.par_iter().enumerate().for_each(|(s, slot)| {
            slot.get_or_init(|| deform_surfel(&self.model, &self.u, &self.g, s));
        });
    }

    /// Every surfel by eq. 1, then every sphere of the model's tree refitted to the deformed
    /// surfels below it: centred on the box around their leaf spheres, its radius the farthest
    /// leaf sphere's reach from there (exact, not a bound of bounds), or the sphere around its
    /// two children where that is smaller. A sphere of spheres loses a little at every level
    /// (on `surfel-impact`, 64 sphere tests a ray with eqs. 4, 9 and 11 against 47 with every
    /// node's smallest enclosing sphere); this costs one pass over the leaves per level.
    fn eager_refit(&self) -> Vec<TreeNode> {
        self.deform_all();
        let tree = &self.model.tree;
        let deformed = |s: u32| {
            let mut fresh = false;
            let d = self.surfel(s as usize, &mut fresh);
            (d.centre, d.leaf_radius)
        };
        let mut leaves = LeafSpheres {
            x: Vec::with_capacity(tree.leaves.len()),
            y: Vec::with_capacity(tree.leaves.len()),
            z: Vec::with_capacity(tree.leaves.len()),
            r: Vec::with_capacity(tree.leaves.len()),
        };
        for &s in &tree.leaves {
            let (c, r) = deformed(s);
            leaves.x.push(c.x);
            leaves.y.push(c.y);
            leaves.z.push(c.z);
            leaves.r.push(r);
        }
        // Boxes around the leaf spheres, bottom-up (preorder: reverse order is bottom-up).
        let mut boxes = vec![(Vec3::ZERO, Vec3::ZERO); tree.nodes.len()];
        for (i, n) in tree.nodes.iter().enumerate().rev() {
            boxes[i] = if n.is_leaf() {
                let j = tree.leaf_range[i][0] as usize;
                let (c, r) = (
                    Vec3::new(leaves.x[j], leaves.y[j], leaves.z[j]),
                    leaves.r[j],
                );
                (c - Vec3::splat(r), c + Vec3::splat(r))
            } else {
                let [a, b] = n.kids.map(|k| boxes[k as usize]);
                (a.0.min(b.0), a.1.max(b.1))
            };
        }
        let mut nodes: Vec<TreeNode> = (tree.nodes.par_iter().enumerate())
            .map(|(i, n)| {
                let (centre, radius) = if n.is_leaf() {
                    deformed(n.kids[1])
                } else {
                    // Two centres, the reach of the surfels below from each: eq. 4's (the
                    // rest sphere's centre carried by the deformation, near the best for a
                    // curved sheet of surfels) and the middle of their box.
                    let [a, b] = tree.leaf_range[i].map(|v| v as usize);
                    let moved = node_centre(&self.model, &self.step, i);
                    let middle = 0.5 * (boxes[i].0 + boxes[i].1);
                    let (r4, rm) = (
                        leaves.radius_about(moved, a..b),
                        leaves.radius_about(middle, a..b),
                    );
                    if r4 <= rm {
                        (moved, r4)
                    } else {
                        (middle, rm)
                    }
                };
                TreeNode {
                    centre,
                    radius,
                    kids: n.kids,
                }
            })
            .collect();
        for i in (0..nodes.len()).rev() {
            let n = nodes[i];
            if !n.is_leaf() {
                let kid = |k: u32| (nodes[k as usize].centre, nodes[k as usize].radius);
                let around = sphere_around(kid(n.kids[0]), kid(n.kids[1]));
                if around.1 < n.radius {
                    (nodes[i].centre, nodes[i].radius) = around;
                }
            }
        }
        nodes
    }

    /// A new hierarchy over the deformed surfels (§4.1.1 on each step).
    fn rebuild(&self) -> Vec<TreeNode> {
        self.deform_all();
        let (centres, radii): (Vec<Vec3>, Vec<f32>) = self
            .surfels
            .iter()
            .map(|s| {
                s.get()
                    .map_or((Vec3::ZERO, 0.0), |d| (d.centre, d.leaf_radius))
            })
            .unzip();
        SphereTree::build(&centres, &radii, None).nodes
    }

    /// Surfels this step has deformed so far.
    pub fn touched_surfels(&self) -> usize {
        self.surfels.iter().filter(|s| s.get().is_some()).count()
    }

    /// The spheres this step has updated so far (for tightness measurements): per tree node,
    /// the radius in use, or `None` if not updated.
    pub fn current_spheres(&self) -> Vec<Option<(Vec3, f32)>> {
        match &self.accel {
            Accel::Lazy(nodes) => (nodes.iter().zip(&self.model.tree.nodes))
                .map(|(lazy, n)| {
                    if n.is_leaf() {
                        return self.surfels[n.kids[1] as usize]
                            .get()
                            .map(|d| (d.centre, d.leaf_radius));
                    }
                    lazy.get()
                })
                .collect(),
            Accel::Fixed(nodes) => nodes.iter().map(|n| Some((n.centre, n.radius))).collect(),
        }
    }
}

impl Drop for PreparedSurfels {
    /// Leaves the share of surfels a lazy step touched for the next step's heuristic (auto
    /// mode only).
    fn drop(&mut self) {
        if self.surfels.is_empty() || self.options.mode != UpdateMode::Auto {
            return;
        }
        match self.used {
            UpdateMode::Lazy | UpdateMode::Auto => {
                let share = self.touched_surfels() as f32 / self.surfels.len() as f32;
                self.runtime.set_touched_share(share);
            }
            // An eager step measures nothing; the share decays so that a lazy step soon
            // measures again.
            UpdateMode::Eager | UpdateMode::Rebuild => {
                let share = self.runtime.touched_share() * 0.9;
                self.runtime.set_touched_share(share);
            }
        }
    }
}
