//! Mirror reflection and Snell refraction of a ray's direction at a surface.

use glam::Vec3;

/// `dir` mirrored about the unit `normal`.
#[inline]
pub fn reflect(dir: Vec3, normal: Vec3) -> Vec3 {
    (dir - 2.0 * dir.dot(normal) * normal).normalize()
}

/// `dir` bent through a boundary with unit `normal` facing against it and index ratio
/// `eta = n1 / n2`; `None` under total internal reflection.
#[inline]
pub fn refract_dir(dir: Vec3, normal: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = -dir.dot(normal);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        return None;
    }
    Some((eta * dir + (eta * cos_i - k.sqrt()) * normal).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snell_and_mirror() {
        let n = Vec3::Y;
        let d = Vec3::new(1.0, -1.0, 0.0).normalize();
        assert!((reflect(d, n) - Vec3::new(1.0, 1.0, 0.0).normalize()).length() < 1e-6);
        let t = refract_dir(d, n, 1.0 / 1.5).expect("entering glass never reflects totally");
        let sin_t = t.x;
        assert!((sin_t - (45f32.to_radians().sin() / 1.5)).abs() < 1e-6);
        assert!(
            refract_dir(d, n, 1.5).is_none(),
            "45° from glass is past critical"
        );
    }
}
