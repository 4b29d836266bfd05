//! Effects at the server's edge: the configured limits, checking and applying a client's (or a
//! scene description's) effect changes, and the `effects` part of `info`.

use isoray_protocol::effects::{
    ClipBoxSpec, EffectChanges, EffectSettings, EffectsInfo, SurfaceStyleSpec,
};
use isoray_render::effects::available_effects;
use isoray_render::{Effects, Lighting};

/// The largest quality settings a client or scene may ask for (`--max-ray-depth`,
/// `--max-samples`) and the passes a still view refines for (`--max-refine-passes`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EffectLimits {
    pub max_depth: u32,
    pub max_samples: u32,
    pub max_passes: u32,
}

impl EffectLimits {
    /// The engine's own ceilings: what a stored scene is checked against on reload.
    pub const ENGINE: EffectLimits = EffectLimits {
        max_depth: isoray_render::effects::MAX_DEPTH,
        max_samples: isoray_render::effects::MAX_SAMPLES,
        max_passes: 4096,
    };

    pub fn from_config(config: &crate::config::Config) -> EffectLimits {
        EffectLimits {
            max_depth: config.max_ray_depth,
            max_samples: config.max_samples,
            max_passes: config.max_refine_passes,
        }
    }
}

/// A change that breaks a limit: the field (relative to the changes object) and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EffectError {
    pub field: &'static str,
    pub message: String,
    /// The value fits the OpenAPI document's schema but breaks a rule between values (min
    /// below max, an isovalue inside the scene's range): a 422 rather than a 400.
    pub relational: bool,
}

/// `effects` with `changes` applied, if every value is within `limits`; nothing is applied
/// otherwise.
pub fn apply(
    effects: &Effects,
    changes: &EffectChanges,
    limits: &EffectLimits,
) -> Result<Effects, EffectError> {
    let mut out = *effects;
    let switches = [
        (changes.shadows, &mut out.shadows),
        (changes.soft_shadows, &mut out.soft_shadows),
        (changes.reflections, &mut out.reflections),
        (changes.refraction, &mut out.refraction),
        (changes.transparency, &mut out.transparency),
        (changes.ambient_occlusion, &mut out.ambient_occlusion),
        (changes.clip_box, &mut out.clip_box),
        (changes.isosurfaces, &mut out.isosurfaces),
    ];
    for (change, slot) in switches {
        if let Some(on) = change {
            *slot = on;
        }
    }
    let quality = [
        ("depth", changes.depth, 0, limits.max_depth, &mut out.depth),
        (
            "layers",
            changes.layers,
            0,
            limits.max_depth,
            &mut out.layers,
        ),
        (
            "light_samples",
            changes.light_samples,
            1,
            limits.max_samples,
            &mut out.light_samples,
        ),
        (
            "ao_samples",
            changes.ao_samples,
            1,
            limits.max_samples,
            &mut out.ao_samples,
        ),
    ];
    for (field, change, lo, hi, slot) in quality {
        if let Some(v) = change {
            if !(lo..=hi).contains(&v) {
                return Err(EffectError {
                    field,
                    relational: false,
                    message: format!(
                        "{field} {v} is outside {lo}..={hi} (the server's configured maximum)"
                    ),
                });
            }
            *slot = v;
        }
    }
    Ok(out)
}

/// The wire form of a session's effects.
pub fn settings(e: &Effects) -> EffectSettings {
    EffectSettings {
        shadows: e.shadows,
        soft_shadows: e.soft_shadows,
        reflections: e.reflections,
        refraction: e.refraction,
        transparency: e.transparency,
        ambient_occlusion: e.ambient_occlusion,
        clip_box: e.clip_box,
        isosurfaces: e.isosurfaces,
        depth: e.depth,
        layers: e.layers,
        light_samples: e.light_samples,
        ao_samples: e.ao_samples,
    }
}

/// `info.effects` for a scene lit by `lighting` with `primitives` primitives.
pub fn info(
    lighting: &Lighting,
    primitives: usize,
    effects: &Effects,
    limits: &EffectLimits,
) -> EffectsInfo {
    EffectsInfo {
        available: available_effects(lighting, primitives)
            .into_iter()
            .map(|k| k.name().to_string())
            .collect(),
        settings: settings(effects),
        max_depth: limits.max_depth,
        max_samples: limits.max_samples,
        max_passes: limits.max_passes,
        volume: lighting.has_volume(),
        clip: lighting.clip_box.map(|c| ClipBoxSpec {
            min: c.min.to_array().map(decimal),
            max: c.max.to_array().map(decimal),
        }),
        surfaces: (!lighting.isosurfaces.is_empty()).then(|| {
            lighting
                .isosurfaces
                .iter()
                .map(|s| {
                    let material = lighting.material(s.material);
                    SurfaceStyleSpec {
                        isovalue: decimal(s.isovalue),
                        color: s.color.unwrap_or(material.diffuse).to_array().map(decimal),
                        opacity: decimal(material.opacity),
                        scene_surface: None,
                    }
                })
                .collect()
        }),
    }
}

