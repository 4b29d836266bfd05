//! A viewer's own look of a scene: its clip box, its further isosurfaces (each with a colour
//! and opacity) and a colour map of the isovalue, set by the `clip`, `surfaces` and
//! `color_map` fields of an `effects` message (or of a render request) and checked here at the
//! edge. The scene's lighting is never changed: [`Style::lighting`] gives a copy with the
//! viewer's choices in it, which the frame traces through
//! [`isoray_render::PreparedScene::with_lighting`]. A default style changes nothing, so every
//! image without one stays byte for byte what it was.

use crate::effects::EffectError;
use glam::Vec3;
use isoray_protocol::effects::{ClipBoxSpec, ColorMapSpec, EffectChanges, SurfaceStyleSpec};
use isoray_render::colormap::{ColorMap, ColorMapKind};
use isoray_render::geom::clip::ClipBox;
use isoray_render::shade::{Isosurface, Material};
use isoray_render::Lighting;

/// Most further isosurfaces a viewer may add.
pub const MAX_SURFACES: usize = 4;
/// Clip box corners stay within this distance of the origin.
const MAX_COORD: f64 = 1.0e6;

/// A viewer-added isosurface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceLook {
    pub isovalue: f32,
    pub color: Vec3,
    pub opacity: f32,
    /// The scene's own further isosurface whose material it is drawn with.
    pub scene_surface: Option<u16>,
}

/// What a viewer chose about the look of a scene; `None` fields keep the scene's own.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Style {
    pub clip: Option<ClipBox>,
    pub surfaces: Option<Vec<SurfaceLook>>,
    pub color_map: Option<ColorMap>,
}

impl Style {
    /// Whether the style changes nothing.
    pub fn is_default(&self) -> bool {
        *self == Style::default()
    }

    /// `scene` with this style applied, or `None` when the style changes nothing.
    pub fn lighting(&self, scene: &Lighting) -> Option<Lighting> {
        if self.is_default() {
            return None;
        }
        let mut l = scene.clone();
        if let Some(clip) = self.clip {
            l.clip_box = Some(clip);
        }
        if let Some(surfaces) = &self.surfaces {
            l.isosurfaces = surfaces
                .iter()
                .map(|s| {
                    // Each added surface gets a material of its own after the scene's: the
                    // scene has at most 64, so the index fits.
                    let material = u16::try_from(l.materials.len()).unwrap_or(u16::MAX);
                    let like = s
                        .scene_surface
                        .and_then(|i| scene.isosurfaces.get(usize::from(i)));
                    let (m, color) = match like {
                        // That surface's material, drawn in the kind's colours times the
                        // viewer's colour as the scene draws it (or in the viewer's colour
                        // where the scene gave the surface a colour of its own).
                        Some(like) => {
                            let mut m = *scene.material(like.material);
                            if like.color.is_none() {
                                m.diffuse = s.color;
                            }
                            (m, like.color.map(|_| s.color))
                        }
                        None => (Material::default(), Some(s.color)),
                    };
                    l.materials.push(Material {
                        opacity: s.opacity,
                        ..m
                    });
                    Isosurface {
                        isovalue: s.isovalue,
                        material,
                        color,
                    }
                })
                .collect();
        }
        l.color_map = self.color_map;
        Some(l)
    }
}

/// `style` with the `clip`, `surfaces` and `color_map` of `changes` applied, if every value is
/// valid: isovalues inside the open `isovalue_range`, a colour map's range defaulting to
/// `slider`. Nothing is applied otherwise.
pub fn apply(
    style: &Style,
    changes: &EffectChanges,
    isovalue_range: (f32, f32),
    slider: (f32, f32),
    scene_surfaces: usize,
) -> Result<Style, EffectError> {
    let mut out = style.clone();
    if let Some(clip) = &changes.clip {
        out.clip = Some(clip_box(clip)?);
    }
    if changes.scene_surfaces == Some(true) {
        if changes.surfaces.is_some() {
            return Err(relational(
                "scene_surfaces",
                "scene_surfaces: true returns to the scene's own isosurfaces; send it without surfaces"
                    .into(),
            ));
        }
        out.surfaces = None;
    }
    if let Some(surfaces) = &changes.surfaces {
        out.surfaces = Some(surface_looks(surfaces, isovalue_range, scene_surfaces)?);
    }
    if let Some(map) = &changes.color_map {
        out.color_map = color_map(map, slider)?;
    }
    Ok(out)
}

