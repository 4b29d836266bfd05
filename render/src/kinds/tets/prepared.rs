//! One time step of a tet scene, ready to trace.
//!
//! How it works (tetrahedral-isosurface-ray-tracing.txt §6): the step's vertices are packed
//! as 4-D points `{x, y, z, v}` (§6.2, "Tet vertices and scalars are also stored as 4D
//! points"), then the implicit BVH is either built from scratch for this step
//! ([`TimeScheme::Rebuild`], Schema I, §6.1) or taken from the mesh's shared BVH and refitted
//! to this step's positions and scalars ([`TimeScheme::Refit`], Schema II, §6.2). With static
//! vertices the refit equals the rebuild node for node; with moving vertices it keeps the
//! rest pose's structure and may trace slower. Smoothed normals (optional) interpolate
//! per-vertex gradients, the volume-weighted mean of the incident tets' gradients; faceted
//! normals use the hit tet's own gradient (the "per-tet gradients" of §8.6).

use crate::geom::frame::LocalFrame;
use crate::kinds::tets::bvh::{BuildKind, Bvh};
use crate::kinds::tets::counters::TetCounters;
use crate::kinds::tets::march::{barycentric, gradient};
use crate::kinds::tets::mesh::{TetMesh, TetScene, Topology};
use crate::kinds::tets::packet::{self, PacketScratch, RayPacket};
use crate::kinds::tets::traverse::{self, TetHit, TetQuery};
use crate::ray::{Hit, Ray};
use glam::{Vec3, Vec4};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// How a step gets its BVH (§6).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TimeScheme {
    /// Schema I: a BVH built for every step.
    Rebuild,
    /// Schema II: one BVH per mesh, refitted for every step.
    Refit,
}

/// How hit normals are computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Normals {
    /// The hit tet's gradient: flat facets.
    Faceted,
    /// Per-vertex gradients interpolated across the tet.
    Smooth,
}

/// Every switch of preparing a tet step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TetOptions {
    pub build: BuildKind,
    pub time: TimeScheme,
    pub normals: Normals,
}

impl Default for TetOptions {
    /// The paper's defaults (BIH-style build, §8.1) with a shared, refitted BVH, and smooth
    /// normals.
    fn default() -> TetOptions {
        TetOptions {
            build: BuildKind::Bih,
            time: TimeScheme::Refit,
            normals: Normals::Smooth,
        }
    }
}

/// A tet step ready to trace.
#[derive(Debug)]
pub struct PreparedTets {
    scene: TetScene,
    verts: Vec<Vec4>,
    bvh: Bvh,
    vertex_gradients: Option<Vec<Vec3>>,
    options: TetOptions,
    rebuilt: bool,
    build_ms: f64,
    shading_ms: f64,
}

impl PreparedTets {
    pub fn new(scene: TetScene, options: TetOptions) -> PreparedTets {
        PreparedTets::new_in_frame(scene, options, &LocalFrame::WORLD)
    }

    /// [`PreparedTets::new`] with the step's vertices moved into `frame` (in `f64`, as they
    /// become the 4-D vertices every query reads; the shared BVH is refitted to them).
    pub fn new_in_frame(scene: TetScene, options: TetOptions, frame: &LocalFrame) -> PreparedTets {
        let started = Instant::now();
        let verts: Vec<Vec4> = scene
            .positions()
            .par_iter()
            .with_min_len(4096)
            .zip(scene.scalars().par_iter())
            .map(|(p, &s)| frame.local_from_world(*p).extend(s))
            .collect();
        let (bvh, rebuilt) = match options.time {
            TimeScheme::Rebuild => (
                Bvh::build_for(scene.mesh().tets(), &verts, options.build),
                true,
            ),
            TimeScheme::Refit if scene.deforms() => {
                refit_or_rebuild(scene.mesh(), &verts, options.build)
            }
            TimeScheme::Refit => (scene.mesh().shared_bvh(options.build).refit(&verts), false),
        };
        let build_ms = started.elapsed().as_secs_f64() * 1e3;
        let started = Instant::now();
        let vertex_gradients = match options.normals {
            Normals::Faceted => None,
            Normals::Smooth => Some(vertex_gradients(scene.mesh(), &verts)),
        };
        PreparedTets {
            scene,
            verts,
            bvh,
            vertex_gradients,
            options,
            rebuilt,
            build_ms,
            shading_ms: started.elapsed().as_secs_f64() * 1e3,
        }
    }

    /// Whether this step's tree was built for it (Schema I, or a deforming step whose refit
    /// degraded past [`REFIT_DEGRADATION`]) rather than refitted.
    pub fn rebuilt(&self) -> bool {
        self.rebuilt
    }

    pub fn scene(&self) -> &TetScene {
        &self.scene
    }

    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    pub fn vertices(&self) -> &[Vec4] {
        &self.verts
    }

    /// The per-vertex gradients smooth normals interpolate (`None`: faceted normals).
    pub fn vertex_gradients(&self) -> Option<&[Vec3]> {
        self.vertex_gradients.as_deref()
    }

    pub fn options(&self) -> TetOptions {
        self.options
    }

    /// Milliseconds spent on the BVH of this step (a build, or a refit plus, the first time,
    /// the shared build) and on its vertex gradients.
    pub fn build_ms(&self) -> f64 {
        self.build_ms
    }

    pub fn shading_ms(&self) -> f64 {
        self.shading_ms
    }

    /// Bytes this step holds beyond the mesh: 4-D vertices, nodes, gradients, and the leaf
    /// order unless it is shared with the mesh's BVH.
    pub fn step_bytes(&self) -> usize {
        let stats = self.bvh.stats();
        let order = match self.options.time {
            TimeScheme::Rebuild => stats.order_bytes,
            TimeScheme::Refit => 0,
        };
        self.verts.len() * std::mem::size_of::<Vec4>()
            + stats.node_bytes
            + order
            + self
                .vertex_gradients
                .as_ref()
                .map_or(0, |g| g.len() * std::mem::size_of::<Vec3>())
    }

