//! Axis-aligned boxes and the ray–box slab test every tree of the engine uses.

use glam::Vec3;

/// An axis-aligned box; empty when `min > max` on some axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn around(center: Vec3, radius: f32) -> Aabb {
        Aabb {
            min: center - Vec3::splat(radius),
            max: center + Vec3::splat(radius),
        }
    }

    pub fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    pub fn intersection(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.max(o.min),
            max: self.max.min(o.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    pub fn area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let d = self.max - self.min;
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }

    /// Whether the sphere overlaps the box (closed).
    pub fn overlaps_sphere(&self, center: Vec3, radius: f32) -> bool {
        let d = center - center.clamp(self.min, self.max);
        !self.is_empty() && d.length_squared() <= radius * radius
    }

    pub fn contains_box(&self, o: &Aabb, slack: f32) -> bool {
        o.is_empty()
            || (o.min.cmpge(self.min - Vec3::splat(slack)).all()
                && o.max.cmple(self.max + Vec3::splat(slack)).all())
    }

    /// The ray's parameter range inside the box, given `1/dir`.
    #[inline]
    pub fn ray_range(
        &self,
        origin: Vec3,
        inv_dir: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32)> {
        slab(self.min, self.max, origin, inv_dir, t_min, t_max)
    }
}

/// The slab test: the range of `origin + t·dir` (given `inv_dir = 1/dir`) inside the box
/// `[lo, hi]`, clamped to `[t_min, t_max]`, if not empty. A ray parallel to a face and lying
/// in its plane gives a NaN slab (`0 · ∞`): glam's `min`/`max` are `a < b ? a : b`, which
/// keep a NaN only as the second operand, so by the axis and the face such a slab constrains
/// nothing, leaves the ray out, or drops the other axes' near bounds (the range then starts
/// at `t_min`); the final `f32::max`/`min` against `[t_min, t_max]` drop a NaN. Deterministic,
/// and only for rays exactly in a face's plane. The packets' lanes
/// (`kinds::metaballs::engine::slabs`) copy these operations bit for bit.
#[inline(always)]
pub fn slab(
    lo: Vec3,
    hi: Vec3,
    origin: Vec3,
    inv_dir: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<(f32, f32)> {
    let t0 = (lo - origin) * inv_dir;
    let t1 = (hi - origin) * inv_dir;
    #[cfg(isoray_mutation = "slab-infinities")]
    if !(t0.is_finite() && t1.is_finite()) {
        return None;
    }
    let near = t0.min(t1).max_element().max(t_min);
    let far = t0.max(t1).min_element().min(t_max);
    (near <= far).then_some((near, far))
}
