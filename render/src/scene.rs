//! The closed set of primitive kinds, and a scene prepared for tracing.
//!
//! Preparing a state builds its acceleration structure from scratch (for metaballs the Fitted
//! BVH of fitted-bvh-metaballs.txt by default, see [`crate::metaball::tree`]; for tets the
//! implicit min–max BVH of tetrahedral-isosurface-ray-tracing.txt, see [`crate::tet`], built
//! once per mesh and refitted per step); the prepared state is then shared, read-only, by
//! every view of it.

use crate::camera::PrimaryRays;
use crate::metaball::{
    MetaballError, MetaballScene, PrepareOptions, PreparedMetaballs, RayCounters,
};
use crate::ray::{Hit, Ray};
use crate::shade::Lighting;
use crate::tet::{
    PacketScratch, PreparedTets, RayPacket, TetCounters, TetError, TetOptions, TetQuery, TetScene,
};
use std::sync::Arc;

/// One state of a scene: the primitives and how they are lit.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub geometry: Geometry,
    pub lighting: Lighting,
}

/// The primitive kinds isoray traces. New kinds are new variants, matched in this file.
#[derive(Clone, Debug, PartialEq)]
pub enum Geometry {
    Metaballs(MetaballScene),
    /// A tetrahedral mesh with one scalar field (one time step).
    Tets(TetScene),
}

