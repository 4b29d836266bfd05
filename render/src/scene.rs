//! A scene state and a scene prepared for tracing; the kinds themselves are in
//! [`crate::kinds`], and every query here is one call into its dispatch.
//!
//! Preparing a state builds its acceleration structure from scratch (for metaballs the Fitted
//! BVH of fitted-bvh-metaballs.txt by default, see [`crate::kinds::metaballs::tree`]; for tets
//! the implicit min–max BVH of tetrahedral-isosurface-ray-tracing.txt, see
//! [`crate::kinds::tets`], built once per mesh and refitted per step); the prepared state is
//! then shared, read-only, by every view of it.
//!
//! A state far from the world's origin is prepared and traced in a [`LocalFrame`] near its
//! own (issue 13): the geometry, the camera and the lighting are moved there in `f64` before
//! anything becomes an `f32` of the hot path. Every query of a [`PreparedScene`] takes rays
//! in that frame ([`PreparedScene::frame`]; [`Ray::in_frame`] moves a world ray) and returns
//! hit distances and normals, which a translation leaves unchanged, and local hit positions.

use crate::camera::{Camera, PrimaryRays};
use crate::geom::frame::LocalFrame;
use crate::kinds::contract::{OcclusionHint, RayStart};
use crate::kinds::dispatch::Tally;
use crate::kinds::metaballs::engine::PrepareOptions;
use crate::kinds::tets::prepared::TetOptions;
use crate::ray::{Hit, Ray};
use crate::shade::Lighting;
use glam::Vec3;
use std::sync::Arc;

// The closed kind enums live with their dispatch; these paths stay for the other crates.
pub use crate::kinds::dispatch::{Geometry, PreparedGeometry, SceneError};

/// One state of a scene: the primitives and how they are lit.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub geometry: Geometry,
    pub lighting: Lighting,
}

impl Scene {
    /// Checks the scene's data against the engine's limits.
    pub fn validate(&self, primitive_limit: usize) -> Result<(), SceneError> {
        self.geometry.validate(primitive_limit)
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        self.geometry.primitive_count()
    }

    /// Isovalues for which the surface may exist, as an open interval.
    pub fn isovalue_range(&self) -> (f32, f32) {
        self.geometry.isovalue_range()
    }

    /// Builds what tracing needs (acceleration structures) for this state: the Fitted BVH
    /// with every optimisation, for the state's lowest isovalue, and Bézier clipping; for
    /// tets the [`TetOptions`] defaults (BIH-style build, shared BVH refitted per step).
    pub fn prepare(self: Arc<Self>) -> PreparedScene {
        let options = self.geometry.default_metaball_options();
        self.prepare_kind(options, TetOptions::default())
    }

    /// [`Scene::prepare`] with a chosen acceleration structure and root finder (a tet scene
    /// ignores them and takes its defaults).
    pub fn prepare_with(self: Arc<Self>, options: PrepareOptions) -> PreparedScene {
        self.prepare_kind(options, TetOptions::default())
    }

    /// [`Scene::prepare`] with chosen tet options (a metaball scene ignores them and takes
    /// its defaults).
    pub fn prepare_tets_with(self: Arc<Self>, tet_options: TetOptions) -> PreparedScene {
        let options = self.geometry.default_metaball_options();
        self.prepare_kind(options, tet_options)
    }

    fn prepare_kind(
        self: Arc<Self>,
        options: PrepareOptions,
        tet_options: TetOptions,
    ) -> PreparedScene {
        let frame = self.geometry.frame();
        let prepared = self.geometry.prepare(options, tet_options, &frame);
        let lighting_in_frame =
            (!frame.is_world()).then(|| Arc::new(self.lighting.in_frame(&frame)));
        PreparedScene {
            scene: self,
            prepared,
            lighting: None,
            frame,
            lighting_in_frame,
        }
    }
}

/// A scene state ready to trace, shared by every session that views this state.
#[derive(Clone, Debug)]
pub struct PreparedScene {
    scene: Arc<Scene>,
    prepared: PreparedGeometry,
    /// A session's own lighting in place of the scene's (see [`PreparedScene::with_lighting`]).
    lighting: Option<Arc<Lighting>>,
    /// The frame the geometry was prepared in (the world's, unless the state is far away).
    frame: LocalFrame,
    /// [`PreparedScene::lighting`] moved into `frame`; `None` in the world frame.
    lighting_in_frame: Option<Arc<Lighting>>,
}

impl PreparedScene {
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// How this state is lit and shaded, in world coordinates: the scene's [`Lighting`], or
    /// the one given to [`PreparedScene::with_lighting`].
    pub fn lighting(&self) -> &Lighting {
        self.lighting.as_deref().unwrap_or(&self.scene.lighting)
    }

    /// [`PreparedScene::lighting`] in the scene's [`LocalFrame`]: tracing reads lighting only
    /// from here.
    pub fn lighting_in_frame(&self) -> &Lighting {
        self.lighting_in_frame
            .as_deref()
            .unwrap_or_else(|| self.lighting())
    }

    /// The frame the geometry is traced in: every query takes rays in it.
    pub fn frame(&self) -> &LocalFrame {
        &self.frame
    }

    /// The primary rays of `camera` (in world coordinates) for an image of `width` ×
    /// `height`, in the scene's frame: the camera is moved in `f64` before its rays are set
    /// up in `f32`.
    pub fn primary_rays(&self, camera: &Camera, width: u32, height: u32) -> PrimaryRays {
        camera.in_frame(&self.frame).rays(width, height)
    }

