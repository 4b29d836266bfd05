//! The undeformed object of deforming-point-sampled-surfaces.txt §3 and §4.4
//! ("Precomputation"): surfels embedded in simulation nodes, their fixed neighbourhoods,
//! clipping neighbours and the bounding-sphere hierarchy, all built once and shared by every
//! step through an `Arc`.
//!
//! How it works: each surfel takes its `EMBED_NODES` nearest simulation nodes with the
//! weights of eq. 2 (support `h` = 1.5 × the distance to the farthest of them, normalised to
//! sum to 1); its MLS neighbourhood (§4.2.1) is itself and the 15 nearest surfels of its own
//! group (surface), with support the distance to the farthest; a surfel of a group that is
//! clipped by another group (§4.3) stores the two nearest surfels of that group. The
//! hierarchy is [`crate::kinds::surfels::tree::SphereTree`].

use crate::geom::frame::LocalFrame;
use crate::kinds::surfels::cones::{self, Cones};
use crate::kinds::surfels::kernel::{sigma_max, weight, Rows};
use crate::kinds::surfels::knn::Grid;
use crate::kinds::surfels::tree::{leaf_order, surfel_bodies, SphereTree};
use glam::Vec3;
use rayon::prelude::*;

/// Simulation nodes each surfel is embedded in (eq. 1's sum).
pub const EMBED_NODES: usize = 8;
/// Surfels in a fixed MLS neighbourhood, the surfel itself included (the paper uses 16).
pub const NEIGHBOURS: usize = 16;

/// One surface element: an elliptical disc `centre + a·t1 + b·t2`, `a² + b² ≤ radius²`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surfel {
    pub centre: Vec3,
    /// The two tangent axes (any length, not parallel).
    pub t1: Vec3,
    pub t2: Vec3,
    /// The outward normal; its side of the tangent plane orients the deformed normal.
    pub normal: Vec3,
    /// Linear-light colour.
    pub colour: Vec3,
    pub radius: f32,
    /// The surface this surfel belongs to (clipping relations are between groups).
    pub group: u16,
}

/// The data an object is made from, checked by [`SurfelModel::new`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfelSet {
    pub surfels: Vec<Surfel>,
    /// Rest positions of the simulation nodes.
    pub nodes: Vec<Vec3>,
    /// Masses of the nodes (for the optimal rigid transform, §4.1.3); empty means all 1.
    pub node_mass: Vec<f32>,
    /// `(a, b)`: surfels of group `a` are clipped by the surface of group `b` (§4.3).
    pub clip: Vec<(u16, u16)>,
    /// The body each node belongs to (empty: one body). Each body gets its own optimal
    /// rigid frame (the per-set transforms of §6), so separately moving objects keep tight
    /// spheres.
    pub node_body: Vec<u16>,
    /// Every body is a closed surface with outward normals, the bodies apart: then a shadow
    /// ray from outside skips the nodes whose hits all face away from it
    /// ([`crate::kinds::surfels::cones`]). Off for sheets, scans and anything not known to be
    /// closed (a wrong `true` lets light through where a ray would cross a body's back).
    pub closed: bool,
}

