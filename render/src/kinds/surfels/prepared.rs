//! A surfel step ready to trace: its hierarchy updated lazily, eagerly or rebuilt
//! (deforming-point-sampled-surfaces.txt §4.1.2, §4.4, §5's baseline, §6's heuristic).
//!
//! How it works: preparing a step computes only the optimal rigid frame and the per-node
//! relative terms (linear in the simulation nodes). In lazy mode every inner sphere and every
//! surfel has a once-only slot for this step, filled by whichever ray touches it first; a
//! filled value is a pure function of the step (eq. 4 and 9 for spheres, eq. 1 for surfels),
//! so it is the same whatever thread computes it, and no lock is taken. A sphere seen while
//! both its children are filled is tightened by eq. 11 and the smallest radius so far kept
//! in an atomic (`fetch_min`); which rays see the tighter radius depends on timing, but every radius in use is a
//! conservative bound, so the set of hits, and the image, do not (the traversal returns the
//! nearest hit, ties to the lower surfel).

use crate::kinds::surfels::deform::{
    deform_surfel, node_sphere, radius_from_children, DeformedSurfel, StepFrame,
};
use crate::kinds::surfels::model::SurfelModel;
use crate::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, SurfelScene, UpdateMode};
use crate::kinds::surfels::tree::{SphereTree, TreeNode};
use glam::{Mat3, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

/// A step with a node whose Jacobian relative to its body's rigid frame has a Frobenius norm
/// above this (a stretch or shear of several times), or that moved more than
/// `LOOSE_MOVE` root radii away from where its body's rigid motion puts it, falls back to a
/// rebuild: eq. 9's bounds would be too loose to prune anything (the documented fallback).
pub const LOOSE_GRADIENT: f32 = 4.0;
pub const LOOSE_MOVE: f32 = 2.0;
/// Auto mode refits eagerly when the previous step touched more than this share of surfels.
pub const EAGER_SHARE: f32 = 0.6;
/// `refined` slot not yet tightened by eq. 11.
pub const UNSET: u32 = u32::MAX;

/// The hierarchy of one step.
pub enum Accel {
    /// The model's hierarchy, spheres filled on first touch.
    Lazy {
        nodes: Vec<OnceLock<(Vec3, f32)>>,
        refined: Vec<AtomicU32>,
    },
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
    build_ms: f64,
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
            build_ms: 0.0,
        };
        p.accel = match used {
            UpdateMode::Lazy | UpdateMode::Auto => Accel::Lazy {
                nodes: (0..p.model.tree.nodes.len())
                    .map(|_| OnceLock::new())
                    .collect(),
                refined: (0..p.model.tree.nodes.len())
                    .map(|_| AtomicU32::new(UNSET))
                    .collect(),
            },
            UpdateMode::Eager => Accel::Fixed(p.eager_refit()),
            UpdateMode::Rebuild => Accel::Fixed(p.rebuild()),
        };
        p.build_ms = start.elapsed().as_secs_f64() * 1e3;
        p
    }

    pub fn build_ms(&self) -> f64 {
        self.build_ms
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

    /// Every surfel by eq. 1, every inner sphere by eqs. 4 and 9, then bottom-up eq. 11.
    fn eager_refit(&self) -> Vec<TreeNode> {
        self.deform_all();
        let tree = &self.model.tree.nodes;
        let mut nodes: Vec<TreeNode> = tree
            .par_iter()
            .enumerate()
            .map(|(i, n)| {
                let (centre, radius) = if n.is_leaf() {
                    let mut fresh = false;
                    let d = self.surfel(n.kids[1] as usize, &mut fresh);
                    (d.centre, d.leaf_radius)
                } else {
                    node_sphere(&self.model, &self.step, i)
                };
                TreeNode {
                    centre,
                    radius,
                    kids: n.kids,
                }
            })
            .collect();
        // Preorder: children come after their parent, so reverse order is bottom-up.
        for i in (0..nodes.len()).rev() {
            let n = nodes[i];
            if !n.is_leaf() {
                let kid = |k: u32| (nodes[k as usize].centre, nodes[k as usize].radius);
                let r11 = radius_from_children(n.centre, [kid(n.kids[0]), kid(n.kids[1])]);
                nodes[i].radius = n.radius.min(r11);
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
            Accel::Lazy { nodes, refined } => (0..nodes.len())
                .map(|i| {
                    let n = self.model.tree.nodes[i];
                    if n.is_leaf() {
                        return self.surfels[n.kids[1] as usize]
                            .get()
                            .map(|d| (d.centre, d.leaf_radius));
                    }
                    let (c, r) = *nodes[i].get()?;
                    let rf = refined[i].load(Ordering::Relaxed);
                    Some((c, if rf == UNSET { r } else { f32::from_bits(rf) }))
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
