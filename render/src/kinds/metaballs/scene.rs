//! A metaball state: the balls, their kernel, and the checks made when one arrives.

use crate::geom::frame::LocalFrame;
use crate::kinds::metaballs::kernel::Kernel;
use glam::{Mat3, Quat, Vec3};

/// A ball's shape of support.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// The sphere of radius `radius`.
    Sphere,
    /// An ellipsoid with semi-axes `radius · axes` along the columns of `rotation`; every
    /// component of `axes` lies in `(0, 1]`, so `radius` bounds it.
    Ellipsoid { axes: Vec3, rotation: Quat },
}

/// One ball. `strength` may be negative (it then carves the surface).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metaball {
    pub center: Vec3,
    /// Radius of support (of the bounding sphere, for an ellipsoid).
    pub radius: f32,
    pub strength: f32,
    /// Linear-light colour, blended by each ball's share of the field.
    pub color: Vec3,
    pub shape: Shape,
}

impl Metaball {
    /// A spherical ball.
    pub fn sphere(center: Vec3, radius: f32, strength: f32, color: Vec3) -> Metaball {
        Metaball {
            center,
            radius,
            strength,
            color,
            shape: Shape::Sphere,
        }
    }

    /// `M` with `s = |M (p - center)|²`: `I / R` for a sphere.
    pub fn normalizing(&self) -> Mat3 {
        match self.shape {
            Shape::Sphere => Mat3::from_diagonal(Vec3::splat(1.0 / self.radius)),
            Shape::Ellipsoid { axes, rotation } => {
                Mat3::from_diagonal((self.radius * axes).recip())
                    * Mat3::from_quat(rotation.normalize()).transpose()
            }
        }
    }

    /// The smallest semi-axis.
    pub fn min_semi_axis(&self) -> f32 {
        match self.shape {
            Shape::Sphere => self.radius,
            Shape::Ellipsoid { axes, .. } => self.radius * axes.min_element(),
        }
    }

    /// `s` at `p` (≥ 1 outside the support).
    pub fn s_at(&self, p: Vec3) -> f32 {
        match self.shape {
            Shape::Sphere => (p - self.center).length_squared() / (self.radius * self.radius),
            Shape::Ellipsoid { .. } => (self.normalizing() * (p - self.center)).length_squared(),
        }
    }
}

/// A problem with metaball data, naming the offending ball.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MetaballError {
    #[error("ball {index}: {field} is not finite")]
    NotFinite { index: usize, field: &'static str },
    #[error("ball {index}: radius {radius} must be positive")]
    BadRadius { index: usize, radius: f32 },
    #[error("ball {index}: ellipsoid axes must lie in (0, 1] and the rotation be non-zero")]
    BadEllipsoid { index: usize },
    #[error("{count} balls exceed the limit of {limit}")]
    TooMany { count: usize, limit: usize },
    #[error("kernel {kernel:?} is not supported (Power needs alpha in 1..=4)")]
    BadKernel { kernel: Kernel },
}

/// The balls of one state and their kernel.
#[derive(Clone, Debug, PartialEq)]
pub struct MetaballScene {
    pub kernel: Kernel,
    pub balls: Vec<Metaball>,
    /// The lowest isovalue this state is meant to be viewed at. The Fitted BVH's tighter
    /// boxes and split-metaball discarding (fitted-bvh-metaballs.txt §5.3) are built for it;
    /// a lower isovalue falls back to a structure built without them.
    pub min_isovalue: f32,
}

impl MetaballScene {
    /// Balls with Wyvill's kernel, viewed from isovalue 0.05 up.
    pub fn new(kernel: Kernel, balls: Vec<Metaball>) -> MetaballScene {
        MetaballScene {
            kernel,
            balls,
            min_isovalue: 0.05,
        }
    }

    /// Checks every ball; the first bad one is named in the error.
    pub fn validate(&self, limit: usize) -> Result<(), MetaballError> {
        if self.balls.len() > limit {
            return Err(MetaballError::TooMany {
                count: self.balls.len(),
                limit,
            });
        }
        if !self.kernel.is_supported() {
            return Err(MetaballError::BadKernel {
                kernel: self.kernel,
            });
        }
        for (index, ball) in self.balls.iter().enumerate() {
            let not_finite = |field| Err(MetaballError::NotFinite { index, field });
            if !ball.center.is_finite() {
                return not_finite("center");
            }
            if !ball.strength.is_finite() {
                return not_finite("strength");
            }
            if !ball.color.is_finite() {
                return not_finite("color");
            }
            if !ball.radius.is_finite() {
                return not_finite("radius");
            }
            if ball.radius <= 0.0 {
                return Err(MetaballError::BadRadius {
                    index,
                    radius: ball.radius,
                });
            }
            if let Shape::Ellipsoid { axes, rotation } = ball.shape {
                let axes_ok =
                    axes.is_finite() && axes.min_element() > 0.0 && axes.max_element() <= 1.0;
                let rotation_ok = rotation.is_finite() && rotation.length_squared() > 1e-12;
                if !axes_ok || !rotation_ok || ball.min_semi_axis() <= 0.0 {
                    return Err(MetaballError::BadEllipsoid { index });
                }
            }
        }
        Ok(())
    }

    /// Isovalues with a possibly non-empty surface: the field never exceeds the sum of the
    /// positive strengths times the kernel's peak, and at zero the surface is the support
    /// boundary itself.
    pub fn isovalue_range(&self) -> (f32, f32) {
        let positive: f32 = self.balls.iter().map(|b| b.strength.max(0.0)).sum();
        (0.0, positive * self.kernel.peak())
    }