fn error(field: &'static str, message: String) -> EffectError {
    EffectError {
        field,
        message,
        relational: false,
    }
}

/// A rule between values, stated in the document's prose (422).
fn relational(field: &'static str, message: String) -> EffectError {
    EffectError {
        field,
        message,
        relational: true,
    }
}

fn clip_box(spec: &ClipBoxSpec) -> Result<ClipBox, EffectError> {
    let corners = spec.min.iter().chain(spec.max.iter());
    if !corners
        .clone()
        .all(|v| v.is_finite() && v.abs() <= MAX_COORD)
    {
        return Err(error(
            "clip",
            format!("clip corners must be finite and within ±{MAX_COORD}"),
        ));
    }
    // Finite (checked above), so `>=` also refuses equal corners.
    if (0..3).any(|i| spec.min[i] >= spec.max[i]) {
        return Err(relational(
            "clip",
            "clip: min must be below max on every axis".into(),
        ));
    }
    let v = |a: [f64; 3]| Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32);
    Ok(ClipBox {
        min: v(spec.min),
        max: v(spec.max),
    })
}

fn surface_looks(
    surfaces: &[SurfaceStyleSpec],
    (lo, hi): (f32, f32),
    scene_surfaces: usize,
) -> Result<Vec<SurfaceLook>, EffectError> {
    if surfaces.len() > MAX_SURFACES {
        return Err(error(
            "surfaces",
            format!(
                "surfaces: at most {MAX_SURFACES} further isosurfaces, not {}",
                surfaces.len()
            ),
        ));
    }
    surfaces
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let iso = s.isovalue as f32;
            if !(iso > lo && iso < hi) {
                return Err(relational(
                    "surfaces",
                    format!(
                        "surfaces[{i}].isovalue {} must be inside the scene's isovalue range ({lo}, {hi})",
                        s.isovalue
                    ),
                ));
            }
            if !s.color.iter().all(|c| (0.0..=1.0).contains(c)) {
                return Err(error(
                    "surfaces",
                    format!("surfaces[{i}].color channels must be in [0, 1]"),
                ));
            }
            if !(0.0..=1.0).contains(&s.opacity) {
                return Err(error(
                    "surfaces",
                    format!("surfaces[{i}].opacity {} must be in [0, 1]", s.opacity),
                ));
            }
            let scene_surface = match s.scene_surface {
                None => None,
                Some(k) if (k as usize) < scene_surfaces => u16::try_from(k).ok(),
                Some(k) => {
                    return Err(relational(
                        "surfaces",
                        format!(
                            "surfaces[{i}].scene_surface {k} names none of the scene's {scene_surfaces} further isosurfaces (info.effects.surfaces)"
                        ),
                    ))
                }
            };
            Ok(SurfaceLook {
                isovalue: iso,
                color: Vec3::new(s.color[0] as f32, s.color[1] as f32, s.color[2] as f32),
                opacity: s.opacity as f32,
                scene_surface,
            })
        })
        .collect()
}

fn color_map(spec: &ColorMapSpec, slider: (f32, f32)) -> Result<Option<ColorMap>, EffectError> {
    if spec.name == "none" {
        return Ok(None);
    }
    let Some(kind) = ColorMapKind::from_name(&spec.name) else {
        let names: Vec<&str> = ColorMapKind::ALL.iter().map(|k| k.name()).collect();
        return Err(error(
            "color_map",
            format!(
                "color_map.name `{}` is not one of {} or none",
                spec.name,
                names.join(", ")
            ),
        ));
    };
    let (lo, hi) = match spec.range {
        None => slider,
        Some([lo, hi]) => {
            if !(lo.is_finite() && hi.is_finite() && lo.abs() <= 1e30 && hi.abs() <= 1e30) {
                return Err(error(
                    "color_map",
                    "color_map.range must be two finite numbers, low below high".into(),
                ));
            }
            if lo >= hi {
                return Err(relational(
                    "color_map",
                    "color_map.range must be two finite numbers, low below high".into(),
                ));
            }
            (lo as f32, hi as f32)
        }
    };
    Ok(Some(ColorMap { kind, lo, hi }))
}

