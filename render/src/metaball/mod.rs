//! Metaballs: balls of finite support whose summed field defines the surface `F(p) = T`.
//!
//! How it works (foundation): each ball `i` has centre `c_i`, radius `R_i` and strength `q_i`
//! and contributes `q_i · f(|p - c_i|² / R_i²)` inside its sphere and nothing outside. The
//! kernel `f` is Wyvill's degree-six polynomial (bezier-clipping-metaballs.txt §2, Fig. 1):
//! `f(s) = 1 - 22/9 s + 17/9 s² - 4/9 s³` with `s = r²/R²`, so `f(0) = 1`, `f(R) = 0`,
//! `f'(R) = 0` and `f(R/2) = 1/2`. The first root along a ray is found by [`march`]: the
//! ray is clipped to the union of the spheres it crosses and each span is marched with a step
//! below the smallest radius there, then refined by bisection.

pub mod march;

use crate::ray::{Hit, Ray};
use glam::Vec3;

/// The radial falloff shared by every ball of a set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// Wyvill, McPheeters and Wyvill's degree-six polynomial in `r²/R²`.
    Wyvill,
}

impl Kernel {
    /// The kernel at `s = r² / R²`, for `s` in `[0, 1]`; zero beyond.
    #[inline]
    pub fn value(self, s: f32) -> f32 {
        if s >= 1.0 {
            return 0.0;
        }
        match self {
            Kernel::Wyvill => 1.0 + s * (-22.0 / 9.0 + s * (17.0 / 9.0 - s * (4.0 / 9.0))),
        }
    }

    /// `df/ds` at `s`, zero beyond the support.
    #[inline]
    pub fn derivative(self, s: f32) -> f32 {
        if s >= 1.0 {
            return 0.0;
        }
        match self {
            Kernel::Wyvill => -22.0 / 9.0 + s * (34.0 / 9.0 - s * (12.0 / 9.0)),
        }
    }
}

/// One ball. `strength` may be negative (it then carves the surface).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metaball {
    pub center: Vec3,
    pub radius: f32,
    pub strength: f32,
    /// Linear-light colour, blended by each ball's share of the field.
    pub color: Vec3,
}

/// A problem with metaball data, naming the offending ball.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MetaballError {
    #[error("ball {index}: {field} is not finite")]
    NotFinite { index: usize, field: &'static str },
    #[error("ball {index}: radius {radius} must be positive")]
    BadRadius { index: usize, radius: f32 },
    #[error("{count} balls exceed the limit of {limit}")]
    TooMany { count: usize, limit: usize },
}

/// The balls of one state and their kernel.
#[derive(Clone, Debug, PartialEq)]
pub struct MetaballScene {
    pub kernel: Kernel,
    pub balls: Vec<Metaball>,
}

impl MetaballScene {
    /// Checks every ball; the first bad one is named in the error.
    pub fn validate(&self, limit: usize) -> Result<(), MetaballError> {
        if self.balls.len() > limit {
            return Err(MetaballError::TooMany {
                count: self.balls.len(),
                limit,
            });
        }
        for (index, ball) in self.balls.iter().enumerate() {
            let finite = |v: Vec3| v.is_finite();
            if !finite(ball.center) {
                return Err(MetaballError::NotFinite {
                    index,
                    field: "center",
                });
            }
            if !ball.strength.is_finite() {
                return Err(MetaballError::NotFinite {
                    index,
                    field: "strength",
                });
            }
            if !finite(ball.color) {
                return Err(MetaballError::NotFinite {
                    index,
                    field: "color",
                });
            }
            if !ball.radius.is_finite() {
                return Err(MetaballError::NotFinite {
                    index,
                    field: "radius",
                });
            }
            if ball.radius <= 0.0 {
                return Err(MetaballError::BadRadius {
                    index,
                    radius: ball.radius,
                });
            }
        }
        Ok(())
    }

    /// Isovalues with a possibly non-empty surface: the field never exceeds the sum of the
    /// positive strengths, and at zero the surface is the support boundary itself.
    pub fn isovalue_range(&self) -> (f32, f32) {
        let positive: f32 = self.balls.iter().map(|b| b.strength.max(0.0)).sum();
        (0.0, positive)
    }

    /// The field at `p`, summing over `balls` (all of them, or an active subset).
    pub fn field_at(&self, balls: &[u32], p: Vec3) -> f32 {
        balls
            .iter()
            .map(|&i| {
                let b = &self.balls[i as usize];
                b.strength
                    * self
                        .kernel
                        .value((p - b.center).length_squared() / (b.radius * b.radius))
            })
            .sum()
    }

    /// Outward unit normal (against the field gradient) and blended colour at `p`.
    pub fn surface_at(&self, balls: &[u32], p: Vec3) -> (Vec3, Vec3) {
        let mut gradient = Vec3::ZERO;
        let mut color = Vec3::ZERO;
        let mut weight = 0.0f32;
        for &i in balls {
            let b = &self.balls[i as usize];
            let inv_r2 = 1.0 / (b.radius * b.radius);
            let d = p - b.center;
            let s = d.length_squared() * inv_r2;
            if s >= 1.0 {
                continue;
            }
            gradient += b.strength * self.kernel.derivative(s) * 2.0 * inv_r2 * d;
            let w = (b.strength * self.kernel.value(s)).max(0.0);
            color += w * b.color;
            weight += w;
        }
        let normal = (-gradient).normalize_or(Vec3::Z);
        let albedo = if weight > 0.0 {
            color / weight
        } else {
            Vec3::splat(0.5)
        };
        (normal, albedo)
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

    /// The first crossing of the isosurface along `ray` within `[t_min, t_max]`.
    pub fn first_hit(&self, ray: &Ray, t_min: f32, t_max: f32, isovalue: f32) -> Option<Hit> {
        march::first_hit(self, ray, t_min, t_max, isovalue)
    }
}

/// Where a ray enters and leaves a ball's sphere of support, if it does.
#[inline]
pub fn sphere_interval(ray: &Ray, center: Vec3, radius: f32) -> Option<(f32, f32)> {
    let oc = ray.origin - center;
    let b = oc.dot(ray.dir);
    let c = oc.length_squared() - radius * radius;
    let disc = b * b - c;
    if disc <= 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    Some((-b - sq, -b + sq))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wyvill_kernel_has_its_defining_values() {
        let k = Kernel::Wyvill;
        assert!((k.value(0.0) - 1.0).abs() < 1e-6);
        assert!(k.value(1.0).abs() < 1e-6);
        assert!((k.value(0.25) - 0.5).abs() < 1e-6, "f(R/2) = 1/2");
        assert!(
            k.derivative(1.0 - 1e-7).abs() < 1e-5,
            "flat at the support boundary"
        );
    }

    #[test]
    fn validation_names_the_offending_ball() {
        let good = Metaball {
            center: Vec3::ZERO,
            radius: 1.0,
            strength: 1.0,
            color: Vec3::ONE,
        };
        let mut scene = MetaballScene {
            kernel: Kernel::Wyvill,
            balls: vec![good; 3],
        };
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
        scene.balls[1].radius = 0.0;
        assert!(matches!(
            scene.validate(10),
            Err(MetaballError::BadRadius { index: 1, .. })
        ));
        assert!(matches!(
            scene.validate(2),
            Err(MetaballError::TooMany { .. })
        ));
    }
}
