//! The effects plan: which kinds of rays a frame traces, and how deep.
//!
//! A session switches effects on and off and picks their quality ([`Effects`]); a scene
//! declares its lights and materials ([`Lighting`]). [`EffectsPlan::new`] combines both with the
//! primitives that exist and keeps only the rays some visible material needs: reflections
//! with no reflective material, refraction with no transparent one, or shadows with no light
//! plan no rays at all, so the integrator never generates them and the frame costs what ray
//! casting alone costs. The seeds trace the same secondary rays through the same structures:
//! fitted-bvh-metaballs.txt Table 2 and Fig. 8 (shadows, reflections, Fresnel, occlusion),
//! bezier-clipping-metaballs.txt §5 (transparent volumetric blobs) and
//! tetrahedral-isosurface-ray-tracing.txt §7 (shadows, multiple transparent isosurfaces, clip
//! box, depth-peeled transparency).

use crate::effects::toggles::{EffectKind, Effects, MAX_DEPTH, MAX_SAMPLES};
use crate::geom::clip::ClipBox;
use crate::geom::rng::Sampling;
use crate::shade::{Light, Lighting, Material};

/// What one frame traces, derived from the scene's lighting and the session's effects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EffectsPlan {
    /// Shadow rays towards the lights.
    pub shadows: bool,
    /// Sphere lights are sampled over their extent (otherwise shadowed from their centre).
    pub soft_shadows: bool,
    /// Shadow rays per sphere light per pass when `soft_shadows`.
    pub light_samples: u32,
    /// Reflection bounces (0: no reflection rays).
    pub reflection_depth: u32,
    /// Refraction bounces (0: no refraction rays).
    pub refraction_depth: u32,
    /// Transparent layers passed straight through (0: transparent surfaces look opaque).
    pub layers: u32,
    /// Occlusion rays per pass (0: none).
    pub ao_samples: u32,
    /// The field is an absorbing volume rather than a surface.
    pub volume: bool,
    pub clip_box: Option<ClipBox>,
    /// The scene's further isosurfaces are traced.
    pub isosurfaces: bool,
    /// How soft shadows and occlusion draw their sample points (stratified across passes
    /// unless a comparison asks for independent ones).
    pub sampling: Sampling,
}

impl EffectsPlan {
    /// Ray casting only.
    pub const PRIMARY_ONLY: EffectsPlan = EffectsPlan {
        shadows: false,
        soft_shadows: false,
        light_samples: 0,
        reflection_depth: 0,
        refraction_depth: 0,
        layers: 0,
        ao_samples: 0,
        volume: false,
        clip_box: None,
        isosurfaces: false,
        sampling: Sampling::Stratified,
    };

    /// The rays `effects` calls for on a scene lit and shaded by `lighting` whose geometry has
    /// `primitive_count` primitives. Only materials that some primitive (or the floor, or a
    /// drawn isosurface) uses count.
    pub fn new(lighting: &Lighting, primitive_count: usize, effects: &Effects) -> EffectsPlan {
        let isosurfaces = effects.isosurfaces && !lighting.isosurfaces.is_empty();
        let volume = effects.transparency && primitive_count > 0 && lighting.has_volume();
        let mut visible = if volume {
            // The field is not a surface then: only the floor's material shows.
            lighting.floor.map(|f| vec![f.material]).unwrap_or_default()
        } else {
            lighting.visible_materials(primitive_count)
        };
        if isosurfaces && !volume && primitive_count > 0 {
            visible.extend(lighting.isosurfaces.iter().map(|s| s.material));
        }
        let materials: Vec<_> = visible.iter().map(|&m| *lighting.material(m)).collect();
        let any = |f: &dyn Fn(&Material) -> bool| materials.iter().any(f);
        let lit_receivers = any(&|m| m.receives_light());
        let lights: Vec<&Light> = lighting.lights.iter().filter(|l| l.is_lit()).collect();
        let something_casts = primitive_count > 0 || lighting.floor.is_some();

        let shadows = effects.shadows && !lights.is_empty() && lit_receivers && something_casts;
        let has_sphere = lights.iter().any(|l| matches!(l, Light::Sphere { .. }));
        let soft_shadows = shadows && has_sphere && effects.soft_shadows;
        let light_samples = if soft_shadows {
            effects.light_samples.clamp(1, MAX_SAMPLES)
        } else {
            0
        };
        let depth = effects.depth.min(MAX_DEPTH);
        let transparent = effects.transparency && any(&|m| m.is_transparent());
        let refractive = transparent && effects.refraction && any(&|m| m.is_refractive());
        let reflection_depth = if effects.reflections && any(&|m| m.is_reflective()) {
            depth
        } else {
            0
        };
        let refraction_depth = if refractive { depth } else { 0 };
        let layers = if transparent {
            effects.layers.min(MAX_DEPTH)
        } else {
            0
        };
        let ao_samples = if effects.ambient_occlusion
            && lighting.ambient.max_element() > 0.0
            && any(&|m| m.diffuse.max_element() > 0.0)
            && lighting.occlusion_distance > 0.0
            && something_casts
        {
            effects.ao_samples.min(MAX_SAMPLES)
        } else {
            0
        };
        let clip_box = if effects.clip_box && primitive_count > 0 {
            lighting.clip_box
        } else {
            None
        };
        EffectsPlan {
            shadows,
            soft_shadows,
            light_samples,
            reflection_depth,
            refraction_depth,
            layers,
            ao_samples,
            volume,
            clip_box,
            isosurfaces: isosurfaces && !volume && primitive_count > 0,
            sampling: Sampling::Stratified,
        }
    }

