//! Local shading: Lambert diffuse plus Blinn-Phong specular from directional lights, in
//! linear light, and the conversion to 8-bit sRGB.

use crate::ray::Hit;
use glam::Vec3;

/// A light infinitely far away.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionalLight {
    /// Unit vector from the surface towards the light.
    pub to_light: Vec3,
    /// Linear-light radiance scale per channel.
    pub color: Vec3,
}

/// How a scene is lit and what lies behind it.
#[derive(Clone, Debug, PartialEq)]
pub struct Lighting {
    pub lights: Vec<DirectionalLight>,
    /// Constant ambient term, linear light.
    pub ambient: Vec3,
    /// Background at the top and bottom of the image, linear light.
    pub background_top: Vec3,
    pub background_bottom: Vec3,
    /// Blinn-Phong exponent and weight of the white specular lobe.
    pub shininess: f32,
    pub specular: f32,
}

impl Default for Lighting {
    fn default() -> Lighting {
        Lighting {
            lights: vec![DirectionalLight {
                to_light: Vec3::new(0.4, 0.8, 0.45).normalize(),
                color: Vec3::splat(1.0),
            }],
            ambient: Vec3::splat(0.08),
            background_top: Vec3::new(0.08, 0.09, 0.12),
            background_bottom: Vec3::new(0.015, 0.015, 0.02),
            shininess: 48.0,
            specular: 0.35,
        }
    }
}

impl Lighting {
    /// Colour of a surface point seen from direction `view_dir` (unit, towards the surface).
    pub fn shade(&self, hit: &Hit, view_dir: Vec3) -> Vec3 {
        let n = hit.normal;
        let to_eye = -view_dir;
        let mut color = self.ambient * hit.albedo;
        for light in &self.lights {
            let n_dot_l = n.dot(light.to_light);
            if n_dot_l <= 0.0 {
                continue;
            }
            let half = (light.to_light + to_eye).normalize_or_zero();
            let spec = n.dot(half).max(0.0).powf(self.shininess) * self.specular;
            color += light.color * (hit.albedo * n_dot_l + Vec3::splat(spec));
        }
        color
    }

    /// Background seen along a ray whose direction has vertical component `dir_y`.
    pub fn background(&self, dir_y: f32) -> Vec3 {
        let a = 0.5 * (dir_y.clamp(-1.0, 1.0) + 1.0);
        self.background_bottom.lerp(self.background_top, a)
    }
}

/// Linear light in `[0, 1]` to an 8-bit sRGB value (IEC 61966-2-1).
#[inline]
pub fn linear_to_srgb8(v: f32) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_endpoints_and_midpoint() {
        assert_eq!(linear_to_srgb8(0.0), 0);
        assert_eq!(linear_to_srgb8(1.0), 255);
        assert_eq!(linear_to_srgb8(0.5), 188, "linear 0.5 is sRGB 0.735");
        assert_eq!(
            linear_to_srgb8(f32::NAN),
            0,
            "NaN never reaches the image as garbage"
        );
    }
}
