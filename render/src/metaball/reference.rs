//! The `f64` reference hit: brute force and Bézier clipping with a tight tolerance, every
//! quantity recomputed in double precision from the scene's data. Tests compare the `f32`
//! finders against it (bezier-clipping-metaballs.txt §3.2 is robust and exact up to its
//! tolerance, so it serves as ground truth).

use super::roots::{self, FindParams, KernelPoly, RayBall, RootFinder, Scratch};
use super::{MetaballScene, Shape};
use glam::{DMat3, DQuat, DVec3};

/// Tolerance of the reference, world units.
pub const REFERENCE_TOLERANCE: f64 = 1e-9;

/// The first `t` in `[t_min, t_max]` with `F ≥ T` along `origin + t·dir` (`dir` is
/// normalised here), in `f64`.
pub fn reference_hit(
    scene: &MetaballScene,
    origin: DVec3,
    dir: DVec3,
    t_min: f64,
    t_max: f64,
    isovalue: f64,
) -> Option<f64> {
    let dir = dir.normalize();
    let mut balls: Vec<RayBall<f64>> = Vec::new();
    for (i, b) in scene.balls.iter().enumerate() {
        let center = b.center.as_dvec3();
        let r = b.radius as f64;
        let m = match b.shape {
            Shape::Sphere => DMat3::from_diagonal(DVec3::splat(1.0 / r)),
            Shape::Ellipsoid { axes, rotation } => {
                let q = DQuat::from_xyzw(
                    rotation.x as f64,
                    rotation.y as f64,
                    rotation.z as f64,
                    rotation.w as f64,
                )
                .normalize();
                DMat3::from_diagonal((r * axes.as_dvec3()).recip())
                    * DMat3::from_quat(q).transpose()
            }
        };
        let e = m * (origin - center);
        let g = m * dir;
        let (a, bq, c) = (g.length_squared(), 2.0 * e.dot(g), e.length_squared());
        let disc = bq * bq - 4.0 * a * (c - 1.0);
        if disc <= 0.0 {
            continue;
        }
        let sq = disc.sqrt();
        let (t0, t1) = ((-bq - sq) / (2.0 * a), (-bq + sq) / (2.0 * a));
        if t1 < t_min || t0 > t_max {
            continue;
        }
        balls.push(RayBall {
            ball: i as u32,
            t0,
            t1,
            a,
            b: bq,
            c,
            q: b.strength as f64,
            lipschitz: 0.0,
            min_radius: 0.0,
            owner: true,
        });
    }
    let params = FindParams {
        kernel: KernelPoly::<f64>::new(scene.kernel),
        isovalue,
        tolerance: REFERENCE_TOLERANCE,
        owners_only: false,
    };
    let mut scratch = Scratch::default();
    roots::find_first(
        RootFinder::BezierClipping,
        &params,
        &balls,
        t_min,
        t_max,
        &mut scratch,
    )
    .t
}
