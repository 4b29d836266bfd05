//! A pinhole camera and the rays it shoots through pixel centres.

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
    /// Precomputes what every primary ray needs for an image of `width` × `height`.
    pub fn rays(&self, width: u32, height: u32) -> PrimaryRays {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let half_h = (self.fov_y_deg.to_radians() * 0.5).tan();
        let half_w = half_h * width as f32 / height.max(1) as f32;
        PrimaryRays {
            eye: self.eye,
            forward,
            right_step: right * (2.0 * half_w / width.max(1) as f32),
            down_step: -up * (2.0 * half_h / height.max(1) as f32),
            top_left: forward - right * half_w + up * half_h,
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
}

impl PrimaryRays {
    /// The ray through the centre of pixel (`x`, `y`), with `y` counted from the top.
    pub fn through_pixel(&self, x: u32, y: u32) -> Ray {
        let dir =
            self.top_left + self.right_step * (x as f32 + 0.5) + self.down_step * (y as f32 + 0.5);
        Ray::new(self.eye, dir)
    }

    /// Unit vector along the view axis, for depth along the view direction.
    pub fn forward(&self) -> Vec3 {
        self.forward
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
    }
}
