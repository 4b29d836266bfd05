//! The sample warps the effects use (their random numbers come from
//! [`crate::geom::rng::PixelRng`], one stream per pixel and pass).

use glam::Vec3;

/// An orthonormal basis `(t, b)` completing the unit vector `n` (Duff et al. 2017).
#[inline]
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// A cosine-weighted direction about the unit normal `n`, from two uniforms.
#[inline]
pub fn cosine_hemisphere(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let phi = std::f32::consts::TAU * u2;
    let (t, b) = basis(n);
    let z = (1.0 - u1).max(0.0).sqrt();
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize()
}

/// A direction uniform in solid angle inside the cone about unit `axis` with half-angle
/// `acos(cos_max)`, from two uniforms: the directions towards a sphere light's visible cap.
#[inline]
pub fn uniform_cone(axis: Vec3, cos_max: f32, u1: f32, u2: f32) -> Vec3 {
    let cos_t = 1.0 - u1 * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * u2;
    let (t, b) = basis(axis);
    (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::rng::PixelRng;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<u64> = (0..4).map(|_| PixelRng::new(3, 4, 5).next_u64()).collect();
        assert!(a.windows(2).all(|w| w[0] == w[1]));
        let mut seen = std::collections::HashSet::new();
        for y in 0..16 {
            for x in 0..16 {
                for pass in 0..4 {
                    assert!(seen.insert(PixelRng::new(x, y, pass).next_u64()));
                }
            }
        }
        let mut r = PixelRng::new(0, 0, 0);
        let mean = (0..10_000).map(|_| r.next_f32() as f64).sum::<f64>() / 10_000.0;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
    }

    #[test]
    fn warps_stay_in_their_domains() {
        let mut r = PixelRng::new(1, 2, 3);
        for n in [Vec3::Z, Vec3::NEG_Z, Vec3::new(0.3, -0.8, 0.2).normalize()] {
            let (t, b) = basis(n);
            assert!(t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5 && t.dot(b).abs() < 1e-5);
            let mut mean_cos = 0.0;
            for _ in 0..4000 {
                let d = cosine_hemisphere(n, r.next_f32(), r.next_f32());
                assert!(d.dot(n) >= -1e-5);
                mean_cos += d.dot(n) / 4000.0;
                let c = uniform_cone(n, 0.9, r.next_f32(), r.next_f32());
                assert!(c.dot(n) >= 0.9 - 1e-5);
            }
            // E[cos θ] = 2/3 under the cosine distribution.
            assert!((mean_cos - 2.0 / 3.0).abs() < 0.02, "{mean_cos}");
        }
    }
}