    /// The nearest hit along `ray` within `[t_min, t_max]`.
    pub fn first_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        q: &TetQuery,
        counters: &mut TetCounters,
    ) -> Option<TetHit> {
        traverse::trace::<false>(&self.bvh, &self.verts, ray, t_min, t_max, q, counters)
    }

    /// Some hit along `ray` within `[t_min, t_max]`, not necessarily the nearest (shadow
    /// rays): traversal stops at the first one found.
    pub fn any_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        q: &TetQuery,
        counters: &mut TetCounters,
    ) -> Option<TetHit> {
        traverse::trace::<true>(&self.bvh, &self.verts, ray, t_min, t_max, q, counters)
    }

    /// [`PreparedTets::first_hit`] for every ray of a packet (same answers, less work).
    #[allow(clippy::too_many_arguments)]
    pub fn first_hits_packet(
        &self,
        packet: &RayPacket<'_>,
        t_min: f32,
        t_max: f32,
        q: &TetQuery,
        scratch: &mut PacketScratch,
        out: &mut [Option<TetHit>],
        counters: &mut TetCounters,
    ) {
        packet::first_hits(
            &self.bvh,
            &self.verts,
            packet,
            t_min,
            t_max,
            q,
            scratch,
            out,
            counters,
        );
    }

    /// Position, normal and colour of a hit. The normal points out of the solid `f > v`
    /// (towards lower values, as for metaballs); shading turns it towards the viewer.
    pub fn hit_record(&self, ray: &Ray, hit: &TetHit, q: &TetQuery) -> Hit {
        let ids = self.scene.mesh().tets()[hit.tet as usize];
        let corners = ids.map(|v| self.verts[v as usize]);
        let position = ray.at(hit.t);
        let facet = gradient(corners).0;
        let smooth = self.vertex_gradients.as_ref().map(|g| {
            let l = barycentric(corners, position);
            (0..4).fold(Vec3::ZERO, |n, i| n + l[i] * g[ids[i] as usize])
        });
        let gradient = match smooth {
            Some(n) if n.length_squared() > 1e-12 * facet.length_squared() => n,
            _ => facet,
        };
        let isovalue = q
            .isovalues()
            .get(hit.surface as usize)
            .copied()
            .unwrap_or(f32::NAN);
        Hit {
            t: hit.t,
            position,
            normal: (-gradient).normalize_or(-ray.dir),
            albedo: self.scene.color_of(isovalue),
            primitive: hit.tet,
        }
    }
}

/// A deforming step's refitted tree may cost at most this many times what its structure cost
/// when it was built ([`Bvh::area_cost`]: summed node surface areas over the root's, scale-
/// free); past it the step builds a tree of its own, which later steps refit instead.
/// Refitting keeps the structure of the pose it was built for (§6.2); under "extreme
/// geometric deformation" the boxes of a refitted tree swell and overlap, and the surface-
/// area cost counts exactly that (the expected nodes a ray visits). 1.5 lets ordinary FE
/// deformation refit for ever (a uniform scale or a rigid move leaves the cost unchanged; the
/// test's twist of a quarter turn raises it by about 10 %) and rebuilds long before a
/// refitted tree traces at half speed.
pub const REFIT_DEGRADATION: f64 = 1.5;

/// §6.2 for a deforming step: refit the structure the previous steps used (the rest pose's,
/// or the last rebuilt); if the refit costs more than [`REFIT_DEGRADATION`] times what that
/// structure cost when built, build a tree for this step and make it the one to refit. Either
/// tree gives the same hits (the traversal's invariant), so which one a step gets when steps
/// are prepared concurrently changes work, never the image.
fn refit_or_rebuild(mesh: &TetMesh, verts: &[Vec4], kind: BuildKind) -> (Bvh, bool) {
    let topology = mesh.moving_topology(kind);
    let refitted = topology.bvh.refit(verts);
    if refitted.area_cost() <= REFIT_DEGRADATION * topology.built_cost {
        return (refitted, false);
    }
    let fresh = Bvh::build_for(mesh.tets(), verts, kind);
    mesh.set_moving_topology(
        kind,
        Topology {
            built_cost: fresh.area_cost(),
            bvh: Arc::new(fresh.clone()),
        },
    );
    (fresh, true)
}

/// Per vertex, the volume-weighted mean gradient of the tets around it: the tets' gradients
/// in parallel, then each vertex gathers its own (in a fixed order: deterministic).
fn vertex_gradients(mesh: &TetMesh, verts: &[Vec4]) -> Vec<Vec3> {
    let per_tet: Vec<(Vec3, f32)> = mesh
        .tets()
        .par_iter()
        .with_min_len(4096)
        .map(|ids| {
            let (g, det) = gradient(ids.map(|v| verts[v as usize]));
            if g.is_finite() {
                (g * det.abs(), det.abs())
            } else {
                (Vec3::ZERO, 0.0)
            }
        })
        .collect();
    let around = mesh.vertex_tets();
    (0..verts.len())
        .into_par_iter()
        .with_min_len(4096)
        .map(|v| {
            let (sum, weight) = around.tets[around.offsets[v]..around.offsets[v + 1]]
                .iter()
                .fold((Vec3::ZERO, 0.0f32), |(s, w), &t| {
                    let (g, tw) = per_tet[t as usize];
                    (s + g, w + tw)
                });
            if weight > 0.0 {
                sum / weight
            } else {
                sum
            }
        })
        .collect()
}