/// Refuses the look of a scalar field, further isosurfaces and a colour map of the isovalue,
/// for a scene that has none (surfels), where they would change nothing; `[]` and `none`,
/// which ask for nothing, pass.
pub fn refuse_without_field(changes: &EffectChanges) -> Result<(), EffectError> {
    if changes.surfaces.as_ref().is_some_and(|s| !s.is_empty()) {
        return Err(relational(
            "surfaces",
            "surfaces: a surfel scene has no scalar field, so no further isosurfaces".into(),
        ));
    }
    if changes.color_map.as_ref().is_some_and(|m| m.name != "none") {
        return Err(relational(
            "color_map",
            "color_map: a surfel scene has no scalar field to colour by".into(),
        ));
    }
    Ok(())
}

/// What a one-shot image's look starts from: the scene's lighting and its field.
pub struct SceneLook<'a> {
    pub lighting: &'a Lighting,
    /// The scene has a scalar field (not a surfel scene).
    pub has_field: bool,
    pub isovalue_range: (f32, f32),
    /// The isovalue slider's range (a colour map's default range).
    pub slider: (f32, f32),
}

/// The effects and the viewer's look of a one-shot image (the render endpoint's `effects`,
/// `isoray render --effects`): the scene's own effects within `limits` with `changes` applied,
/// and the style their `clip`, `surfaces` and `color_map` set, as a session's `effects`
/// message sets both; the first invalid value is the error.
pub fn one_shot(
    scene: &SceneLook,
    changes: Option<&EffectChanges>,
    limits: &crate::effects::EffectLimits,
) -> Result<(isoray_render::Effects, Style), EffectError> {
    let fx = crate::effects::clamp(&scene.lighting.effects, limits);
    let Some(changes) = changes else {
        return Ok((fx, Style::default()));
    };
    if !scene.has_field {
        refuse_without_field(changes)?;
    }
    let fx = crate::effects::apply(&fx, changes, limits)?;
    let own = scene.lighting.isosurfaces.len();
    let style = apply(
        &Style::default(),
        changes,
        scene.isovalue_range,
        scene.slider,
        own,
    )?;
    Ok((fx, style))
}

