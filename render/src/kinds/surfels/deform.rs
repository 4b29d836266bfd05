//! The deformation of one step (deforming-point-sampled-surfaces.txt §3, §4.1.2–§4.1.3):
//! surfels moved by eq. 1, sphere centres by eq. 4 and radii bounded by eq. 9, all relative
//! to the optimal rigid frame of the simulation nodes.
//!
//! Conventions: a step gives each simulation node its displacement `u_j` and the Jacobian
//! `G_j = ∂u/∂x` at it, so the first-order displacement near node `j` is
//! `u_j + G_j (x − x_j)` (the paper's `∇uᵀ d`). A surfel's tangent axes move with the
//! interpolated Jacobian `I + Σ_j w_j G_j`; its normal is their cross product, on the side of
//! the rest normal.
//!
//! The rigid frame leaves eq. 1 unchanged (the weights sum to 1, so the frame cancels) but
//! shrinks the relative displacements `ũ_j = x_j + u_j − frame(x_j)` and gradients
//! `G̃_j = (I + G_j) Rᵀ − I` that eq. 9 sums, which keeps the radii tight under rotation.

use crate::kinds::surfels::kernel::{sigma_max, weight};
use crate::kinds::surfels::knn::Grid;
use crate::kinds::surfels::model::{SurfelError, SurfelModel};
use crate::kinds::surfels::rigid::RigidFrame;
use crate::kinds::surfels::tree::MIXED;
use glam::{Mat3, Vec3};

/// A bound's relative safety margin against `f32` round-off (eq. 9 is exact in reals).
const MARGIN: f32 = 1e-5;

/// A surfel after the step's deformation, with its leaf sphere's radius.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeformedSurfel {
    pub centre: Vec3,
    pub t1: Vec3,
    pub t2: Vec3,
    pub normal: Vec3,
    /// `σ_max([t1' t2']) · radius`: the leaf sphere about `centre`.
    pub leaf_radius: f32,
}

/// Checks a step's per-node arrays against the model.
pub fn check_step(model: &SurfelModel, u: &[Vec3], g: &[Mat3]) -> Result<(), SurfelError> {
    let nodes = model.nodes.len();
    if u.len() != nodes {
        return Err(SurfelError::StepCount {
            what: "displacements",
            got: u.len(),
            nodes,
        });
    }
    if g.len() != nodes {
        return Err(SurfelError::StepCount {
            what: "gradients",
            got: g.len(),
            nodes,
        });
    }
    if let Some(index) = u.iter().position(|v| !v.is_finite()) {
        return Err(SurfelError::StepNotFinite {
            what: "displacement",
            index,
        });
    }
    if let Some(index) = g.iter().position(|m| !m.is_finite()) {
        return Err(SurfelError::StepNotFinite {
            what: "gradient",
            index,
        });
    }
    Ok(())
}

/// Node data relative to one rigid frame.
#[derive(Clone, Debug, Default)]
pub struct Relative {
    pub rel_u: Vec<Vec3>,
    pub rel_g: Vec<Mat3>,
    pub g_norm: Vec<f32>,
}

/// A step's per-node data relative to the optimal rigid frames: each body's own (for
/// spheres over one body) and the whole object's (for spheres over several).
#[derive(Clone, Debug)]
pub struct StepFrame {
    pub frames: Vec<RigidFrame>,
    pub global: RigidFrame,
    /// Each node relative to its own body's frame.
    pub own: Relative,
    /// Each node relative to the global frame (empty with one body: the same as `own`).
    pub all: Relative,
}

impl StepFrame {
    pub fn new(model: &SurfelModel, u: &[Vec3], g: &[Mat3]) -> StepFrame {
        let moved: Vec<Vec3> = model.nodes.iter().zip(u).map(|(x, d)| *x + *d).collect();
        let global = RigidFrame::optimal(&model.nodes, &moved, &model.node_mass);
        let frames: Vec<RigidFrame> = if model.bodies <= 1 {
            vec![global]
        } else {
            (0..model.bodies)
                .map(|b| {
                    let ids: Vec<usize> = (0..model.nodes.len())
                        .filter(|&j| model.node_body[j] == b)
                        .collect();
                    let pick = |v: &[Vec3]| ids.iter().map(|&j| v[j]).collect::<Vec<_>>();
                    let mass: Vec<f32> = ids.iter().map(|&j| model.node_mass[j]).collect();
                    RigidFrame::optimal(&pick(&model.nodes), &pick(&moved), &mass)
                })
                .collect()
        };
        let relative = |frame_of: &dyn Fn(usize) -> RigidFrame| {
            let mut r = Relative::default();
            for j in 0..model.nodes.len() {
                let f = frame_of(j);
                r.rel_u.push(moved[j] - f.apply(model.nodes[j]));
                let gj = (Mat3::IDENTITY + g[j]) * f.rotation.transpose() - Mat3::IDENTITY;
                r.g_norm.push(frobenius(&gj));
                r.rel_g.push(gj);
            }
            r
        };
        let own = relative(&|j| frames[model.node_body[j] as usize]);
        let all = if model.bodies <= 1 {
            Relative::default()
        } else {
            relative(&|_| global)
        };
        StepFrame {
            frames,
            global,
            own,
            all,
        }
    }