    /// The same prepared state (sharing its acceleration structure) lit by `lighting`
    /// instead: a session's own clip box, isosurfaces or colour map, without preparing the
    /// state again. Cheap: two reference counts and the lighting.
    pub fn with_lighting(&self, lighting: Lighting) -> PreparedScene {
        let lighting_in_frame =
            (!self.frame.is_world()).then(|| Arc::new(lighting.in_frame(&self.frame)));
        PreparedScene {
            scene: self.scene.clone(),
            prepared: self.prepared.clone(),
            lighting: Some(Arc::new(lighting)),
            frame: self.frame,
            lighting_in_frame,
        }
    }

    pub fn geometry(&self) -> &PreparedGeometry {
        &self.prepared
    }

    /// Milliseconds spent building the acceleration structure.
    pub fn build_ms(&self) -> f64 {
        self.prepared.build_ms()
    }

    /// The first crossing of the isosurface along `ray` (in the scene's [`frame`]) within
    /// `[t_min, t_max]`.
    ///
    /// [`frame`]: PreparedScene::frame
    #[inline]
    pub fn first_hit(&self, ray: &Ray, t_min: f32, t_max: f32, isovalue: f32) -> Option<Hit> {
        self.prepared
            .first_hit_uncounted(ray, t_min, t_max, isovalue)
    }

    /// [`PreparedScene::first_hit`], adding the kind's work to `counters` (every kind's
    /// [`SceneCounters`](crate::kinds::counters::SceneCounters), or a metaball counter set).
    #[inline]
    pub fn first_hit_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut impl Tally,
    ) -> Option<Hit> {
        self.prepared
            .first_hit(ray, t_min, t_max, isovalue, counters)
    }

    /// [`PreparedScene::first_hit_counted`] for a ray that leaves the surface outwards from a
    /// start lifted off it (a mirror ray from outside the solid): see
    /// [`PreparedKind::first_hit_leaving`](crate::kinds::contract::PreparedKind::first_hit_leaving).
    #[inline]
    pub fn first_hit_leaving_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut impl Tally,
    ) -> Option<Hit> {
        self.prepared
            .first_hit_leaving(ray, t_min, t_max, isovalue, counters)
    }

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
        counters: &mut impl Tally,
    ) -> Vec<(Ray, Option<Hit>)> {
        self.prepared
            .primary_tile(rays, rect, isovalue, t_max, counters)
    }

    /// Some root of the isosurface on `[t_min, t_max]`, stopping at the first one found (not
    /// necessarily the nearest). A root at `t_min` means the segment starts inside the solid.
    #[inline]
    pub fn any_hit_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut impl Tally,
    ) -> Option<f32> {
        self.prepared.any_hit(ray, t_min, t_max, isovalue, counters)
    }

    /// Whether the isosurface blocks `span` of `ray`
    /// ([`PreparedKind::occluded`](crate::kinds::contract::PreparedKind::occluded)): `hint`
    /// carries where the caller's last blocked ray was blocked.
    #[inline]
    pub fn occluded_counted(
        &self,
        ray: &Ray,
        span: (f32, f32),
        isovalue: f32,
        start: RayStart,
        hint: &mut OcclusionHint,
        counters: &mut impl Tally,
    ) -> bool {
        (self.prepared).occluded(ray, span, isovalue, start, hint, counters)
    }

    /// Whether `root`, an any-hit root on `span` of `ray`, blocks it
    /// ([`settle`](crate::kinds::contract::settle)).
    #[inline]
    pub fn settles(
        &self,
        ray: &Ray,
        span: (f32, f32),
        isovalue: f32,
        root: Option<f32>,
        counters: &mut impl Tally,
    ) -> bool {
        self.prepared.settle(ray, span, isovalue, root, counters)
    }

    /// Shadow rays towards one light traced together, where the kind has a packet for them
    /// ([`crate::kinds::contract::PreparedKind::any_hits_towards`]).
    #[allow(clippy::too_many_arguments)]
    pub fn any_hits_towards(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        light: Option<Vec3>,
        isovalue: f32,
        starts: &[RayStart],
        hint: &mut OcclusionHint,
        counters: &mut impl Tally,
    ) -> Option<Vec<Option<f32>>> {
        (self.prepared)
            .any_hits_towards(rays, t_min, t_max, light, isovalue, starts, hint, counters)
    }

    /// From a start inside the solid, where the ray leaves it within `[t_min, t_max]`.
    #[inline]
    pub fn exit_hit_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut impl Tally,
    ) -> Option<Hit> {
        self.prepared
            .exit_hit(ray, t_min, t_max, isovalue, counters)
    }

    /// The successive crossings of the isosurface along `ray` within `[t_min, t_max]`, at
    /// most `max`, appended to `out` (see
    /// [`PreparedKind::crossings`](crate::kinds::contract::PreparedKind::crossings)).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn crossings_counted(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        out: &mut Vec<Hit>,
        counters: &mut impl Tally,
    ) {
        self.prepared
            .crossings(ray, t_min, t_max, isovalue, inside, max, out, counters)
    }

    /// How many crossings [`PreparedScene::crossings_counted`] finds, at most `max` (see
    /// [`PreparedKind::crossing_count`](crate::kinds::contract::PreparedKind::crossing_count)).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn crossing_count(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        counters: &mut impl Tally,
    ) -> usize {
        self.prepared
            .crossing_count(ray, t_min, t_max, isovalue, inside, max, counters)
    }

    /// `∫ density dt` over `[t_min, t_max]`: the field for metaballs, 0 for tets.
    #[inline]
    pub fn optical_depth(&self, ray: &Ray, t_min: f32, t_max: f32) -> f32 {
        self.prepared.optical_depth(ray, t_min, t_max)
    }
}