/// Refuses the viewer-only fields in a scene description's `lighting.effects`, naming the
/// scene's own field for each.
pub fn refuse_in_scene(changes: &EffectChanges) -> Result<(), EffectError> {
    if changes.clip.is_some() {
        return Err(error(
            "clip",
            "clip is a viewer's setting; a scene's clip box is lighting.clip_box".into(),
        ));
    }
    if changes.surfaces.is_some() {
        return Err(error(
            "surfaces",
            "surfaces is a viewer's setting; a scene's are lighting.isosurfaces".into(),
        ));
    }
    if changes.scene_surfaces.is_some() {
        return Err(error(
            "scene_surfaces",
            "scene_surfaces is a viewer's setting; a scene's are lighting.isosurfaces".into(),
        ));
    }
    if changes.color_map.is_some() {
        return Err(error(
            "color_map",
            "color_map is a viewer's setting, not a scene's".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn changes(json: &str) -> EffectChanges {
        serde_json::from_str(json).expect("parses")
    }

    #[test]
    fn a_default_style_leaves_the_lighting_alone() {
        assert!(Style::default().lighting(&Lighting::default()).is_none());
    }

    #[test]
    fn clip_surfaces_and_map_reach_the_lighting() {
        let c = changes(
            r#"{"clip":{"min":[-1,-2,-3],"max":[1,2,3]},
                "surfaces":[{"isovalue":0.4,"color":[1,0,0],"opacity":0.5}],
                "color_map":{"name":"viridis","range":[0,2]}}"#,
        );
        let s = apply(&Style::default(), &c, (0.0, 1.0), (0.1, 0.9), 0).expect("valid");
        let l = s.lighting(&Lighting::default()).expect("a style");
        let clip = l.clip_box.expect("clip");
        assert_eq!(
            (clip.min, clip.max),
            (Vec3::new(-1.0, -2.0, -3.0), Vec3::new(1.0, 2.0, 3.0))
        );
        assert_eq!(l.isosurfaces.len(), 1);
        let surface = l.isosurfaces[0];
        assert_eq!((surface.isovalue, surface.color), (0.4, Some(Vec3::X)));
        assert_eq!(l.materials[surface.material as usize].opacity, 0.5);
        let map = l.color_map.expect("map");
        assert_eq!(
            (map.kind, map.lo, map.hi),
            (ColorMapKind::Viridis, 0.0, 2.0)
        );
        // Without a range the map spans the slider; `none` removes it.
        let s = apply(
            &s,
            &changes(r#"{"color_map":{"name":"grey"}}"#),
            (0.0, 1.0),
            (0.1, 0.9),
            0,
        )
        .expect("valid");
        assert_eq!(s.color_map.map(|m| (m.lo, m.hi)), Some((0.1, 0.9)));
        let s = apply(
            &s,
            &changes(r#"{"color_map":{"name":"none"},"surfaces":[]}"#),
            (0.0, 1.0),
            (0.1, 0.9),
            0,
        )
        .expect("valid");
        assert_eq!(s.color_map, None);
        assert_eq!(s.surfaces, Some(Vec::new()));
    }

    #[test]
    fn bad_values_name_the_field_and_change_nothing() {
        for (json, field) in [
            (r#"{"clip":{"min":[1,0,0],"max":[0,1,1]}}"#, "clip"),
            (r#"{"clip":{"min":[0,0,0],"max":[1e9,1,1]}}"#, "clip"),
            (r#"{"surfaces":[{"isovalue":2}]}"#, "surfaces"),
            (
                r#"{"surfaces":[{"isovalue":0.5,"color":[2,0,0]}]}"#,
                "surfaces",
            ),
            (
                r#"{"surfaces":[{"isovalue":0.5,"opacity":-1}]}"#,
                "surfaces",
            ),
            (
                r#"{"surfaces":[{"isovalue":0.5},{"isovalue":0.5},{"isovalue":0.5},{"isovalue":0.5},{"isovalue":0.5}]}"#,
                "surfaces",
            ),
            (r#"{"color_map":{"name":"jet"}}"#, "color_map"),
            (
                r#"{"color_map":{"name":"grey","range":[1,1]}}"#,
                "color_map",
            ),
        ] {
            let e = apply(&Style::default(), &changes(json), (0.0, 1.0), (0.0, 1.0), 0)
                .expect_err(json);
            assert_eq!(e.field, field, "{json}: {}", e.message);
        }
        assert!(refuse_in_scene(&changes(r#"{"color_map":{"name":"grey"}}"#)).is_err());
        assert!(refuse_in_scene(&changes(r#"{"scene_surfaces":true}"#)).is_err());
        assert!(refuse_in_scene(&changes(r#"{"shadows":true}"#)).is_ok());
    }

    #[test]
    fn a_scene_without_a_field_refuses_its_look() {
        for json in [
            r#"{"surfaces":[{"isovalue":0.5}]}"#,
            r#"{"color_map":{"name":"viridis"}}"#,
        ] {
            let e = refuse_without_field(&changes(json)).expect_err(json);
            assert!(
                e.relational && e.message.contains("surfel"),
                "{json}: {e:?}"
            );
        }
        for json in [
            r#"{"surfaces":[]}"#,
            r#"{"color_map":{"name":"none"}}"#,
            r#"{"shadows":true,"scene_surfaces":true}"#,
        ] {
            refuse_without_field(&changes(json)).expect(json);
        }
    }

    #[test]
    fn scene_surfaces_returns_to_the_scenes_own() {
        let scene = Lighting {
            isosurfaces: vec![Isosurface {
                isovalue: 0.2,
                material: 0,
                color: None,
            }],
            ..Lighting::default()
        };
        let range = ((0.0, 1.0), (0.0, 1.0));
        let added = changes(r#"{"surfaces":[{"isovalue":0.7}],"color_map":{"name":"grey"}}"#);
        let s = apply(&Style::default(), &added, range.0, range.1, 0).expect("valid");
        let l = s.lighting(&scene).expect("a style");
        assert_eq!(
            l.isosurfaces.iter().map(|i| i.isovalue).collect::<Vec<_>>(),
            [0.7]
        );
        // Back to the scene's own surface; the colour map stays the viewer's.
        let reset = apply(
            &s,
            &changes(r#"{"scene_surfaces":true}"#),
            range.0,
            range.1,
            0,
        )
        .expect("valid");
        assert_eq!(reset.surfaces, None);
        let l = reset.lighting(&scene).expect("the map is still a style");
        assert_eq!(l.isosurfaces, scene.isosurfaces);
        assert_eq!(l.materials, scene.materials);
        // `false` changes nothing; with `surfaces` in the same message it is refused, and the
        // style stays as it was.
        let kept = apply(
            &s,
            &changes(r#"{"scene_surfaces":false}"#),
            range.0,
            range.1,
            0,
        );
        assert_eq!(kept.expect("valid"), s);
        let both = changes(r#"{"scene_surfaces":true,"surfaces":[{"isovalue":0.3}]}"#);
        let e = apply(&s, &both, range.0, range.1, 0).expect_err("both");
        assert_eq!((e.field, e.relational), ("scene_surfaces", true));
    }

    #[test]
    fn a_surface_like_the_scenes_keeps_its_material() {
        // Shells' translucent shell: a shiny material whose blue the balls' colours multiply.
        let shell = Material {
            diffuse: Vec3::new(0.4, 0.6, 1.0),
            specular: 0.9,
            shininess: 120.0,
            reflectivity: 0.2,
            opacity: 0.3,
            ..Material::default()
        };
        let scene = Lighting {
            materials: vec![Material::default(), shell],
            isosurfaces: vec![Isosurface {
                isovalue: 0.2,
                material: 1,
                color: None,
            }],
            ..Lighting::default()
        };
        let range = ((0.0, 1.0), (0.0, 1.0));
        // The shell moved and made more opaque, and a plain surface beside it.
        let edit = changes(
            r#"{"surfaces":[{"isovalue":0.3,"color":[0.4,0.6,1],"opacity":0.5,"scene_surface":0},
                            {"isovalue":0.6,"color":[1,0,0]}]}"#,
        );
        let s = apply(&Style::default(), &edit, range.0, range.1, 1).expect("valid");
        let l = s.lighting(&scene).expect("a style");
        let (like, plain) = (l.isosurfaces[0], l.isosurfaces[1]);
        assert_eq!((like.isovalue, like.color), (0.3, None));
        assert_eq!(
            *l.material(like.material),
            Material {
                opacity: 0.5,
                ..shell
            }
        );
        assert_eq!((plain.isovalue, plain.color), (0.6, Some(Vec3::X)));
        assert_eq!(*l.material(plain.material), Material::default());
        // The scene's materials stay, the added ones come after them.
        assert_eq!(l.materials[..2], scene.materials[..]);
        // An index past the scene's surfaces is refused, naming it, and nothing changes.
        let past = changes(r#"{"surfaces":[{"isovalue":0.3,"scene_surface":1}]}"#);
        let e = apply(&s, &past, range.0, range.1, 1).expect_err("no second surface");
        assert_eq!((e.field, e.relational), ("surfaces", true));
        assert!(e.message.contains("scene_surface 1"), "{}", e.message);
    }

    #[test]
    fn the_scenes_surfaces_sent_back_as_listed_are_drawn_as_the_scene_draws_them() {
        // What a client does when it adopts Shells' surfaces unchanged: each row of
        // `info.effects.surfaces` sent back with its index. Every surface must come out with
        // the scene's isovalue, colour and material (only the materials' indices differ).
        let scene = isoray_render::scenes::DemoScene::Shells
            .state_at(2.0)
            .lighting;
        let limits = crate::effects::EffectLimits {
            max_depth: 4,
            max_samples: 16,
            max_passes: 16,
        };
        let effects = isoray_render::Effects::OFF;
        let listed = crate::effects::info(&scene, 24, &effects, &limits).surfaces;
        let listed = listed.expect("Shells lists its surfaces");
        assert_eq!(listed.len(), scene.isosurfaces.len());
        let back: Vec<SurfaceStyleSpec> = (0u32..)
            .zip(listed)
            .map(|(k, s)| SurfaceStyleSpec {
                scene_surface: Some(k),
                ..s
            })
            .collect();
        let changes = EffectChanges {
            surfaces: Some(back),
            ..changes("{}")
        };
        let (range, slider) = ((0.0, 10.0), (0.1, 5.0));
        let own = scene.isosurfaces.len();
        let style = apply(&Style::default(), &changes, range, slider, own).expect("valid");
        let l = style.lighting(&scene).expect("a style");
        for (drawn, was) in l.isosurfaces.iter().zip(&scene.isosurfaces) {
            assert_eq!((drawn.isovalue, drawn.color), (was.isovalue, was.color));
            assert_eq!(l.material(drawn.material), scene.material(was.material));
        }
    }
}