    /// The largest relative Jacobian norm and relative displacement over the nodes (each in
    /// its body's frame): what says whether the hierarchy still means anything.
    pub fn extremes(&self) -> (f32, f32) {
        let g = self.own.g_norm.iter().copied().fold(0.0, f32::max);
        let u = self
            .own
            .rel_u
            .iter()
            .map(|v| v.length())
            .fold(0.0, f32::max);
        (g, u)
    }
}

#[inline]
fn frobenius(m: &Mat3) -> f32 {
    (m.x_axis.length_squared() + m.y_axis.length_squared() + m.z_axis.length_squared()).sqrt()
}

/// Eq. 1 for surfel `s`, its tangent axes and normal with it.
#[inline]
pub fn deform_surfel(model: &SurfelModel, u: &[Vec3], g: &[Mat3], s: usize) -> DeformedSurfel {
    let rest = &model.surfels[s];
    let mut disp = Vec3::ZERO;
    let mut jac = Mat3::ZERO;
    for &(j, w) in model.embed.row(s) {
        let j = j as usize;
        let gj = g[j];
        disp += w * (u[j] + gj * (rest.centre - model.nodes[j]));
        jac += gj * w;
    }
    let t1 = rest.t1 + jac * rest.t1;
    let t2 = rest.t2 + jac * rest.t2;
    let n = t1.cross(t2) * model.orient[s];
    DeformedSurfel {
        centre: rest.centre + disp,
        t1,
        t2,
        normal: n.normalize_or_zero(),
        leaf_radius: sigma_max(t1, t2) * rest.radius * (1.0 + MARGIN),
    }
}

/// Eq. 4 for inner sphere `node`: the moved centre.
#[inline]
pub fn node_centre(model: &SurfelModel, step: &StepFrame, node: usize) -> Vec3 {
    let (frame, _, uc) = centre_shift(model, step, node);
    frame.apply(model.tree.nodes[node].centre) + uc
}

/// Eq. 4 and eq. 9 for inner sphere `node`: the moved centre and the conservative radius.
#[inline]
pub fn node_sphere(model: &SurfelModel, step: &StepFrame, node: usize) -> (Vec3, f32) {
    let rest = model.tree.nodes[node];
    let (frame, rel, uc) = centre_shift(model, step, node);
    let mut grow = 0.0f32;
    for t in model.tree.terms.row(node) {
        let j = t.node as usize;
        grow += t.a * (rel.rel_u[j] - uc).length() + t.b * rel.g_norm[j];
    }
    let centre = frame.apply(rest.centre) + uc;
    (centre, grown(centre, rest.radius + grow))
}

/// The rigid frame and relative terms of `node`'s body, and eq. 4's displacement of its
/// centre relative to that frame.
#[inline]
fn centre_shift<'a>(
    model: &SurfelModel,
    step: &'a StepFrame,
    node: usize,
) -> (&'a RigidFrame, &'a Relative, Vec3) {
    let rest = model.tree.nodes[node];
    let body = model.tree.body[node];
    let (frame, rel) = if body == MIXED && model.bodies > 1 {
        (&step.global, &step.all)
    } else {
        (
            &step.frames[(body as usize).min(step.frames.len() - 1)],
            &step.own,
        )
    };
    let rot = frame.rotation;
    let mut uc = Vec3::ZERO;
    for t in model.tree.terms.row(node) {
        let j = t.node as usize;
        let d = rot * (rest.centre - model.nodes[j]);
        uc += t.wc * (rel.rel_u[j] + rel.rel_g[j] * d);
    }
    (frame, rel, uc)
}

/// Eq. 11: the parent radius from its children's updated spheres.
#[inline]
pub fn radius_from_children(centre: Vec3, kids: [(Vec3, f32); 2]) -> f32 {
    let r = kids
        .iter()
        .map(|(c, r)| (centre - *c).length() + r)
        .fold(0.0f32, f32::max);
    r * (1.0 + MARGIN)
}

