//! Follows one camera ray: first hit, then local shading; the background where it misses.

use crate::ray::Ray;
use crate::scene::PreparedScene;
use glam::Vec3;

/// Far limit of every ray, in scene units.
pub const T_MAX: f32 = 1.0e4;

/// Shaded linear colour and hit distance (`INFINITY` on a miss) of one primary ray.
pub fn trace_primary(scene: &PreparedScene, ray: &Ray, isovalue: f32) -> (Vec3, f32) {
    let lighting = &scene.scene().lighting;
    match scene.first_hit(ray, 0.0, T_MAX, isovalue) {
        Some(hit) => (lighting.shade(&hit, ray.dir), hit.t),
        None => (lighting.background(ray.dir.y), f32::INFINITY),
    }
}
