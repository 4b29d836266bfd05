//! Normal cones: which way the hits below a hierarchy node can face, so that a ray leaving a
//! closed object passes over the nodes whose every crossing would lead out of a body.
//!
//! Why it holds: a ray that leaves the surface of a closed body outwards (the body a closed
//! surface with outward normals) starts outside it, so its first crossing of that body, if
//! any, enters it and faces the ray (`n·d < 0`). A node of that body all of whose possible
//! hits face away from the ray (`n·d > 0`) cannot hold that crossing, and the ray is blocked
//! by the body exactly when it is blocked without the node, so a shadow ray may skip it.
//! Shadow rays from lit surfels seen from outside are such rays (the caller says so:
//! `RayStart::Leaving`); nodes of other bodies, which may hold the start where bodies press
//! into each other, are not skipped. `SurfelSet::closed` says which objects qualify.
//!
//! How the bound is built: a leaf's hit normal is the normalised, non-negatively weighted sum
//! of its fixed neighbourhood's deformed normals (intersect.rs, eq. 12), so it lies in any
//! cone (under 90°) that holds theirs. A surfel's deformed normal is `cof(F) n₀`, along
//! `F⁻ᵀ n₀`, with `F = Σ wⱼ (I + Gⱼ)` (eq. 1's interpolated Jacobian, the weights
//! non-negative and summing to 1). With every node of its embedding in one body whose rigid
//! frame turns by `R` (§4.1.3), `F = (I + H) R` with `H = Σ wⱼ G̃ⱼ`, `G̃ⱼ = (I + Gⱼ) Rᵀ − I`,
//! so `‖H‖₂ ≤ h = maxⱼ ‖G̃ⱼ‖_F` and `‖(I + H)⁻ᵀ − I‖₂ ≤ h / (1 − h)`: the normal lies within
//! `asin(h / (1 − h))` of `R n₀` (for `h < ½`; beyond, nothing is skipped). Each node keeps
//! the smallest cone around its neighbourhoods' rest normals (built once, children merged),
//! its body ([`MIXED`] if several: never skipped) and an anchor that lists the simulation
//! nodes its normals depend on; each step widens the cone by its anchor's `h` and turns its
//! axis with its body's frame ([`Widening`]).

use crate::kinds::surfels::kernel::Rows;
use crate::kinds::surfels::tree::{SphereTree, MIXED};
use glam::{DVec3, Mat3, Vec3};
use rayon::prelude::*;

/// Added to every leaf cone's half-angle (radians): more than the `f32` rounding of the
/// normals, their sums and the cull's dot product.
const SLACK: f64 = 1e-4;

/// A cone of directions: `axis` and its half-angle's cosine and sine. A half-angle of 90° or
/// more holds no useful bound and is stored as `cos = -1` (never skipped).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalCone {
    pub axis: Vec3,
    pub cos: f32,
    pub sin: f32,
}

impl NormalCone {
    /// The cone that bounds nothing.
    pub const ALL: NormalCone = NormalCone {
        axis: Vec3::ZERO,
        cos: -1.0,
        sin: 0.0,
    };
}

/// Per node of the model's hierarchy: the rest cone of the normals its hits can have, the
/// body of the simulation nodes that move them ([`MIXED`] if several), and its anchor: the
/// nearest node at or above it over at least [`ANCHOR`] surfels (or the root), which lists
/// every simulation node those normals depend on, so that a step bounds their turn per anchor
/// (near a dent, not over the whole body).
#[derive(Clone, Debug, Default)]
pub struct Cones {
    pub cone: Vec<NormalCone>,
    pub body: Vec<u16>,
    pub anchor: Vec<u32>,
    /// Per anchor, the simulation nodes of the embeddings of its leaves' neighbourhoods.
    pub sims: Rows<u32>,
    /// Per surfel, the body of its embedding's simulation nodes ([`MIXED`] if several): the
    /// body a ray leaving it starts outside of.
    pub surfel_body: Vec<u16>,
}

/// Surfels below a node from which it lists its own simulation nodes (a smaller node uses its
/// anchor's, a superset): a few thousand list entries on `surfel-impact`.
const ANCHOR: u32 = 256;

/// A cone as `f64` axis and half-angle while building.
#[derive(Clone, Copy)]
struct Wide {
    axis: DVec3,
    angle: f64,
}

const HALF_PI: f64 = std::f64::consts::FRAC_PI_2;

