//! The optimal rigid transform of deforming-point-sampled-surfaces.txt §4.1.3, factored out
//! of every step: translation between the mass centres and the least-squares rotation
//! `R = V Uᵀ` from the SVD of `F = Σ m̃² (x − x_m)(x' − x'_m)ᵀ` (eq. 10).
//!
//! nalgebra is used for the 3×3 SVD only (glam has none); everything else is glam.

use glam::{DMat3, DVec3, Mat3, Vec3};

/// `x ↦ rotation · (x − rest_centre) + moved_centre`: the rigid motion that best aligns the
/// rest simulation nodes with the deformed ones.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidFrame {
    pub rotation: Mat3,
    pub rest_centre: Vec3,
    pub moved_centre: Vec3,
}

impl RigidFrame {
    pub const IDENTITY: RigidFrame = RigidFrame {
        rotation: Mat3::IDENTITY,
        rest_centre: Vec3::ZERO,
        moved_centre: Vec3::ZERO,
    };

    /// The optimal frame for rest positions `rest`, deformed positions `moved` and masses.
    pub fn optimal(rest: &[Vec3], moved: &[Vec3], mass: &[f32]) -> RigidFrame {
        let total: f64 = mass.iter().map(|&m| m as f64).sum();
        if rest.is_empty() || total <= 0.0 {
            return RigidFrame::IDENTITY;
        }
        let norm = |m: f32| m as f64 / total;
        let mut xm = DVec3::ZERO;
        let mut ym = DVec3::ZERO;
        for ((x, y), &m) in rest.iter().zip(moved).zip(mass) {
            xm += norm(m) * x.as_dvec3();
            ym += norm(m) * y.as_dvec3();
        }
        let mut f = DMat3::ZERO;
        for ((x, y), &m) in rest.iter().zip(moved).zip(mass) {
            let w = norm(m) * norm(m);
            let a = x.as_dvec3() - xm;
            let b = y.as_dvec3() - ym;
            // Outer product a bᵀ, column by column.
            f += DMat3::from_cols(a * b.x, a * b.y, a * b.z) * w;
        }
        RigidFrame {
            rotation: rotation_of(&f).as_mat3(),
            rest_centre: xm.as_vec3(),
            moved_centre: ym.as_vec3(),
        }
    }

    /// Where the rigidly moved reference system puts rest point `x`.
    #[inline]
    pub fn apply(&self, x: Vec3) -> Vec3 {
        self.rotation * (x - self.rest_centre) + self.moved_centre
    }
}

/// `R = V Uᵀ` with `F = U W Vᵀ`, a proper rotation (a reflection is flipped on the smallest
/// singular value).
fn rotation_of(f: &DMat3) -> DMat3 {
    let m = nalgebra::Matrix3::from_fn(|r, c| f.col(c)[r]);
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return DMat3::IDENTITY;
    };
    let v = v_t.transpose();
    let mut r = v * u.transpose();
    if r.determinant() < 0.0 {
        // Flip the column of V for the smallest singular value.
        let smallest = (0..3)
            .min_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]))
            .unwrap_or(2);
        let mut v2 = v;
        v2.column_mut(smallest).neg_mut();
        r = v2 * u.transpose();
    }
    DMat3::from_cols_array(&[
        r[(0, 0)],
        r[(1, 0)],
        r[(2, 0)],
        r[(0, 1)],
        r[(1, 1)],
        r[(2, 1)],
        r[(0, 2)],
        r[(1, 2)],
        r[(2, 2)],
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::rng::SplitMix64;

    #[test]
    fn recovers_a_rigid_motion() {
        let mut rng = SplitMix64(11);
        let rest: Vec<Vec3> = (0..40).map(|_| rng.in_unit_ball() * 2.0).collect();
        let mass: Vec<f32> = (0..40).map(|_| rng.range(0.5, 2.0)).collect();
        let rot = Mat3::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).normalize(), 2.3);
        let t = Vec3::new(3.0, -1.0, 0.5);
        let moved: Vec<Vec3> = rest.iter().map(|x| rot * *x + t).collect();
        let frame = RigidFrame::optimal(&rest, &moved, &mass);
        for (x, y) in rest.iter().zip(&moved) {
            assert!((frame.apply(*x) - *y).length() < 1e-4, "{frame:?}");
        }
        assert!((frame.rotation.determinant() - 1.0).abs() < 1e-5);
    }
}