/// Why scene data was rejected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    #[error(transparent)]
    Metaball(#[from] MetaballError),
    #[error(transparent)]
    Tet(#[from] TetError),
}

impl Scene {
    /// Checks the scene's data against the engine's limits.
    pub fn validate(&self, primitive_limit: usize) -> Result<(), SceneError> {
        match &self.geometry {
            Geometry::Metaballs(m) => m.validate(primitive_limit)?,
            Geometry::Tets(t) => t.validate(primitive_limit)?,
        }
        Ok(())
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        match &self.geometry {
            Geometry::Metaballs(m) => m.balls.len(),
            Geometry::Tets(t) => t.tet_count(),
        }
    }

    /// Isovalues for which the surface may exist, as an open interval.
    pub fn isovalue_range(&self) -> (f32, f32) {
        match &self.geometry {
            Geometry::Metaballs(m) => m.isovalue_range(),
            Geometry::Tets(t) => t.isovalue_range(),
        }
    }

    /// Builds what tracing needs (acceleration structures) for this state: the Fitted BVH
    /// with every optimisation, for the state's lowest isovalue, and Bézier clipping; for
    /// tets the [`TetOptions`] defaults (BIH-style build, shared BVH refitted per step).
    pub fn prepare(self: Arc<Self>) -> PreparedScene {
        match &self.geometry {
            Geometry::Metaballs(m) => {
                let options = PrepareOptions::fitted(m.min_isovalue);
                self.prepare_with(options)
            }
            Geometry::Tets(_) => self.prepare_tets_with(TetOptions::default()),
        }
    }

    /// [`Scene::prepare`] with a chosen acceleration structure and root finder (a tet scene
    /// ignores them and takes its defaults).
    pub fn prepare_with(self: Arc<Self>, options: PrepareOptions) -> PreparedScene {
        self.prepare_kind(options, TetOptions::default())
    }

    /// [`Scene::prepare`] with chosen tet options (a metaball scene ignores them and takes
    /// its defaults).
    pub fn prepare_tets_with(self: Arc<Self>, tet_options: TetOptions) -> PreparedScene {
        let options = match &self.geometry {
            Geometry::Metaballs(m) => PrepareOptions::fitted(m.min_isovalue),
            Geometry::Tets(_) => PrepareOptions::fitted(0.0),
        };
        self.prepare_kind(options, tet_options)
    }

    fn prepare_kind(
        self: Arc<Self>,
        options: PrepareOptions,
        tet_options: TetOptions,
    ) -> PreparedScene {
        let prepared = match &self.geometry {
            Geometry::Metaballs(m) => {
                PreparedGeometry::Metaballs(Arc::new(PreparedMetaballs::new(m.clone(), options)))
            }
            Geometry::Tets(t) => {
                PreparedGeometry::Tets(Arc::new(PreparedTets::new(t.clone(), tet_options)))
            }
        };
        PreparedScene {
            scene: self,
            prepared,
        }
    }
}

/// A scene state ready to trace, shared by every session that views this state.
#[derive(Clone, Debug)]
pub struct PreparedScene {
    scene: Arc<Scene>,
    prepared: PreparedGeometry,
}

/// The prepared form of each primitive kind.
#[derive(Clone, Debug)]
pub enum PreparedGeometry {
    Metaballs(Arc<PreparedMetaballs>),
    Tets(Arc<PreparedTets>),
}

impl PreparedScene {
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn geometry(&self) -> &PreparedGeometry {
        &self.prepared
    }

    /// Milliseconds spent building the acceleration structure.
    pub fn build_ms(&self) -> f64 {
        match &self.prepared {
            PreparedGeometry::Metaballs(m) => m.build_ms(),
            PreparedGeometry::Tets(t) => t.build_ms() + t.shading_ms(),
        }
    }

    /// The first crossing of the isosurface along `ray` within `[t_min, t_max]`.
    pub fn first_hit(&self, ray: &Ray, t_min: f32, t_max: f32, isovalue: f32) -> Option<Hit> {
        match &self.prepared {
            PreparedGeometry::Metaballs(m) => m.first_hit(ray, t_min, t_max, isovalue),
            PreparedGeometry::Tets(t) => tet_first_hit(t, ray, t_min, t_max, isovalue),
        }
    }

    /// [`PreparedScene::first_hit`], adding traversal and root-finder counts to `counters`.
    pub fn first_hit_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut RayCounters,
    ) -> Option<Hit> {
        match &self.prepared {
            PreparedGeometry::Metaballs(m) => {
                m.first_hit_counted(ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Tets(t) => {
                // Tets count their own work (TetCounters); here only rays and hits.
                let hit = tet_first_hit(t, ray, t_min, t_max, isovalue);
                counters.rays += 1;
                counters.hits += hit.is_some() as u64;
                hit
            }
        }
    }
}

/// Primary rays a tile at a time: the one query that sees many rays from one eye at once.
impl PreparedScene {
    /// Each primary ray through pixels `x0..x1 × y0..y1` of `rays` (row by row) and its
    /// first hit, exactly as [`PreparedScene::first_hit`] would find it ray by ray. Tets trace
    /// the tile as one packet (tetrahedral-isosurface-ray-tracing.txt §5.2); metaballs ray by
    /// ray.
    pub fn primary_hits(
        &self,
        rays: &PrimaryRays,
        rect: (u32, u32, u32, u32),
        isovalue: f32,
        t_max: f32,
    ) -> Vec<(Ray, Option<Hit>)> {
        let (x0, y0, x1, y1) = rect;
        match &self.prepared {
            PreparedGeometry::Metaballs(m) => (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| rays.through_pixel(x, y)))
                .map(|ray| (ray, m.first_hit(&ray, 0.0, t_max, isovalue)))
                .collect(),
            PreparedGeometry::Tets(t) => {
                let mut dirs = Vec::new();
                let packet = RayPacket::tile(rays, rect, &mut dirs);
                let mut hits = vec![None; packet.dirs.len()];
                let q = TetQuery::single(isovalue);
                let mut c = TetCounters::default();
                let mut scratch = PacketScratch::default();
                t.first_hits_packet(&packet, 0.0, t_max, &q, &mut scratch, &mut hits, &mut c);
                packet
                    .dirs
                    .iter()
                    .zip(hits)
                    .map(|(&dir, hit)| {
                        let ray = Ray {
                            origin: packet.origin,
                            dir,
                        };
                        (ray, hit.map(|h| t.hit_record(&ray, &h, &q)))
                    })
                    .collect()
            }
        }
    }
}

/// The queries secondary rays make (shadows, occlusion, transmission, volumes). Every
/// primitive kind answers them; a new kind adds its arm to each.
impl PreparedScene {
    /// Some root of the isosurface on `[t_min, t_max]`, stopping at the first one found (not
    /// necessarily the nearest). A root at `t_min` means the segment starts inside the solid.
    pub fn any_hit_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut RayCounters,
    ) -> Option<f32> {
        match &self.prepared {
            PreparedGeometry::Metaballs(m) => {
                m.any_hit_counted(ray, t_min, t_max, isovalue, counters)
            }
            PreparedGeometry::Tets(t) => {
                let mut c = TetCounters::default();
                let hit = t.any_hit(ray, t_min, t_max, &TetQuery::single(isovalue), &mut c);
                counters.rays += 1;
                counters.hits += hit.is_some() as u64;
                hit.map(|h| h.t)
            }
        }
    }

    /// From a start inside the solid, where the ray leaves it within `[t_min, t_max]`.
    pub fn exit_hit_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut RayCounters,
    ) -> Option<Hit> {
        match &self.prepared {
            PreparedGeometry::Metaballs(m) => {
                m.exit_hit_counted(ray, t_min, t_max, isovalue, counters)
            }
            // Every crossing of a tet isosurface is a surface (no root sits at the segment's
            // start to mean "inside"), so the way out is the first crossing.
            PreparedGeometry::Tets(_) => {
                self.first_hit_counted(ray, t_min, t_max, isovalue, counters)
            }
        }
    }

    /// `∫ density dt` over `[t_min, t_max]`: the field for metaballs.
    pub fn optical_depth(&self, ray: &Ray, t_min: f32, t_max: f32) -> f32 {
        match &self.prepared {
            PreparedGeometry::Metaballs(m) => m.optical_depth(ray, t_min, t_max),
            // The tet paper renders isosurfaces only (§8.8): no density to absorb.
            PreparedGeometry::Tets(_) => 0.0,
        }
    }
}

/// The nearest crossing of one tet isosurface, as a shaded-ready hit.
fn tet_first_hit(
    t: &PreparedTets,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
) -> Option<Hit> {
    let q = TetQuery::single(isovalue);
    let mut c = TetCounters::default();
    let hit = t.first_hit(ray, t_min, t_max, &q, &mut c)?;
    Some(t.hit_record(ray, &hit, &q))
}