    /// Whether frames differ from one pass to the next (soft shadows or occlusion sample),
    /// so that accumulating passes refines the image.
    pub fn is_stochastic(&self) -> bool {
        self.soft_shadows || self.ao_samples > 0
    }

    /// Whether only primary rays are traced.
    pub fn is_primary_only(&self) -> bool {
        let sampling = EffectsPlan::PRIMARY_ONLY.sampling;
        EffectsPlan { sampling, ..*self } == EffectsPlan::PRIMARY_ONLY
    }

    /// The effects of `kind` this plan actually traces.
    pub fn uses(&self, kind: EffectKind) -> bool {
        match kind {
            EffectKind::Shadows => self.shadows,
            EffectKind::SoftShadows => self.soft_shadows,
            EffectKind::Reflections => self.reflection_depth > 0,
            EffectKind::Refraction => self.refraction_depth > 0,
            EffectKind::Transparency => self.layers > 0 || self.volume,
            EffectKind::AmbientOcclusion => self.ao_samples > 0,
            EffectKind::ClipBox => self.clip_box.is_some(),
            EffectKind::Isosurfaces => self.isosurfaces,
        }
    }
}

/// The effects a scene can use at all: those a plan with every effect on traces.
pub fn available_effects(lighting: &Lighting, primitive_count: usize) -> Vec<EffectKind> {
    let all = Effects {
        light_samples: 2,
        ao_samples: 1,
        depth: 1,
        layers: 1,
        ..Effects::ALL
    };
    let plan = EffectsPlan::new(lighting, primitive_count, &all);
    EffectKind::ALL
        .into_iter()
        .filter(|&k| plan.uses(k))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shade::{Material, MaterialGroup};
    use glam::Vec3;

    #[test]
    fn unusable_effects_plan_no_rays() {
        let lighting = Lighting::default();
        // One directional light, one opaque, non-reflective material.
        let plan = EffectsPlan::new(&lighting, 10, &Effects::ALL);
        assert!(plan.shadows);
        assert!(!plan.soft_shadows, "no sphere light");
        assert_eq!(plan.reflection_depth, 0, "nothing reflects");
        assert_eq!(plan.refraction_depth, 0, "nothing is transparent");
        assert_eq!(plan.layers, 0);
        assert!(!plan.volume && plan.clip_box.is_none() && !plan.isosurfaces);
        let dark = Lighting {
            lights: Vec::new(),
            ..Lighting::default()
        };
        let plan = EffectsPlan::new(&dark, 10, &Effects::ALL);
        assert!(!plan.shadows, "no light, no shadow rays");
        assert_eq!(
            available_effects(&lighting, 10),
            vec![EffectKind::Shadows, EffectKind::AmbientOcclusion]
        );
    }

    #[test]
    fn only_visible_materials_count() {
        let mut lighting = Lighting::default();
        lighting.materials.push(Material {
            reflectivity: 0.8,
            opacity: 0.5,
            ior: 1.5,
            ..Material::default()
        });
        lighting.groups.push(MaterialGroup {
            first: 100,
            count: 10,
            material: 1,
        });
        let effects = Effects {
            depth: 3,
            ..Effects::ALL
        };
        let hidden = EffectsPlan::new(&lighting, 50, &effects);
        assert_eq!(
            (
                hidden.reflection_depth,
                hidden.refraction_depth,
                hidden.layers
            ),
            (0, 0, 0),
            "the mirror glass group has no primitive in this state"
        );
        let shown = EffectsPlan::new(&lighting, 105, &effects);
        assert_eq!(
            (shown.reflection_depth, shown.refraction_depth, shown.layers),
            (3, 3, 4)
        );
        let no_refraction = Effects {
            refraction: false,
            ..effects
        };
        assert_eq!(
            EffectsPlan::new(&lighting, 105, &no_refraction).refraction_depth,
            0
        );
    }

    #[test]
    fn soft_shadows_need_a_sphere_light() {
        let mut lighting = Lighting::default();
        lighting.lights.push(Light::Sphere {
            center: Vec3::Y * 5.0,
            radius: 1.0,
            color: Vec3::ONE,
        });
        let effects = Effects {
            light_samples: 8,
            ..Effects::ALL
        };
        let plan = EffectsPlan::new(&lighting, 1, &effects);
        assert!(plan.soft_shadows);
        assert_eq!(plan.light_samples, 8);
        assert!(plan.is_stochastic());
        let hard = Effects {
            soft_shadows: false,
            ambient_occlusion: false,
            ..effects
        };
        let plan = EffectsPlan::new(&lighting, 1, &hard);
        assert!(plan.shadows && !plan.soft_shadows);
        assert!(!plan.is_stochastic());
        assert!(EffectsPlan::new(&lighting, 1, &Effects::OFF).is_primary_only());
        // A floor is scene geometry, not an effect: ray casting alone draws it (the fast path).
        let floored = Lighting {
            floor: Some(crate::shade::Floor {
                height: -1.0,
                material: 0,
                colors: [Vec3::ONE, Vec3::ZERO],
                checker: 1.0,
            }),
            ..lighting
        };
        let plan = EffectsPlan::new(&floored, 1, &Effects::OFF);
        assert!(plan.is_primary_only());
    }
}