/// `v` as the shortest decimal that reads back as it (`0.15f32` as `0.15`, not
/// `0.15000000596046448`), for values a client shows.
fn decimal(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::from(v))
}

/// A scene's starting effects, clamped to `limits` (a scene may ask for more than a server
/// allows; viewers then start at the server's limit).
pub fn clamp(effects: &Effects, limits: &EffectLimits) -> Effects {
    Effects {
        depth: effects.depth.min(limits.max_depth),
        layers: effects.layers.min(limits.max_depth),
        light_samples: effects.light_samples.clamp(1, limits.max_samples.max(1)),
        ao_samples: effects.ao_samples.clamp(1, limits.max_samples.max(1)),
        ..*effects
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use isoray_render::shade::{Isosurface, Material};

    const LIMITS: EffectLimits = EffectLimits {
        max_depth: 4,
        max_samples: 16,
        max_passes: 8,
    };

    #[test]
    fn info_gives_the_scene_clip_box_where_it_has_one() {
        let mut lighting = Lighting::default();
        assert_eq!(info(&lighting, 1, &Effects::OFF, &LIMITS).clip, None);
        lighting.clip_box = Some(isoray_render::geom::clip::ClipBox {
            min: glam::Vec3::new(-1.0, -2.0, 0.5),
            max: glam::Vec3::new(1.0, 2.0, 3.25),
        });
        let clip = info(&lighting, 1, &Effects::OFF, &LIMITS).clip;
        assert_eq!(
            clip,
            Some(ClipBoxSpec {
                min: [-1.0, -2.0, 0.5],
                max: [1.0, 2.0, 3.25],
            })
        );
    }

    #[test]
    fn info_says_where_the_field_is_drawn_as_a_volume() {
        use isoray_render::shade::Volume;
        let mut lighting = Lighting::default();
        assert!(!info(&lighting, 1, &Effects::OFF, &LIMITS).volume);
        for (density, drawn) in [(0.8, true), (0.0, false), (f32::INFINITY, false)] {
            lighting.volume = Some(Volume {
                density,
                color: glam::Vec3::ONE,
            });
            assert_eq!(
                info(&lighting, 1, &Effects::OFF, &LIMITS).volume,
                drawn,
                "{density}"
            );
        }
        let clouds = isoray_render::scenes::DemoScene::Clouds
            .state_at(1.0)
            .lighting;
        assert!(info(&clouds, 40, &Effects::OFF, &LIMITS).volume);
    }

    #[test]
    fn info_lists_the_scenes_own_isosurfaces() {
        let mut lighting = Lighting::default();
        assert_eq!(info(&lighting, 1, &Effects::OFF, &LIMITS).surfaces, None);
        lighting.materials = vec![
            Material::default(),
            Material {
                diffuse: glam::Vec3::new(0.25, 0.5, 1.0),
                opacity: 0.3,
                ..Material::default()
            },
        ];
        lighting.isosurfaces = vec![
            Isosurface {
                isovalue: 0.15,
                material: 1,
                color: None,
            },
            Isosurface {
                isovalue: 2.0,
                material: 0,
                color: Some(glam::Vec3::new(0.0, 1.0, 0.5)),
            },
        ];
        let surfaces = info(&lighting, 1, &Effects::OFF, &LIMITS).surfaces;
        assert_eq!(
            surfaces,
            Some(vec![
                SurfaceStyleSpec {
                    isovalue: 0.15,
                    color: [0.25, 0.5, 1.0],
                    opacity: 0.3,
                    scene_surface: None,
                },
                SurfaceStyleSpec {
                    isovalue: 2.0,
                    color: [0.0, 1.0, 0.5],
                    opacity: 1.0,
                    scene_surface: None,
                },
            ])
        );
    }

    #[test]
    fn changes_apply_or_name_the_field_and_change_nothing() {
        let base = Effects::OFF;
        let on = apply(
            &base,
            &EffectChanges {
                shadows: Some(true),
                depth: Some(3),
                ..Default::default()
            },
            &LIMITS,
        )
        .expect("valid");
        assert!(on.shadows && on.depth == 3 && !on.reflections);
        for (changes, field) in [
            (
                EffectChanges {
                    depth: Some(5),
                    ..Default::default()
                },
                "depth",
            ),
            (
                EffectChanges {
                    shadows: Some(true),
                    layers: Some(99),
                    ..Default::default()
                },
                "layers",
            ),
            (
                EffectChanges {
                    light_samples: Some(0),
                    ..Default::default()
                },
                "light_samples",
            ),
            (
                EffectChanges {
                    ao_samples: Some(17),
                    ..Default::default()
                },
                "ao_samples",
            ),
        ] {
            let e = apply(&base, &changes, &LIMITS).expect_err(field);
            assert_eq!(e.field, field);
            assert!(e.message.contains(field), "{}", e.message);
        }
    }
}
