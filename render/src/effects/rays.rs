//! The closed set of ray kinds a frame traces, and rays counted per kind.

/// The closed set of ray kinds a frame traces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RayKind {
    /// From the camera.
    Primary,
    /// Towards a light point (hard) or a point of a sphere light (soft); any-hit.
    Shadow,
    /// Mirror reflection, and the Fresnel-reflected part at refractive surfaces.
    Reflection,
    /// Bent through a refractive surface.
    Refraction,
    /// Straight on behind a transparent surface (depth peeling).
    Transparency,
    /// Ambient occlusion; any-hit within the occlusion distance.
    Occlusion,
    /// Optical depth through an absorbing volume (one per traced segment).
    Volume,
}

impl RayKind {
    pub const ALL: [RayKind; 7] = [
        RayKind::Primary,
        RayKind::Shadow,
        RayKind::Reflection,
        RayKind::Refraction,
        RayKind::Transparency,
        RayKind::Occlusion,
        RayKind::Volume,
    ];

    pub fn name(self) -> &'static str {
        match self {
            RayKind::Primary => "primary",
            RayKind::Shadow => "shadow",
            RayKind::Reflection => "reflection",
            RayKind::Refraction => "refraction",
            RayKind::Transparency => "transparency",
            RayKind::Occlusion => "occlusion",
            RayKind::Volume => "volume",
        }
    }
}

/// Rays traced, per kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    pub counts: [u64; 7],
}

impl RayCounts {
    #[inline]
    pub fn bump(&mut self, kind: RayKind) {
        self.counts[kind as usize] += 1;
    }

    #[inline]
    pub fn add_n(&mut self, kind: RayKind, n: u64) {
        self.counts[kind as usize] += n;
    }

    pub fn get(&self, kind: RayKind) -> u64 {
        self.counts[kind as usize]
    }

    pub fn add(&mut self, other: &RayCounts) {
        for (a, b) in self.counts.iter_mut().zip(other.counts) {
            *a += b;
        }
    }

    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }
}
