//! The `f64` reference: brute force and Bézier clipping with a tight tolerance, every
//! quantity recomputed in double precision from the scene's data. Tests compare the `f32`
//! finders and acceleration modes against it (bezier-clipping-metaballs.txt §3.2: the field
//! on a ray is an exact polynomial per section and clipping brackets its first root, so with
//! a tolerance of `1e-9` it serves as ground truth).

use crate::kinds::metaballs::roots::{self, FindParams, KernelPoly, RayBall, RootFinder, Scratch};
use crate::kinds::metaballs::scene::{MetaballScene, Shape};
use glam::{DMat3, DQuat, DVec3};

/// Tolerance of the reference, world units.
pub const REFERENCE_TOLERANCE: f64 = 1e-9;

/// One ray through a scene in `f64`: the balls it crosses, ready for repeated queries.
#[derive(Debug)]
pub struct ReferenceRay {
    balls: Vec<RayBall<f64>>,
    kernel: KernelPoly<f64>,
    t_min: f64,
    t_max: f64,
}

impl ReferenceRay {
    /// The balls of `scene` that `origin + t·dir` (`dir` normalised here) crosses within
    /// `[t_min, t_max]`.
    pub fn new(
        scene: &MetaballScene,
        origin: DVec3,
        dir: DVec3,
        t_min: f64,
        t_max: f64,
    ) -> ReferenceRay {
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
            let Some((t0, t1, a, tc, s_min)) = RayBall::along(e.to_array(), g.to_array()) else {
                continue;
            };
            if t1 < t_min || t0 > t_max {
                continue;
            }
            balls.push(RayBall {
                ball: i as u32,
                t0,
                t1,
                a,
                tc,
                s_min,
                q: b.strength as f64,
                lipschitz: 0.0,
                min_radius: 0.0,
                owner: true,
            });
        }
        ReferenceRay {
            balls,
            kernel: KernelPoly::new(scene.kernel),
            t_min,
            t_max,
        }
    }

    /// The field at `t`.
    pub fn field(&self, t: f64) -> f64 {
        self.balls.iter().map(|b| b.term(&self.kernel, t)).sum()
    }

    /// Indices of the balls the ray crosses.
    pub fn crossed(&self) -> impl Iterator<Item = u32> + '_ {
        self.balls.iter().map(|b| b.ball)
    }

    /// Where the centres of the crossed balls project onto the ray.
    pub fn projections(&self) -> impl Iterator<Item = f64> + '_ {
        self.balls.iter().map(|b| b.tc)
    }

    /// The first `t` in `[from, t_max]` with `F(t) ≥ isovalue`.
    pub fn first_at_least(&self, isovalue: f64, from: f64) -> Option<f64> {
        find(
            &self.balls,
            self.kernel,
            isovalue,
            from.max(self.t_min),
            self.t_max,
        )
    }

    /// The first `t` in `[from, t_max]` with `F(t) < isovalue` (to `1e-12` in the field), or
    /// `t_max` when there is none: the exit of a stretch that starts at `from`.
    pub fn first_below(&self, isovalue: f64, from: f64) -> f64 {
        // F < T  ⇔  -F > -T: the first root of the negated field just above -T.
        let negated: Vec<RayBall<f64>> = self
            .balls
            .iter()
            .map(|b| RayBall { q: -b.q, ..*b })
            .collect();
        let lo = from.max(self.t_min);
        find(&negated, self.kernel, -isovalue + 1e-12, lo, self.t_max).unwrap_or(self.t_max)
    }
}

fn find(
    balls: &[RayBall<f64>],
    kernel: KernelPoly<f64>,
    isovalue: f64,
    lo: f64,
    hi: f64,
) -> Option<f64> {
    let params = FindParams {
        kernel,
        isovalue,
        tolerance: REFERENCE_TOLERANCE,
        owners_only: false,
    };
    let mut scratch = Scratch::default();
    roots::find_first(
        RootFinder::BezierClipping,
        &params,
        balls,
        lo,
        hi,
        &mut scratch,
    )
    .t
}

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
    ReferenceRay::new(scene, origin, dir, t_min, t_max).first_at_least(isovalue, t_min)
}
