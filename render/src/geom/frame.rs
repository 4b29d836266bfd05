//! The local frame a prepared scene is traced in: world coordinates minus an origin chosen in
//! `f64`, so a scene far from the world's origin is traced near its own (issue 13).
//!
//! How it works: `f32` spaces its values by about `6·10⁻⁸` of their magnitude, so a scene of
//! extent 1 placed 10⁵ from the origin has its positions, and every difference the hot path
//! forms from them, rounded to 0.008. [`LocalFrame::for_bounds`] picks the origin once per
//! prepared state, from the state's bounds: zero when the bounds' centre lies within a few
//! extents of the world origin (every ordinary scene, traced exactly as before), else the
//! centre rounded to a multiple of the power of two at or above the extent. That rounding
//! makes the translation exact for any `f32` position near the scene (the origin is a multiple
//! of the position's own spacing and the difference is small), so the local scene is the world
//! scene moved, not re-rounded; the camera and the lights move with it in `f64`. Distances and
//! normals do not change under a translation, so hit distances, depth and normals keep their
//! meaning; only hit positions are local.

use glam::{DVec3, Vec3};

/// Recentre only when the centre lies farther than this many extents from the origin.
const FAR_EXTENTS: f64 = 8.0;

/// A translation: `local = world - origin`, computed in `f64`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LocalFrame {
    /// The world position of the local frame's origin.
    pub origin: DVec3,
}

impl LocalFrame {
    /// The world frame itself.
    pub const WORLD: LocalFrame = LocalFrame {
        origin: DVec3::ZERO,
    };

    /// The frame for a state with world bounds `bounds` (`None`, or bounds that are not
    /// finite: the world frame). Deterministic: a function of the bounds alone.
    pub fn for_bounds(bounds: Option<(Vec3, Vec3)>) -> LocalFrame {
        let Some((lo, hi)) = bounds else {
            return LocalFrame::WORLD;
        };
        let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
        let centre = (lo + hi) * 0.5;
        let extent = (hi - lo).max_element();
        if !(centre.is_finite() && extent.is_finite() && extent >= 0.0) {
            return LocalFrame::WORLD;
        }
        if centre.abs().max_element() <= FAR_EXTENTS * extent.max(f64::MIN_POSITIVE) {
            return LocalFrame::WORLD;
        }
        // The power of two at or above the extent (at least 2⁻²⁰, for a point-like state).
        let grid = 2f64.powi(extent.max(1e-6).log2().ceil() as i32);
        LocalFrame {
            origin: (centre / grid).round() * grid,
        }
    }

    /// Whether this is the world frame (nothing moves).
    #[inline]
    pub fn is_world(&self) -> bool {
        self.origin == DVec3::ZERO
    }

    /// A world position in this frame.
    #[inline]
    pub fn local_from_world(&self, p_in_world: Vec3) -> Vec3 {
        if self.is_world() {
            return p_in_world;
        }
        (p_in_world.as_dvec3() - self.origin).as_vec3()
    }

    /// A position of this frame in the world, in `f64`.
    #[inline]
    pub fn world_from_local(&self, p_in_local: Vec3) -> DVec3 {
        p_in_local.as_dvec3() + self.origin
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scene_near_the_origin_keeps_the_world_frame() {
        let b = Some((Vec3::new(-1.0, 0.5, -2.0), Vec3::new(3.0, 2.0, 1.0)));
        assert!(LocalFrame::for_bounds(b).is_world());
        assert!(LocalFrame::for_bounds(None).is_world());
        let inf = Some((Vec3::splat(f32::NEG_INFINITY), Vec3::ONE));
        assert!(LocalFrame::for_bounds(inf).is_world());
    }

    #[test]
    fn a_far_scene_moves_exactly() {
        let o = 1.0e5f32;
        let lo = Vec3::new(o - 1.0, o - 1.0, o - 1.0);
        let hi = Vec3::new(o + 1.8, o + 1.0, o + 1.0);
        let f = LocalFrame::for_bounds(Some((lo, hi)));
        // Extent 2.8: a grid of 4, the centre 1e5 + 0.4 rounds to 1e5.
        assert_eq!(f.origin, DVec3::splat(1.0e5));
        let p = Vec3::new(o + 0.796875, o - 0.0078125, o + 4.0);
        let local = f.local_from_world(p);
        assert_eq!(local, Vec3::new(0.796875, -0.0078125, 4.0));
        assert_eq!(f.world_from_local(local), p.as_dvec3());
    }
}