/// Why surfel data was rejected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SurfelError {
    #[error("a surfel object needs at least one surfel")]
    NoSurfels,
    #[error("a surfel object needs at least one simulation node")]
    NoNodes,
    #[error("{count} surfels exceed the limit of {limit}")]
    TooMany { count: usize, limit: usize },
    #[error("{what} {index} is not finite")]
    NotFinite { what: &'static str, index: usize },
    #[error("surfel {index} has a zero-length or parallel tangent axis")]
    DegenerateTangents { index: usize },
    #[error("surfel {index} has a normal in its tangent plane or of zero length")]
    DegenerateNormal { index: usize },
    #[error("surfel {index} has radius {radius}; it must be positive")]
    BadRadius { index: usize, radius: f32 },
    #[error("node mass {index} is {mass}; masses must be positive")]
    BadMass { index: usize, mass: f32 },
    #[error("{got} node masses for {nodes} nodes")]
    MassCount { got: usize, nodes: usize },
    #[error("{got} node bodies for {nodes} nodes")]
    BodyCount { got: usize, nodes: usize },
    #[error("a clipping relation names group {group}, which no surfel has")]
    UnknownGroup { group: u16 },
    #[error("a step has {got} {what} for {nodes} simulation nodes")]
    StepCount {
        what: &'static str,
        got: usize,
        nodes: usize,
    },
    #[error("node {index}'s {what} is not finite")]
    StepNotFinite { what: &'static str, index: usize },
}

/// The undeformed object, everything precomputed (§4.4).
#[derive(Debug)]
pub struct SurfelModel {
    /// The set's surfels in the hierarchy's leaf order ([`leaf_order`]), not as given.
    pub surfels: Vec<Surfel>,
    pub nodes: Vec<Vec3>,
    pub node_mass: Vec<f32>,
    pub node_body: Vec<u16>,
    /// Number of bodies.
    pub bodies: u16,
    /// Per surfel: `(node, normalised weight of eq. 2)`.
    pub embed: Rows<(u32, f32)>,
    /// Per surfel: its fixed MLS neighbourhood (itself first).
    pub neighbours: Rows<u32>,
    /// Per surfel: the support radius `h` of its MLS weights.
    pub support: Vec<f32>,
    /// Per surfel: pairs of nearest surfels of each surface clipping it.
    pub clip: Rows<[u32; 2]>,
    /// Per surfel: `σ_max([t1 t2]) · radius`, the rest radius of its leaf sphere.
    pub leaf_radius: Vec<f32>,
    /// Whether the surfel's normal lies on the `t1 × t2` side.
    pub orient: Vec<f32>,
    pub tree: SphereTree,
    pub groups: u16,
    /// Per hierarchy node, the normal cone of its hits ([`SurfelSet::closed`] objects only;
    /// empty otherwise).
    pub cones: Cones,
}

impl SurfelModel {
    /// Checks `set` and precomputes everything tracing needs (§4.4 "Precomputation").
    pub fn new(set: SurfelSet, limit: usize) -> Result<SurfelModel, SurfelError> {
        check(&set, limit)?;
        let SurfelSet {
            surfels,
            nodes,
            mut node_mass,
            clip,
            mut node_body,
            closed,
        } = set;
        if node_mass.is_empty() {
            node_mass = vec![1.0; nodes.len()];
        }
        if node_body.is_empty() {
            node_body = vec![0; nodes.len()];
        }
        // In the hierarchy's leaf order: a sphere's surfels, their neighbours and their
        // deformed copies then share cache lines.
        // (A surfel's embedding row depends on its centre alone, so it is permuted with it.)
        let (surfels, embed) = {
            let centres: Vec<Vec3> = surfels.iter().map(|s| s.centre).collect();
            let embed = embed_rows(&centres, &nodes);
            let body = surfel_bodies((&embed, &nodes, &node_body));
            let order = leaf_order(&centres, &body);
            (
                order
                    .iter()
                    .map(|&i| surfels[i as usize])
                    .collect::<Vec<_>>(),
                Rows::from_rows(order.iter().map(|&i| embed.row(i as usize).to_vec())),
            )
        };
        let centres: Vec<Vec3> = surfels.iter().map(|s| s.centre).collect();
        let by_group = ByGroup::new(&surfels);
        let grids = by_group.grids();
        let (neighbours, support) = neighbour_rows(&surfels, &by_group, &grids);
        let clip = clip_rows(&surfels, &clip, &by_group, &grids);
        let leaf_radius: Vec<f32> = surfels
            .iter()
            .map(|s| sigma_max(s.t1, s.t2) * s.radius)
            .collect();
        let orient: Vec<f32> = surfels
            .iter()
            .map(|s| s.normal.dot(s.t1.cross(s.t2)).signum())
            .collect();
        let tree = SphereTree::build(&centres, &leaf_radius, Some((&embed, &nodes, &node_body)));
        let bodies = node_body.iter().copied().max().unwrap_or(0) + 1;
        let cones = if closed {
            let normals: Vec<glam::DVec3> = (surfels.iter().zip(&orient))
                .map(|(s, &o)| {
                    (s.t1.as_dvec3().cross(s.t2.as_dvec3()) * o as f64).normalize_or_zero()
                })
                .collect();
            cones::build(&normals, &neighbours, (&embed, &node_body), &tree)
        } else {
            Cones::default()
        };
        Ok(SurfelModel {
            cones,
            surfels,
            nodes,
            node_mass,
            node_body,
            bodies,
            embed,
            neighbours,
            support,
            clip,
            leaf_radius,
            orient,
            tree,
            groups: (by_group.members.len() as u16).max(1),
        })
    }

    /// The same object moved into `frame` (surfel centres, simulation nodes and the
    /// hierarchy's sphere centres, in `f64`; everything else is translation-invariant).
    /// O(surfels): only a state far from the origin pays it (see [`LocalFrame`]).
    pub fn in_frame(&self, frame: &LocalFrame) -> SurfelModel {
        let mut surfels = self.surfels.clone();
        for s in &mut surfels {
            s.centre = frame.local_from_world(s.centre);
        }
        let mut tree = self.tree.clone();
        for n in &mut tree.nodes {
            n.centre = frame.local_from_world(n.centre);
        }
        SurfelModel {
            surfels,
            nodes: self
                .nodes
                .iter()
                .map(|&p| frame.local_from_world(p))
                .collect(),
            node_mass: self.node_mass.clone(),
            node_body: self.node_body.clone(),
            bodies: self.bodies,
            embed: self.embed.clone(),
            neighbours: self.neighbours.clone(),
            support: self.support.clone(),
            clip: self.clip.clone(),
            leaf_radius: self.leaf_radius.clone(),
            orient: self.orient.clone(),
            tree,
            groups: self.groups,
            cones: self.cones.clone(),
        }
    }

    pub fn len(&self) -> usize {
        self.surfels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.surfels.is_empty()
    }
}

fn check(set: &SurfelSet, limit: usize) -> Result<(), SurfelError> {
    if set.surfels.is_empty() {
        return Err(SurfelError::NoSurfels);
    }
    if set.nodes.is_empty() {
        return Err(SurfelError::NoNodes);
    }
    if set.surfels.len() > limit {
        return Err(SurfelError::TooMany {
            count: set.surfels.len(),
            limit,
        });
    }
    for (index, s) in set.surfels.iter().enumerate() {
        let finite = s.centre.is_finite()
            && s.t1.is_finite()
            && s.t2.is_finite()
            && s.normal.is_finite()
            && s.colour.is_finite()
            && s.radius.is_finite();
        if !finite {
            return Err(SurfelError::NotFinite {
                what: "surfel",
                index,
            });
        }
        let cross = s.t1.cross(s.t2);
        let scale = s.t1.length() * s.t2.length();
        if !(scale > 0.0) || cross.length() <= 1e-6 * scale {
            return Err(SurfelError::DegenerateTangents { index });
        }
        let n = s.normal.length();
        if !(n > 0.0) || s.normal.dot(cross).abs() <= 1e-6 * n * cross.length() {
            return Err(SurfelError::DegenerateNormal { index });
        }
        if !(s.radius > 0.0) {
            return Err(SurfelError::BadRadius {
                index,
                radius: s.radius,
            });
        }
    }
    for (index, p) in set.nodes.iter().enumerate() {
        if !p.is_finite() {
            return Err(SurfelError::NotFinite {
                what: "node",
                index,
            });
        }
    }
    if !set.node_mass.is_empty() && set.node_mass.len() != set.nodes.len() {
        return Err(SurfelError::MassCount {
            got: set.node_mass.len(),
            nodes: set.nodes.len(),
        });
    }
    if !set.node_body.is_empty() && set.node_body.len() != set.nodes.len() {
        return Err(SurfelError::BodyCount {
            got: set.node_body.len(),
            nodes: set.nodes.len(),
        });
    }
    for (index, &mass) in set.node_mass.iter().enumerate() {
        if !(mass > 0.0 && mass.is_finite()) {
            return Err(SurfelError::BadMass { index, mass });
        }
    }
    let groups = set.surfels.iter().map(|s| s.group).max().unwrap_or(0);
    for &(a, b) in &set.clip {
        for group in [a, b] {
            if group > groups || !set.surfels.iter().any(|s| s.group == group) {
                return Err(SurfelError::UnknownGroup { group });
            }
        }
    }
    Ok(())
}

fn embed_rows(centres: &[Vec3], nodes: &[Vec3]) -> Rows<(u32, f32)> {
    let grid = Grid::new(nodes);
    let k = EMBED_NODES.min(nodes.len());
    let rows: Vec<Vec<(u32, f32)>> = centres
        .par_iter()
        .map_init(Vec::new, |near, &c| {
            grid.nearest(c, k, None, near);
            let far = near.last().map_or(0.0, |n| n.1.sqrt());
            let h = 1.5 * far + 1e-6;
            let mut row: Vec<(u32, f32)> = near
                .iter()
                .map(|&(j, d2)| (j, weight(d2.sqrt() / h)))
                .collect();
            let sum: f32 = row.iter().map(|r| r.1).sum();
            for r in &mut row {
                r.1 /= sum;
            }
            row
        })
        .collect();
    Rows::from_rows(rows)
}

/// The surfels of each group (surface) and their centres, and each surfel's index within its
/// group: what the per-surface neighbour searches ([`neighbour_rows`], [`clip_rows`]) run on.
struct ByGroup {
    members: Vec<Vec<u32>>,
    points: Vec<Vec<Vec3>>,
    local: Vec<u32>,
}

impl ByGroup {
    fn new(surfels: &[Surfel]) -> ByGroup {
        let groups = surfels
            .iter()
            .map(|s| s.group as usize + 1)
            .max()
            .unwrap_or(0);
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); groups];
        let mut local = vec![0u32; surfels.len()];
        for (i, s) in surfels.iter().enumerate() {
            let m = &mut members[s.group as usize];
            local[i] = m.len() as u32;
            m.push(i as u32);
        }
        let points = members
            .iter()
            .map(|m| m.iter().map(|&i| surfels[i as usize].centre).collect())
            .collect();
        ByGroup {
            members,
            points,
            local,
        }
    }

    /// A grid over each group's centres.
    fn grids(&self) -> Vec<Grid<'_>> {
        self.points.iter().map(|p| Grid::new(p)).collect()
    }
}

