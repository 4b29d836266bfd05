//! Effects and scene shading on the wire: what a scene description may say about materials,
//! groups, floor, clip box, extra isosurfaces and volumes (inside
//! [`crate::api::LightingSpec`]), the `effects` client message, and the `effects` part of
//! `info`. Serde shapes only; the server checks every value (finite, in range, within its
//! configured limits) and converts to engine types at its edge.

use serde::{Deserialize, Serialize};

/// Which effects to switch and how well to render them; absent fields stay as they are.
/// Used by the `effects` client message and by a scene's `lighting.effects` (the effects its
/// viewers start with).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct EffectChanges {
    /// Shadow rays towards every light.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shadows: Option<bool>,
    /// Sphere lights sampled over their extent, refined while the view rests.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub soft_shadows: Option<bool>,
    /// Mirror reflection.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reflections: Option<bool>,
    /// Refraction with Fresnel weighting (materials with `ior` > 1 and `opacity` < 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refraction: Option<bool>,
    /// Transparent surfaces (depth peeling) and absorbing volumes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transparency: Option<bool>,
    /// Ambient occlusion, refined while the view rests.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient_occlusion: Option<bool>,
    /// The scene's clip box cuts its primitives.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip_box: Option<bool>,
    /// The scene's further isosurfaces.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub isosurfaces: Option<bool>,
    /// Reflection and refraction bounces, `0..=max_depth`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<u32>,
    /// Transparent layers a ray passes through, `0..=max_depth`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layers: Option<u32>,
    /// Shadow rays per sphere light per pixel and pass, `1..=max_samples`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_samples: Option<u32>,
    /// Ambient-occlusion rays per pixel and pass, `1..=max_samples`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ao_samples: Option<u32>,
    /// A viewer's own clip box in place of the scene's (`clip_box` switches it); finite, `min`
    /// below `max` on every axis. Not in a scene description (that has `lighting.clip_box`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<ClipBoxSpec>,
    /// A viewer's own further isosurfaces in place of the scene's (`isosurfaces` switches
    /// them), at most 4, each with its colour and opacity; `[]` draws none. Not in a scene
    /// description (that has `lighting.isosurfaces`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surfaces: Option<Vec<SurfaceStyleSpec>>,
    /// `true`: the scene's own further isosurfaces again in place of the viewer's `surfaces`
    /// (not with `surfaces` in the same message); `false` changes nothing. Not in a scene
    /// description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene_surfaces: Option<bool>,
    /// Colour every isosurface by its value through a colour map; `{"name": "none"}` returns
    /// to the scene's own colours. Not in a scene description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color_map: Option<ColorMapSpec>,
}

/// A further isosurface a viewer adds, with its own look.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SurfaceStyleSpec {
    /// Inside the scene's isovalue range.
    pub isovalue: f64,
    /// Linear-light diffuse colour, each channel in `[0, 1]` (a colour map, when set, wins).
    #[serde(default = "ones")]
    pub color: [f64; 3],
    /// `[0, 1]`; below 1 the surface is transparent (with `transparency` on).
    #[serde(default = "one")]
    pub opacity: f64,
    /// Which of the scene's own further isosurfaces (an index into `info.effects.surfaces`)
    /// this one is drawn like: with that surface's material at this isovalue, `color` in place
    /// of the material's diffuse colour (the scene's own colours multiply it, as they do the
    /// scene's surface) and this opacity. Absent: a plain surface of `color`. Not in
    /// `info.effects.surfaces`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene_surface: Option<u32>,
}

/// A colour map of the isovalue: `name` is `viridis`, `inferno`, `cool_warm`, `grey` or
/// `none`; `range` (low below high, finite) defaults to the scene's isovalue slider range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ColorMapSpec {
    pub name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
}

/// A session's effects, in full.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectSettings {
    pub shadows: bool,
    pub soft_shadows: bool,
    pub reflections: bool,
    pub refraction: bool,
    pub transparency: bool,
    pub ambient_occlusion: bool,
    pub clip_box: bool,
    pub isosurfaces: bool,
    pub depth: u32,
    pub layers: u32,
    pub light_samples: u32,
    pub ao_samples: u32,
}

/// The `effects` part of `info`: what the scene can use, what is on, and the limits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectsInfo {
    /// The effects this scene's lights and materials can use, by name (`shadows`,
    /// `soft_shadows`, `reflections`, `refraction`, `transparency`, `ambient_occlusion`,
    /// `clip_box`, `isosurfaces`). Switching on any other changes nothing and costs nothing.
    pub available: Vec<String>,
    /// The session's effects now.
    pub settings: EffectSettings,
    /// Largest `depth` and `layers`.
    pub max_depth: u32,
    /// Largest `light_samples` and `ao_samples`.
    pub max_samples: u32,
    /// Refinement passes a still view accumulates at most.
    pub max_passes: u32,
    /// Whether the scene's field is drawn as an absorbing volume while `transparency` is on:
    /// there is no isosurface then, so the isovalue, further isosurfaces and a colour map show
    /// only with `transparency` off.
    #[serde(default)]
    pub volume: bool,
    /// The scene's own clip box (`lighting.clip_box`), which `clip_box` switches until the
    /// viewer sets a `clip` of its own; absent when the scene has none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<ClipBoxSpec>,
    /// The scene's own further isosurfaces (`lighting.isosurfaces`), which `isosurfaces`
    /// switches until the viewer sets `surfaces` of its own: each one's isovalue, its
    /// material's diffuse colour (the scene's own colours multiply it) and opacity. Absent
    /// when the scene has none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surfaces: Option<Vec<SurfaceStyleSpec>>,
}

