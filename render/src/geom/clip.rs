//! The clip box: the one region an effect or a query cuts away from the scene.

use glam::Vec3;

/// An axis-aligned box whose inside is cut away, exposing what lies within
/// (tetrahedral-isosurface-ray-tracing.txt §7, "Clipping Planes and Boxes"). A very large
/// extent on one side turns it into a clipping plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClipBox {
    pub min: Vec3,
    pub max: Vec3,
}

impl ClipBox {
    /// Where `origin + t·dir` is inside the box, if anywhere.
    #[inline]
    pub fn range(&self, origin: Vec3, dir: Vec3) -> Option<(f32, f32)> {
        let inv = dir.recip();
        let a = (self.min - origin) * inv;
        let b = (self.max - origin) * inv;
        let near = a.min(b).max_element();
        let far = a.max(b).min_element();
        (near <= far).then_some((near, far))
    }

    /// Whether `p` is inside the (closed) box.
    #[inline]
    pub fn contains(&self, p: Vec3) -> bool {
        self.min.cmple(p).all() && p.cmple(self.max).all()
    }

    /// Whether the box `[lo, hi]` lies wholly inside the clip box.
    #[inline]
    pub fn encloses(&self, lo: Vec3, hi: Vec3) -> bool {
        self.min.cmple(lo).all() && hi.cmple(self.max).all()
    }
}
