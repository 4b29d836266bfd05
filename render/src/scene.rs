//! The closed set of primitive kinds, and a scene prepared for tracing.

use crate::metaball::{MetaballError, MetaballScene};
use crate::ray::{Hit, Ray};
use crate::shade::Lighting;
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
}

/// Why scene data was rejected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    #[error(transparent)]
    Metaball(#[from] MetaballError),
}

impl Scene {
    /// Checks the scene's data against the engine's limits.
    pub fn validate(&self, primitive_limit: usize) -> Result<(), SceneError> {
        match &self.geometry {
            Geometry::Metaballs(m) => m.validate(primitive_limit)?,
        }
        Ok(())
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        match &self.geometry {
            Geometry::Metaballs(m) => m.balls.len(),
        }
    }

    /// Isovalues for which the surface may exist, as an open interval.
    pub fn isovalue_range(&self) -> (f32, f32) {
        match &self.geometry {
            Geometry::Metaballs(m) => m.isovalue_range(),
        }
    }

    /// Builds what tracing needs (acceleration structures) for this state.
    pub fn prepare(self: Arc<Self>) -> PreparedScene {
        PreparedScene { scene: self }
    }
}

/// A scene state ready to trace, shared by every session that views this state.
#[derive(Clone, Debug)]
pub struct PreparedScene {
    scene: Arc<Scene>,
}

impl PreparedScene {
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The first crossing of the isosurface along `ray` within `[t_min, t_max]`.
    pub fn first_hit(&self, ray: &Ray, t_min: f32, t_max: f32, isovalue: f32) -> Option<Hit> {
        match &self.scene.geometry {
            Geometry::Metaballs(m) => m.first_hit(ray, t_min, t_max, isovalue),
        }
    }
}