/// The smallest cone around both (the classic merge: the larger if it holds the other, else
/// the half-angle `(φ + θ₁ + θ₂) / 2` about an axis turned from `a`'s towards `b`'s).
fn merge(a: Wide, b: Wide) -> Wide {
    if a.angle >= HALF_PI || b.angle >= HALF_PI {
        return Wide {
            axis: DVec3::ZERO,
            angle: HALF_PI,
        };
    }
    let phi = a.axis.dot(b.axis).clamp(-1.0, 1.0).acos();
    if phi + b.angle <= a.angle {
        return a;
    }
    if phi + a.angle <= b.angle {
        return b;
    }
    let angle = (phi + a.angle + b.angle) / 2.0;
    if angle >= HALF_PI || phi < 1e-12 {
        return Wide {
            axis: if angle >= HALF_PI {
                DVec3::ZERO
            } else {
                a.axis
            },
            angle: angle.min(HALF_PI),
        };
    }
    // Slerp from a's axis towards b's by `angle - a.angle`.
    let t = angle - a.angle;
    let axis = (a.axis * (phi - t).sin() + b.axis * t.sin()) / phi.sin();
    Wide {
        axis: axis.normalize_or_zero(),
        angle,
    }
}

/// The cone around unit directions `dirs` (about their normalised sum).
fn around(dirs: impl Iterator<Item = DVec3> + Clone) -> Wide {
    let axis = dirs.clone().sum::<DVec3>().normalize_or_zero();
    if axis == DVec3::ZERO {
        return Wide {
            axis,
            angle: HALF_PI,
        };
    }
    let angle = dirs
        .map(|n| n.dot(axis).clamp(-1.0, 1.0).acos())
        .fold(0.0, f64::max);
    Wide {
        axis,
        angle: angle + SLACK,
    }
}

fn same_body(a: u16, b: u16) -> u16 {
    if a == b {
        a
    } else {
        MIXED
    }
}

/// Every node's cone and body (nodes in preorder, so children come after their parent), from
/// each surfel's rest normal as eq. 1 deforms it (`normals`: unit `t1 × t2` on the outward
/// side; the given normal may lean off the tangent plane, the deformed one never does).
pub fn build(
    normals: &[DVec3],
    neighbours: &Rows<u32>,
    (embed, node_body): (&Rows<(u32, f32)>, &[u16]),
    tree: &SphereTree,
) -> Cones {
    let row_body: Vec<u16> = (0..normals.len())
        .map(|s| {
            let mut bodies = embed.row(s).iter().map(|&(j, _)| node_body[j as usize]);
            let first = bodies.next().unwrap_or(MIXED);
            bodies.fold(first, same_body)
        })
        .collect();
    let n = tree.nodes.len();
    // The leaves' cones, bodies and simulation nodes in parallel (each depends on its
    // neighbourhood alone), then the inner nodes' from their children, bottom up.
    let leaves: Vec<(Wide, u16, Vec<u32>)> = (0..n)
        .into_par_iter()
        .map(|k| {
            let node = &tree.nodes[k];
            if !node.is_leaf() {
                let none = Wide {
                    axis: DVec3::ZERO,
                    angle: HALF_PI,
                };
                return (none, MIXED, Vec::new());
            }
            let hood = neighbours.row(node.kids[1] as usize);
            let cone = around(hood.iter().map(|&j| normals[j as usize]));
            let mut bodies = hood.iter().map(|&j| row_body[j as usize]);
            let first = bodies.next().unwrap_or(MIXED);
            let mut sims: Vec<u32> = hood
                .iter()
                .flat_map(|&j| embed.row(j as usize).iter().map(|&(sim, _)| sim))
                .collect();
            sims.sort_unstable();
            sims.dedup();
            (cone, bodies.fold(first, same_body), sims)
        })
        .collect();
    let (mut wide, mut body): (Vec<Wide>, Vec<u16>) = leaves.iter().map(|l| (l.0, l.1)).unzip();
    let sims_of_leaf: Vec<Vec<u32>> = leaves.into_iter().map(|l| l.2).collect();
    for k in (0..n).rev() {
        let node = &tree.nodes[k];
        if !node.is_leaf() {
            let [a, b] = node.kids.map(|c| c as usize);
            wide[k] = merge(wide[a], wide[b]);
            body[k] = same_body(body[a], body[b]);
        }
    }
    let (anchor, sims) = anchors(tree, &sims_of_leaf, node_body.len());
    let cone = wide
        .iter()
        .map(|w| {
            if w.angle >= HALF_PI || w.axis == DVec3::ZERO {
                NormalCone::ALL
            } else {
                NormalCone {
                    axis: w.axis.as_vec3(),
                    cos: w.angle.cos() as f32,
                    sin: w.angle.sin() as f32,
                }
            }
        })
        .collect();
    Cones {
        cone,
        body,
        anchor,
        sims,
        surfel_body: row_body,
    }
}

