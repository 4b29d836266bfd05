//! The effects a session switches on and off, and their quality ([`Effects`]): plain
//! settings, which scenes carry as their defaults ([`crate::shade::Lighting::effects`]).

/// Most reflection/refraction bounces and transparency layers the engine traces.
pub const MAX_DEPTH: u32 = 16;
/// Most samples per pixel and pass of one stochastic effect.
pub const MAX_SAMPLES: u32 = 256;

/// A session's effect switches and quality settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Effects {
    /// Shadow rays towards every light.
    pub shadows: bool,
    /// Sphere lights sampled over their extent (otherwise from their centre).
    pub soft_shadows: bool,
    /// Mirror reflection rays.
    pub reflections: bool,
    /// Refraction rays with Fresnel weighting through transparent materials with IOR ≠ 1.
    pub refraction: bool,
    /// Transparent surfaces let the ray continue (depth peeling); volumes absorb.
    pub transparency: bool,
    /// Ambient-occlusion rays.
    pub ambient_occlusion: bool,
    /// The scene's clip box cuts its primitives.
    pub clip_box: bool,
    /// The scene's further isosurfaces are drawn.
    pub isosurfaces: bool,
    /// Reflection and refraction bounces.
    pub depth: u32,
    /// Transparent layers a ray passes through.
    pub layers: u32,
    /// Shadow rays per sphere light per pixel per pass.
    pub light_samples: u32,
    /// Occlusion rays per pixel per pass.
    pub ao_samples: u32,
}

impl Effects {
    /// Ray casting only, with the default quality for effects switched on later.
    pub const OFF: Effects = Effects {
        shadows: false,
        soft_shadows: false,
        reflections: false,
        refraction: false,
        transparency: false,
        ambient_occlusion: false,
        clip_box: false,
        isosurfaces: false,
        depth: 2,
        layers: 4,
        light_samples: 4,
        ao_samples: 4,
    };

    /// Every effect on, with the default quality.
    pub const ALL: Effects = Effects {
        shadows: true,
        soft_shadows: true,
        reflections: true,
        refraction: true,
        transparency: true,
        ambient_occlusion: true,
        clip_box: true,
        isosurfaces: true,
        ..Effects::OFF
    };

    /// Whether `kind` is switched on.
    pub fn enabled(&self, kind: EffectKind) -> bool {
        match kind {
            EffectKind::Shadows => self.shadows,
            EffectKind::SoftShadows => self.soft_shadows,
            EffectKind::Reflections => self.reflections,
            EffectKind::Refraction => self.refraction,
            EffectKind::Transparency => self.transparency,
            EffectKind::AmbientOcclusion => self.ambient_occlusion,
            EffectKind::ClipBox => self.clip_box,
            EffectKind::Isosurfaces => self.isosurfaces,
        }
    }

    /// Switches `kind` on or off.
    pub fn set(&mut self, kind: EffectKind, on: bool) {
        match kind {
            EffectKind::Shadows => self.shadows = on,
            EffectKind::SoftShadows => self.soft_shadows = on,
            EffectKind::Reflections => self.reflections = on,
            EffectKind::Refraction => self.refraction = on,
            EffectKind::Transparency => self.transparency = on,
            EffectKind::AmbientOcclusion => self.ambient_occlusion = on,
            EffectKind::ClipBox => self.clip_box = on,
            EffectKind::Isosurfaces => self.isosurfaces = on,
        }
    }
}

impl Default for Effects {
    fn default() -> Effects {
        Effects::OFF
    }
}

/// The closed set of effects a session can switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EffectKind {
    Shadows,
    SoftShadows,
    Reflections,
    Refraction,
    Transparency,
    AmbientOcclusion,
    ClipBox,
    Isosurfaces,
}

impl EffectKind {
    pub const ALL: [EffectKind; 8] = [
        EffectKind::Shadows,
        EffectKind::SoftShadows,
        EffectKind::Reflections,
        EffectKind::Refraction,
        EffectKind::Transparency,
        EffectKind::AmbientOcclusion,
        EffectKind::ClipBox,
        EffectKind::Isosurfaces,
    ];

    /// The name used on the wire.
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::Shadows => "shadows",
            EffectKind::SoftShadows => "soft_shadows",
            EffectKind::Reflections => "reflections",
            EffectKind::Refraction => "refraction",
            EffectKind::Transparency => "transparency",
            EffectKind::AmbientOcclusion => "ambient_occlusion",
            EffectKind::ClipBox => "clip_box",
            EffectKind::Isosurfaces => "isosurfaces",
        }
    }

    pub fn from_name(name: &str) -> Option<EffectKind> {
        EffectKind::ALL.into_iter().find(|k| k.name() == name)
    }
}