/// The `effects` client message: switch effects and set their quality.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectsInput {
    pub input_id: crate::version::InputId,
    pub effects: EffectChanges,
}

/// The kind of a light.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum LightKind {
    /// Infinitely far; needs `to_light`.
    #[default]
    Directional,
    /// A point; needs `position`.
    Point,
    /// A uniformly emitting sphere, an area light with soft shadows; needs `position` and
    /// `radius`.
    Sphere,
}

/// How a group of primitives (or the floor, or an isosurface) looks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Linear-light diffuse colour in `[0, 1]`, multiplied with each primitive's own colour.
    #[serde(default = "ones")]
    pub diffuse: [f64; 3],
    /// Weight of the specular lobe, `[0, 1]`.
    #[serde(default = "default_specular")]
    pub specular: f64,
    /// Specular exponent, `[1, 10000]`.
    #[serde(default = "default_shininess")]
    pub shininess: f64,
    /// Mirror share, `[0, 1]`.
    #[serde(default)]
    pub reflectivity: f64,
    /// Index of refraction, `[1, 4]`.
    #[serde(default = "one")]
    pub ior: f64,
    /// `[0, 1]`; below 1 the surface is transparent.
    #[serde(default = "one")]
    pub opacity: f64,
    /// Emitted linear-light radiance, each channel `[0, 1000]`.
    #[serde(default)]
    pub emission: [f64; 3],
}

fn ones() -> [f64; 3] {
    [1.0; 3]
}
fn one() -> f64 {
    1.0
}
fn default_specular() -> f64 {
    0.35
}
fn default_shininess() -> f64 {
    48.0
}

impl Default for MaterialSpec {
    fn default() -> MaterialSpec {
        MaterialSpec {
            diffuse: ones(),
            specular: default_specular(),
            shininess: default_shininess(),
            reflectivity: 0.0,
            ior: 1.0,
            opacity: 1.0,
            emission: [0.0; 3],
        }
    }
}

/// Primitives `first .. first + count` (by index in each step) use `materials[material]`;
/// the rest use `materials[0]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct GroupSpec {
    pub first: u32,
    pub count: u32,
    pub material: u16,
}

/// A horizontal floor plane `y = height`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct FloorSpec {
    pub height: f64,
    /// Index into `materials`.
    #[serde(default)]
    pub material: u16,
    /// Linear-light colours of the two kinds of checker squares, `[0, 1]`.
    #[serde(default = "floor_colors")]
    pub colors: [[f64; 3]; 2],
    /// Edge of a checker square; 0 for a plain floor.
    #[serde(default)]
    pub checker: f64,
}

fn floor_colors() -> [[f64; 3]; 2] {
    [[0.6; 3], [0.3; 3]]
}

/// An axis-aligned box whose inside is cut away.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ClipBoxSpec {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// A further isosurface of the field, with its own material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct IsosurfaceSpec {
    pub isovalue: f64,
    #[serde(default)]
    pub material: u16,
}

/// Render the field as an absorbing volume (when transparency is on).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct VolumeSpec {
    /// Extinction per unit of field and length, `> 0`.
    pub density: f64,
    /// Linear-light radiance the lit volume scatters towards the viewer, `[0, 1]`.
    #[serde(default = "ones")]
    pub color: [f64; 3],
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effects_message_shape() {
        let m: crate::messages::ClientMessage = serde_json::from_str(
            r#"{"type":"effects","input_id":4,"effects":{"shadows":true,"depth":3}}"#,
        )
        .expect("parses");
        let crate::messages::ClientMessage::Effects(e) = m else {
            panic!("effects message")
        };
        assert_eq!(e.effects.shadows, Some(true));
        assert_eq!(e.effects.depth, Some(3));
        assert_eq!(e.effects.reflections, None);
        assert!(serde_json::from_str::<EffectChanges>(r#"{"shadow":true}"#).is_err());
        assert!(serde_json::from_str::<EffectChanges>(r#"{"depth":-1}"#).is_err());
        let m: MaterialSpec = serde_json::from_str(r#"{"ior":1.5}"#).expect("defaults");
        assert_eq!((m.ior, m.opacity, m.diffuse), (1.5, 1.0, [1.0; 3]));
    }
}