    /// The field at `p`, summing over `balls` (all of them, or an active subset).
    pub fn field_at(&self, balls: &[u32], p: Vec3) -> f32 {
        balls
            .iter()
            .map(|&i| {
                let b = &self.balls[i as usize];
                b.strength * self.kernel.value(b.s_at(p))
            })
            .sum()
    }

    /// Outward unit normal (against the field gradient) and blended colour at `p`.
    pub fn surface_at(&self, balls: impl IntoIterator<Item = u32>, p: Vec3) -> (Vec3, Vec3) {
        let (normal, albedo, _) = self.surface_detail(balls, p);
        (normal, albedo)
    }

    /// [`MetaballScene::surface_at`], plus the ball with the largest share of the field at
    /// `p` (its material group shades the hit; 0 when none contributes).
    pub fn surface_detail(
        &self,
        balls: impl IntoIterator<Item = u32>,
        p: Vec3,
    ) -> (Vec3, Vec3, u32) {
        let mut dominant = (0u32, 0.0f32);
        let mut gradient = Vec3::ZERO;
        let mut color = Vec3::ZERO;
        let mut weight = 0.0f32;
        for i in balls {
            let b = &self.balls[i as usize];
            let d = p - b.center;
            // s and ds/dp = 2 Mᵀ M d.
            let (s, ds) = match b.shape {
                Shape::Sphere => {
                    let inv_r2 = 1.0 / (b.radius * b.radius);
                    (d.length_squared() * inv_r2, 2.0 * inv_r2 * d)
                }
                Shape::Ellipsoid { .. } => {
                    let m = b.normalizing();
                    let md = m * d;
                    (md.length_squared(), 2.0 * (m.transpose() * md))
                }
            };
            if s >= 1.0 {
                continue;
            }
            gradient += b.strength * self.kernel.derivative(s) * ds;
            let w = (b.strength * self.kernel.value(s)).max(0.0);
            color += w * b.color;
            weight += w;
            if w > dominant.1 {
                dominant = (i, w);
            }
        }
        let normal = (-gradient).normalize_or(Vec3::Z);
        let albedo = if weight > 0.0 {
            color / weight
        } else {
            Vec3::splat(0.5)
        };
        (normal, albedo, dominant.0)
    }

    /// The same scene moved into `frame` (each ball's centre, in `f64`).
    pub fn in_frame(&self, frame: &LocalFrame) -> MetaballScene {
        let mut s = self.clone();
        for b in &mut s.balls {
            b.center = frame.local_from_world(b.center);
        }
        s
    }

    /// Axis-aligned bounds of every ball's support, or `None` for an empty scene.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut it = self.balls.iter();
        let first = it.next()?;
        let init = (
            first.center - Vec3::splat(first.radius),
            first.center + Vec3::splat(first.radius),
        );
        Some(it.fold(init, |(lo, hi), b| {
            (
                lo.min(b.center - Vec3::splat(b.radius)),
                hi.max(b.center + Vec3::splat(b.radius)),
            )
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ray::Ray;

    #[test]
    fn validation_names_the_offending_ball() {
        let good = Metaball::sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE);
        let mut scene = MetaballScene::new(Kernel::Wyvill, vec![good; 3]);
        assert_eq!(scene.validate(10), Ok(()));
        scene.balls[2].center.x = f32::NAN;
        assert_eq!(
            scene.validate(10),
            Err(MetaballError::NotFinite {
                index: 2,
                field: "center"
            })
        );
        scene.balls[2] = good;
        scene.balls[1].center.y = f32::INFINITY;
        assert_eq!(
            scene.validate(10),
            Err(MetaballError::NotFinite {
                index: 1,
                field: "center"
            })
        );
        scene.balls[1] = good;
        scene.balls[1].radius = 0.0;
        assert!(matches!(
            scene.validate(10),
            Err(MetaballError::BadRadius { index: 1, .. })
        ));
        scene.balls[1].radius = -2.0;
        assert!(matches!(
            scene.validate(10),
            Err(MetaballError::BadRadius { index: 1, .. })
        ));
        scene.balls[1] = good;
        scene.balls[0].shape = Shape::Ellipsoid {
            axes: Vec3::new(1.0, 0.0, 0.5),
            rotation: Quat::IDENTITY,
        };
        assert_eq!(
            scene.validate(10),
            Err(MetaballError::BadEllipsoid { index: 0 })
        );
        scene.balls[0] = good;
        assert!(matches!(
            scene.validate(2),
            Err(MetaballError::TooMany { count: 3, limit: 2 })
        ));
        scene.kernel = Kernel::Power { alpha: 7 };
        assert!(matches!(
            scene.validate(10),
            Err(MetaballError::BadKernel { .. })
        ));
    }

    #[test]
    fn single_ball_hit_matches_the_analytic_radius() {
        // One Wyvill ball of radius 2 at T = 0.5 is a sphere of radius 1 (f(R/2) = 1/2).
        let scene = MetaballScene::new(
            Kernel::Wyvill,
            vec![Metaball::sphere(Vec3::ZERO, 2.0, 1.0, Vec3::ONE)],
        );
        let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
        let hit = scene
            .first_hit(&ray, 0.0, 100.0, 0.5)
            .expect("the ray hits the ball");
        assert!((hit.t - 4.0).abs() < 1e-3, "t = {}", hit.t);
        assert!((hit.normal - Vec3::Z).length() < 1e-3);
        let miss = Ray::new(Vec3::new(0.0, 1.5, 5.0), Vec3::NEG_Z);
        assert!(scene.first_hit(&miss, 0.0, 100.0, 0.5).is_none());
    }
}
