//! Rays and hit records shared by every primitive kind.

use crate::geom::frame::LocalFrame;
use glam::Vec3;

/// A ray `origin + t * dir`; `dir` has unit length so `t` is a distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray {
            origin,
            dir: dir.normalize(),
        }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + t * self.dir
    }

    /// The same ray in `frame` (the origin moved in `f64`; the direction, and so every
    /// distance along the ray, unchanged).
    pub fn in_frame(&self, frame: &LocalFrame) -> Ray {
        Ray {
            origin: frame.local_from_world(self.origin),
            dir: self.dir,
        }
    }
}

/// Distance a secondary ray starts off its surface, against self-intersection: above the
/// root finder's tolerance and the `f32` spacing at `p`. The integrator's continuing rays and
/// [`crossings`](crate::kinds::contract::PreparedKind::crossings) step past a crossing by it.
#[inline]
pub fn surface_offset(p: Vec3) -> f32 {
    1.0e-3 + 2.0e-5 * p.abs().max_element()
}

/// How close to a segment's start a root must be to mean "the segment starts inside".
pub const INSIDE_EPS: f32 = 2.0e-4;

/// The first intersection of a ray with a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f32,
    pub position: Vec3,
    /// Unit normal pointing out of the solid (towards lower field values for metaballs).
    pub normal: Vec3,
    /// Linear-light diffuse colour at the hit.
    pub albedo: Vec3,
    /// The primitive whose material shades the hit (for metaballs, the ball with the largest
    /// share of the field there).
    pub primitive: u32,
}