/// Each surfel's fixed MLS neighbourhood (itself and its nearest others) and support, taken
/// from its own surface (group) only: a surface that another clips is its own MLS surface
/// continued past the edge and cut there (§4.3), so a neighbourhood that reached across the
/// edge into the other surface would blend the two and round the edge it is meant to keep
/// sharp.
fn neighbour_rows(surfels: &[Surfel], by: &ByGroup, grids: &[Grid]) -> (Rows<u32>, Vec<f32>) {
    let rows: Vec<(Vec<u32>, f32)> = (0..surfels.len())
        .into_par_iter()
        .map_init(Vec::new, |near, i| {
            let g = surfels[i].group as usize;
            let k = (NEIGHBOURS - 1).min(by.members[g].len() - 1);
            grids[g].nearest(surfels[i].centre, k, Some(by.local[i]), near);
            let mut row = vec![i as u32];
            row.extend(near.iter().map(|n| by.members[g][n.0 as usize]));
            let h = near.last().map_or(1e-3, |n| n.1.sqrt()).max(1e-6);
            (row, h)
        })
        .collect();
    let support = rows.iter().map(|r| r.1).collect();
    (Rows::from_rows(rows.into_iter().map(|r| r.0)), support)
}

fn clip_rows(
    surfels: &[Surfel],
    relations: &[(u16, u16)],
    by: &ByGroup,
    grids: &[Grid],
) -> Rows<[u32; 2]> {
    if relations.is_empty() {
        return Rows::from_rows(surfels.iter().map(|_| Vec::new()));
    }
    let members = &by.members;
    let rows: Vec<Vec<[u32; 2]>> = surfels
        .par_iter()
        .map_init(Vec::new, |near, s| {
            let mut row = Vec::new();
            for &(a, b) in relations {
                if a != s.group || members[b as usize].is_empty() {
                    continue;
                }
                grids[b as usize].nearest(s.centre, 2, None, near);
                let first = members[b as usize][near[0].0 as usize];
                let second = near
                    .get(1)
                    .map_or(first, |n| members[b as usize][n.0 as usize]);
                row.push([first, second]);
            }
            row
        })
        .collect();
    Rows::from_rows(rows)
}