/// The smallest sphere around two spheres (each given as centre and radius), grown by the
/// same relative margin as eq. 11's radius: the parent sphere eq. 11 would give if the
/// parent's centre were free to move (used when it is tighter than eq. 4's centre allows).
#[inline]
pub fn sphere_around(a: (Vec3, f32), b: (Vec3, f32)) -> (Vec3, f32) {
    let d = (b.0 - a.0).length();
    if d + b.1 <= a.1 {
        return (a.0, a.1 * (1.0 + MARGIN));
    }
    if d + a.1 <= b.1 {
        return (b.0, b.1 * (1.0 + MARGIN));
    }
    let r = 0.5 * (d + a.1 + b.1);
    let centre = a.0 + (b.0 - a.0) * ((r - a.1) / d);
    (centre, grown(centre, r))
}

/// Radius `r` about `centre` grown against rounding: by [`MARGIN`] of itself and, since the
/// centre's rounding moves it by a few ulps of its coordinates, of the centre's largest one.
#[inline]
fn grown(centre: Vec3, r: f32) -> f32 {
    r * (1.0 + MARGIN) + MARGIN * centre.abs().max_element()
}

/// Leaf spheres as structure-of-arrays: centres and radii.
pub struct LeafSpheres {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub z: Vec<f32>,
    pub r: Vec<f32>,
}

impl LeafSpheres {
    /// The radius about `centre` that holds leaf spheres `range` (`max |centre − c| + r`),
    /// grown by the same margins as [`sphere_around`] against the rounding of the distances.
    /// Branch-free over the range, so it runs across vector lanes.
    pub fn radius_about(&self, centre: Vec3, range: std::ops::Range<usize>) -> f32 {
        let (x, y, z, r) = (
            &self.x[range.clone()],
            &self.y[range.clone()],
            &self.z[range.clone()],
            &self.r[range],
        );
        const LANES: usize = 8;
        let reach = |i: usize| {
            let (dx, dy, dz) = (x[i] - centre.x, y[i] - centre.y, z[i] - centre.z);
            (dx * dx + dy * dy + dz * dz).sqrt() + r[i]
        };
        let mut most = [0.0f32; LANES];
        let whole = x.len() / LANES * LANES;
        for base in (0..whole).step_by(LANES) {
            let (x, y, z, r) = (
                &x[base..base + LANES],
                &y[base..base + LANES],
                &z[base..base + LANES],
                &r[base..base + LANES],
            );
            for lane in 0..LANES {
                let (dx, dy, dz) = (x[lane] - centre.x, y[lane] - centre.y, z[lane] - centre.z);
                let d = (dx * dx + dy * dy + dz * dz).sqrt() + r[lane];
                // Not `f32::max`: its NaN rule keeps the loop scalar.
                most[lane] = if d > most[lane] { d } else { most[lane] };
            }
        }
        for i in whole..x.len() {
            most[0] = most[0].max(reach(i));
        }
        grown(centre, most.into_iter().fold(0.0f32, f32::max))
    }
}

/// Node Jacobians estimated by least squares from full node positions: for each node, the
/// `G` minimising `Σ_k w_k ‖(u_k − u_j) − G (x_k − x_j)‖²` over its 8 nearest rest
/// neighbours with the weights of eq. 2 (regularised where the neighbours are coplanar).
pub fn gradients_by_least_squares(rest: &[Vec3], moved: &[Vec3]) -> Vec<Mat3> {
    let grid = Grid::new(rest);
    let k = 8.min(rest.len().saturating_sub(1));
    let mut near = Vec::new();
    (0..rest.len())
        .map(|j| {
            grid.nearest(rest[j], k, Some(j as u32), &mut near);
            let h = 1.5 * near.last().map_or(1.0, |n| n.1.sqrt()) + 1e-6;
            let uj = moved[j] - rest[j];
            let mut m = Mat3::ZERO;
            let mut b = Mat3::ZERO;
            for &(i, d2) in &near {
                let i = i as usize;
                let w = weight(d2.sqrt() / h);
                let d = rest[i] - rest[j];
                let du = moved[i] - rest[i] - uj;
                m += outer(d, d) * w;
                b += outer(du, d) * w;
            }
            let trace = m.x_axis.x + m.y_axis.y + m.z_axis.z;
            let reg = Mat3::from_diagonal(Vec3::splat(1e-4 * trace + 1e-12));
            let inv = (m + reg).inverse();
            if inv.is_finite() {
                b * inv
            } else {
                Mat3::ZERO
            }
        })
        .collect()
}

/// `a bᵀ`.
#[inline]
fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}