/// Each node's anchor and each anchor's simulation nodes: the union of its leaves'
/// (`sims_of_leaf`, by leaf node). Nodes are in preorder, so a node's subtree is the span of
/// `2n − 1` slots from it (`n` its surfels) and a parent comes before its children.
fn anchors(
    tree: &SphereTree,
    sims_of_leaf: &[Vec<u32>],
    sim_nodes: usize,
) -> (Vec<u32>, Rows<u32>) {
    let mut anchor = vec![0u32; tree.nodes.len()];
    let mut rows = Vec::new();
    let mut stamp = vec![u32::MAX; sim_nodes];
    for (k, node) in tree.nodes.iter().enumerate() {
        let [a, b] = tree.leaf_range[k];
        if k == 0 || b - a >= ANCHOR {
            let id = rows.len() as u32;
            let span = &sims_of_leaf[k..k + 2 * (b - a) as usize - 1];
            let mut row = Vec::new();
            for &sim in span.iter().flatten() {
                if stamp[sim as usize] != id {
                    stamp[sim as usize] = id;
                    row.push(sim);
                }
            }
            rows.push(row);
            anchor[k] = id;
        }
        // Children too small to anchor themselves take this node's anchor (set above, or
        // inherited from its own parent earlier in preorder).
        if !node.is_leaf() {
            for c in node.kids {
                let [a, b] = tree.leaf_range[c as usize];
                if b - a < ANCHOR {
                    anchor[c as usize] = anchor[k];
                }
            }
        }
    }
    (anchor, Rows::from_rows(rows))
}

/// One step's turn of the rest cones: per body its rotation (its optimal rigid frame's,
/// §4.1.3), and per anchor the cosine and sine of `asin(h / (1 − h))` for the largest Jacobian
/// relative to its body's frame, `h = maxⱼ ‖(I + Gⱼ) Rᵀ − I‖_F` over the anchor's simulation
/// nodes, or `None` where `h ≥ ½` (nothing is skipped). With every node of a surfel's
/// embedding in body `b`, eq. 1's `F = Σ wⱼ (I + Gⱼ) = (I + H) R` with `‖H‖₂ ≤ h`, so its
/// normal, along `R (I + H)⁻ᵀ n₀`, lies within that angle of `R n₀`. Nodes over several
/// bodies skip nothing.
#[derive(Clone, Debug, Default)]
pub struct Widening {
    rotation: Vec<Mat3>,
    turn: Vec<Option<(f32, f32)>>,
}

/// Added to each anchor's largest relative Jacobian: more than its `f32` rounding.
const H_SLACK: f64 = 1e-5;

impl Widening {
    /// From the step's per-body rigid rotations and per-node `‖G̃ⱼ‖_F` (`StepFrame`'s).
    pub fn new(rotation: Vec<Mat3>, norms: &[f32], cones: &Cones) -> Widening {
        let anchors = cones.sims.start.len() - 1;
        let turn = (0..anchors)
            .map(|a| {
                let h = (cones.sims.row(a).iter())
                    .map(|&j| norms.get(j as usize).map_or(f64::NAN, |&v| v as f64))
                    .fold(0.0, |m: f64, v| {
                        if v.is_nan() || m.is_nan() {
                            f64::NAN
                        } else {
                            m.max(v)
                        }
                    });
                let h = h + H_SLACK;
                let ratio = h / (1.0 - h);
                // NaN fails both tests and skips nothing.
                (h < 0.5 && ratio < 1.0).then(|| {
                    let angle = ratio.asin();
                    (angle.cos() as f32, angle.sin() as f32)
                })
            })
            .collect();
        Widening { rotation, turn }
    }

    /// `(axis, sin)` of node `n`'s cone this step, or `None` where it bounds nothing: a unit
    /// direction `d` with `axis · d > sin` meets only hits below `n` that face away from it.
    #[inline]
    pub fn cone(&self, cones: &Cones, n: usize) -> Option<(Vec3, f32)> {
        let (c, b) = (cones.cone[n], cones.body[n]);
        if b == MIXED || c.cos <= -1.0 {
            return None;
        }
        let (cd, sd) = (*self.turn.get(cones.anchor[n] as usize)?)?;
        let rotation = *self.rotation.get(b as usize)?;
        // cos and sin of (θ + δ); a sum of 90° or more bounds nothing.
        let cos = c.cos * cd - c.sin * sd;
        (cos > 0.0).then(|| (rotation * c.axis, c.sin * cd + c.cos * sd + SIN_SLACK))
    }
}

/// Added to the cull's threshold: more than the rounding of the sums above.
const SIN_SLACK: f32 = 1e-5;
