//! A pinhole camera and the rays it shoots through pixel centres.

use crate::geom::frame::LocalFrame;
use crate::ray::Ray;
use glam::Vec3;

/// A look-at pinhole camera in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
}

impl Camera {
    /// The same camera in `frame` (eye and target moved in `f64`; see [`LocalFrame`]).
    pub fn in_frame(&self, frame: &LocalFrame) -> Camera {
        Camera {
            eye: frame.local_from_world(self.eye),
            target: frame.local_from_world(self.target),
            ..*self
        }
    }

    /// Precomputes what every primary ray needs for an image of `width` × `height`.
    pub fn rays(&self, width: u32, height: u32) -> PrimaryRays {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let half_h = (self.fov_y_deg.to_radians() * 0.5).tan();
        let half_w = half_h * width as f32 / height.max(1) as f32;
        let right_step = right * (2.0 * half_w / width.max(1) as f32);
        let down_step = -up * (2.0 * half_h / height.max(1) as f32);
        PrimaryRays {
            eye: self.eye,
            forward,
            right_step,
            down_step,
            top_left: forward - right * half_w + up * half_h,
            right_dual: right_step / right_step.length_squared(),
            down_dual: down_step / down_step.length_squared(),
        }
    }
}

/// Generator of primary rays for one image size.
#[derive(Clone, Copy, Debug)]
pub struct PrimaryRays {
    eye: Vec3,
    forward: Vec3,
    right_step: Vec3,
    down_step: Vec3,
    top_left: Vec3,
    /// `right_step / |right_step|²` and likewise: dotted with an offset in the image plane
    /// they give it in pixels (the steps are orthogonal).
    right_dual: Vec3,
    down_dual: Vec3,
}

impl PrimaryRays {
    /// The ray through the centre of pixel (`x`, `y`), with `y` counted from the top.
    pub fn through_pixel(&self, x: u32, y: u32) -> Ray {
        let dir =
            self.top_left + self.right_step * (x as f32 + 0.5) + self.down_step * (y as f32 + 0.5);
        Ray::new(self.eye, dir)
    }

    /// The unnormalised direction (component 1 along the view axis) of the ray through the
    /// continuous pixel coordinates (`x`, `y`): pixel (`x`, `y`)'s own ray at `x + 0.5`,
    /// `y + 0.5`, as in [`PrimaryRays::through_pixel`].
    pub fn direction_at(&self, x: f32, y: f32) -> Vec3 {
        self.top_left + self.right_step * x + self.down_step * y
    }

    /// The eye, every primary ray's origin.
    pub fn eye(&self) -> Vec3 {
        self.eye
    }

    /// Where `point` appears in the image: the continuous pixel coordinates `(x, y)` whose
    /// ray passes through it (pixel `(x, y)`'s own ray has exactly those), or `None` unless
    /// the point lies in front of the eye.
    pub fn pixel_of(&self, point: Vec3) -> Option<(f32, f32)> {
        let v = point - self.eye;
        let depth = v.dot(self.forward);
        if !(depth > 0.0 && depth * depth > 1e-12 * v.length_squared()) {
            return None;
        }
        // Scaled so its component along `forward` is 1, like every unnormalised pixel ray.
        let rel = v * (1.0 / depth) - self.top_left;
        Some((
            rel.dot(self.right_dual) - 0.5,
            rel.dot(self.down_dual) - 0.5,
        ))
    }

    /// Unit vector along the view axis, for depth along the view direction.
    pub fn forward(&self) -> Vec3 {
        self.forward
    }

    /// What [`PrimaryRays::through_pixel`] is made of, for a backend that builds the rays
    /// itself (the GPU's): eye, direction through the top-left corner, one pixel's step right
    /// and down, and the view axis.
    pub fn parts(&self) -> [Vec3; 5] {
        [
            self.eye,
            self.top_left,
            self.right_step,
            self.down_step,
            self.forward,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_at_the_target() {
        let camera = Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 45.0,
        };
        let rays = camera.rays(101, 101);
        let ray = rays.through_pixel(50, 50);
        assert!((ray.dir - Vec3::NEG_Z).length() < 1e-6);
        let top = rays.through_pixel(50, 0);
        assert!(top.dir.y > 0.0, "row 0 is the top of the image");
        let (x, y) = rays.pixel_of(top.at(3.0)).expect("in front of the eye");
        assert!((x - 50.0).abs() < 1e-3 && y.abs() < 1e-3, "{x} {y}");
        let corner = camera.rays(64, 48).through_pixel(63, 47);
        let (x, y) = camera
            .rays(64, 48)
            .pixel_of(corner.at(7.0))
            .expect("in front");
        assert!(
            (x - 63.0).abs() < 1e-3 && (y - 47.0).abs() < 1e-3,
            "{x} {y}"
        );
        assert!(
            rays.pixel_of(Vec3::new(0.0, 0.0, 6.0)).is_none(),
            "behind the eye"
        );
    }
}
