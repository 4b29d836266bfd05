//! From API types to engine types, validating at the boundary: every non-finite or
//! out-of-range value is refused with the field that holds it. What depends on the scene's
//! kind is in the kind's own module beside this one.

use crate::effects::EffectLimits;
use crate::kinds::error::KindError;
use glam::Vec3;
use isoray_protocol::api::{
    ApiCamera, IsosurfaceSpec, LightKind, LightSpec, LightingSpec, MaterialSpec,
};
use isoray_render::shade::{ClipBox, Floor, Isosurface, Light, Material, MaterialGroup, Volume};
use isoray_render::{Camera, Lighting};

/// Largest coordinate accepted: keeps values exact enough in f32.
const MAX_COORDINATE: f64 = 1.0e6;

pub fn finite(v: f64, field: &str) -> Result<f32, KindError> {
    if v.is_finite() && v.abs() <= MAX_COORDINATE {
        Ok(v as f32)
    } else {
        Err(KindError::invalid(
            "invalid_value",
            format!("{field} is {v}; it must be a finite number of magnitude at most 1e6"),
        )
        .field(field))
    }
}

/// `v` as `f32`, infinite when it is beyond `f32`'s range (rather than rounded to its largest
/// value), so the check for finite values refuses what the document's range refuses.
pub fn to_f32(v: f64) -> f32 {
    if v.abs() <= f64::from(f32::MAX) {
        v as f32
    } else {
        f32::INFINITY.copysign(v as f32)
    }
}

/// The latest time in seconds a viewer may ask a scene for (a built-in scene's generators
/// stay finite up to it; far beyond, their `f32` phases overflow).
pub const MAX_TIME: f64 = 1.0e9;

/// A time `t` in seconds asked of a scene (the render endpoint's and histogram's `time`,
/// `isoray render --time`): a number in `[0, MAX_TIME]` (400 otherwise).
pub fn scene_time(t: f64, field: &str) -> Result<f64, KindError> {
    if t.is_finite() && (0.0..=MAX_TIME).contains(&t) {
        Ok(t)
    } else {
        Err(
            KindError::invalid("invalid_value", format!("{field} {t} must be in [0, 1e9]"))
                .field(field),
        )
    }
}

/// A viewer's isovalue `v` (the websocket's `isovalue` input, the render endpoint's and
/// `isoray render`'s `isovalue`) for a scene whose meaningful isovalues are the open `range`:
/// a finite number inside it (400 when not a number at all, 422 outside the range), and
/// refused for a scene without a scalar field (a surfel scene, 422).
pub fn isovalue(
    v: f64,
    range: (f32, f32),
    scalar_field: bool,
    field: &str,
) -> Result<f32, KindError> {
    if !scalar_field {
        return Err(KindError::relational(
            "invalid_value",
            format!("{field}: a surfel scene has no scalar field to take an isovalue of"),
        )
        .field(field));
    }
    if !v.is_finite() {
        return Err(KindError::invalid(
            "invalid_value",
            format!("{field} {v} is not a finite number"),
        )
        .field(field));
    }
    let (lo, hi) = range;
    if !(v > f64::from(lo) && v < f64::from(hi)) {
        return Err(KindError::relational(
            "invalid_value",
            format!("{field} {v} is outside the scene's range ({lo}, {hi})"),
        )
        .field(field));
    }
    Ok(v as f32)
}

pub fn vec3(v: [f64; 3], field: &str) -> Result<Vec3, KindError> {
    Ok(Vec3::new(
        finite(v[0], &format!("{field}[0]"))?,
        finite(v[1], &format!("{field}[1]"))?,
        finite(v[2], &format!("{field}[2]"))?,
    ))
}

/// A camera with a usable basis.
pub fn camera(c: &ApiCamera, field: &str) -> Result<Camera, KindError> {
    let eye = vec3(c.eye, &format!("{field}.eye"))?;
    let target = vec3(c.target, &format!("{field}.target"))?;
    let up = vec3(c.up, &format!("{field}.up"))?;
    let fov = finite(c.fov_y_deg, &format!("{field}.fov_y_deg"))?;
    let forward = target - eye;
    if forward.length() < 1e-6 || forward.normalize().cross(up).length() < 1e-6 {
        return Err(KindError::relational(
            "invalid_value",
            format!("{field}: eye and target must differ and up must not be parallel to the view"),
        )
        .field(field));
    }
    if !(1.0..=170.0).contains(&fov) {
        return Err(KindError::invalid(
            "invalid_value",
            format!("{field}.fov_y_deg {fov} must be in [1, 170]"),
        )
        .field(format!("{field}.fov_y_deg")));
    }
    Ok(Camera {
        eye,
        target,
        up,
        fov_y_deg: fov,
    })
}

fn range(v: f64, lo: f64, hi: f64, field: &str) -> Result<f32, KindError> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v as f32)
    } else {
        Err(KindError::invalid(
            "invalid_value",
            format!("{field} is {v}; it must be a number in [{lo}, {hi}]"),
        )
        .field(field))
    }
}

/// A linear-light colour, each channel in `[0, hi]`.
fn color(v: [f64; 3], hi: f64, field: &str) -> Result<Vec3, KindError> {
    Ok(Vec3::new(
        range(v[0], 0.0, hi, &format!("{field}[0]"))?,
        range(v[1], 0.0, hi, &format!("{field}[1]"))?,
        range(v[2], 0.0, hi, &format!("{field}[2]"))?,
    ))
}

fn invalid(field: String, message: String) -> KindError {
    KindError::invalid("invalid_value", message).field(field)
}

/// A rule between values that the document states in prose (422).
fn relational(field: String, message: String) -> KindError {
    KindError::relational("invalid_value", message).field(field)
}

/// Most lights, materials, groups and isosurfaces a scene may declare.
const MAX_LIGHTS: usize = 8;
const MAX_MATERIALS: usize = 64;
const MAX_GROUPS: usize = 1024;
const MAX_ISOSURFACES: usize = 4;

fn light(spec: &LightSpec, field: &str) -> Result<Light, KindError> {
    let intensity = range(
        spec.intensity,
        0.0,
        MAX_COORDINATE,
        &format!("{field}.intensity"),
    )?;
    let color = color(spec.color, 1.0, &format!("{field}.color"))? * intensity;
    let need = |v: Option<[f64; 3]>, name: &str| {
        v.ok_or_else(|| {
            relational(
                format!("{field}.{name}"),
                format!("{field}: a {:?} light needs `{name}`", spec.kind).to_lowercase(),
            )
        })
    };
    let unused = |present: bool, name: &str| {
        if present {
            Err(relational(
                format!("{field}.{name}"),
                format!("{field}.{name} does not apply to a {:?} light", spec.kind).to_lowercase(),
            ))
        } else {
            Ok(())
        }
    };
    Ok(match spec.kind {
        LightKind::Directional => {
            unused(spec.position.is_some(), "position")?;
            unused(spec.radius.is_some(), "radius")?;
            let dir = vec3(
                need(spec.to_light, "to_light")?,
                &format!("{field}.to_light"),
            )?;
            if dir.length() < 1e-6 {
                return Err(relational(
                    format!("{field}.to_light"),
                    format!("{field}.to_light must not be zero"),
                ));
            }
            Light::Directional {
                to_light: dir.normalize(),
                color,
            }
        }
        LightKind::Point => {
            unused(spec.to_light.is_some(), "to_light")?;
            unused(spec.radius.is_some(), "radius")?;
            Light::Point {
                position: vec3(
                    need(spec.position, "position")?,
                    &format!("{field}.position"),
                )?,
                color,
            }
        }
        LightKind::Sphere => {
            unused(spec.to_light.is_some(), "to_light")?;
            let radius = spec.radius.ok_or_else(|| {
                relational(
                    format!("{field}.radius"),
                    format!("{field}: a sphere light needs `radius`"),
                )
            })?;
            let radius = finite(radius, &format!("{field}.radius"))?;
            if radius <= 0.0 {
                return Err(invalid(
                    format!("{field}.radius"),
                    format!("{field}.radius {radius} must be positive"),
                ));
            }
            Light::Sphere {
                center: vec3(
                    need(spec.position, "position")?,
                    &format!("{field}.position"),
                )?,
                radius,
                color,
            }
        }
    })
}

fn material(spec: &MaterialSpec, field: &str) -> Result<Material, KindError> {
    let f = |name: &str| format!("{field}.{name}");
    Ok(Material {
        diffuse: color(spec.diffuse, 1.0, &f("diffuse"))?,
        specular: range(spec.specular, 0.0, 1.0, &f("specular"))?,
        shininess: range(spec.shininess, 1.0, 10_000.0, &f("shininess"))?,
        reflectivity: range(spec.reflectivity, 0.0, 1.0, &f("reflectivity"))?,
        ior: range(spec.ior, 1.0, 4.0, &f("ior"))?,
        opacity: range(spec.opacity, 0.0, 1.0, &f("opacity"))?,
        emission: color(spec.emission, 1000.0, &f("emission"))?,
    })
}

fn material_index(index: u16, count: usize, field: String) -> Result<u16, KindError> {
    if (index as usize) < count {
        Ok(index)
    } else {
        Err(relational(
            field.clone(),
            format!("{field} {index} names no material (there are {count})"),
        ))
    }
}

pub fn lighting(spec: &LightingSpec, limits: &EffectLimits) -> Result<Lighting, KindError> {
    let mut l = Lighting::default();
    if let Some(lights) = &spec.lights {
        if lights.len() > MAX_LIGHTS {
            return Err(invalid(
                "lighting.lights".into(),
                format!("at most {MAX_LIGHTS} lights"),
            ));
        }
        l.lights = lights
            .iter()
            .enumerate()
            .map(|(i, s)| light(s, &format!("lighting.lights[{i}]")))
            .collect::<Result<_, _>>()?;
    }
    if let Some(v) = spec.ambient {
        l.ambient = color(v, 1.0, "lighting.ambient")?;
    }
    if let Some(v) = spec.background_top {
        l.background_top = color(v, 1.0, "lighting.background_top")?;
    }
    if let Some(v) = spec.background_bottom {
        l.background_bottom = color(v, 1.0, "lighting.background_bottom")?;
    }
    if let Some(materials) = &spec.materials {
        if materials.is_empty() || materials.len() > MAX_MATERIALS {
            return Err(invalid(
                "lighting.materials".into(),
                format!("lighting.materials must hold 1 to {MAX_MATERIALS} materials"),
            ));
        }
        l.materials = materials
            .iter()
            .enumerate()
            .map(|(i, m)| material(m, &format!("lighting.materials[{i}]")))
            .collect::<Result<_, _>>()?;
    }
    if let Some(v) = spec.shininess {
        l.materials[0].shininess = range(v, 1.0, 10_000.0, "lighting.shininess")?;
    }
    if let Some(v) = spec.specular {
        l.materials[0].specular = range(v, 0.0, 1.0, "lighting.specular")?;
    }
    let count = l.materials.len();
    if let Some(groups) = &spec.groups {
        if groups.len() > MAX_GROUPS {
            return Err(invalid(
                "lighting.groups".into(),
                format!("at most {MAX_GROUPS} groups"),
            ));
        }
        l.groups = groups
            .iter()
            .enumerate()
            .map(|(i, g)| {
                Ok(MaterialGroup {
                    first: g.first,
                    count: g.count,
                    material: material_index(
                        g.material,
                        count,
                        format!("lighting.groups[{i}].material"),
                    )?,
                })
            })
            .collect::<Result<_, KindError>>()?;
    }
    if let Some(floor) = &spec.floor {
        l.floor = Some(Floor {
            height: finite(floor.height, "lighting.floor.height")?,
            material: material_index(floor.material, count, "lighting.floor.material".into())?,
            colors: [
                color(floor.colors[0], 1.0, "lighting.floor.colors[0]")?,
                color(floor.colors[1], 1.0, "lighting.floor.colors[1]")?,
            ],
            checker: range(floor.checker, 0.0, MAX_COORDINATE, "lighting.floor.checker")?,
        });
    }
    if let Some(clip) = &spec.clip_box {
        let min = vec3(clip.min, "lighting.clip_box.min")?;
        let max = vec3(clip.max, "lighting.clip_box.max")?;
        if !min.cmplt(max).all() {
            return Err(relational(
                "lighting.clip_box".into(),
                "lighting.clip_box: min must be below max on every axis".into(),
            ));
        }
        l.clip_box = Some(ClipBox { min, max });
    }
    if let Some(surfaces) = &spec.isosurfaces {
        l.isosurfaces = isosurfaces(surfaces, count)?;
    }
    if let Some(volume) = &spec.volume {
        let density = range(
            volume.density,
            0.0,
            MAX_COORDINATE,
            "lighting.volume.density",
        )?;
        if density <= 0.0 {
            return Err(invalid(
                "lighting.volume.density".into(),
                "lighting.volume.density must be positive".into(),
            ));
        }
        l.volume = Some(Volume {
            density,
            color: color(volume.color, 1.0, "lighting.volume.color")?,
        });
    }
    if let Some(d) = spec.occlusion_distance {
        l.occlusion_distance = finite(d, "lighting.occlusion_distance")?;
        if l.occlusion_distance <= 0.0 {
            return Err(invalid(
                "lighting.occlusion_distance".into(),
                "lighting.occlusion_distance must be positive".into(),
            ));
        }
    }
    if let Some(changes) = &spec.effects {
        crate::style::refuse_in_scene(changes).map_err(|e| {
            invalid(
                format!("lighting.effects.{}", e.field),
                format!("lighting.effects.{}", e.message),
            )
        })?;
        l.effects = crate::effects::apply(&l.effects, changes, limits).map_err(|e| {
            invalid(
                format!("lighting.effects.{}", e.field),
                format!("lighting.effects.{}", e.message),
            )
        })?;
    }
    Ok(l)
}

/// Further isosurfaces (`lighting.isosurfaces`), each with a positive isovalue and a material
/// among the `count` declared.
fn isosurfaces(surfaces: &[IsosurfaceSpec], count: usize) -> Result<Vec<Isosurface>, KindError> {
    if surfaces.len() > MAX_ISOSURFACES {
        return Err(invalid(
            "lighting.isosurfaces".into(),
            format!("at most {MAX_ISOSURFACES} further isosurfaces"),
        ));
    }
    surfaces
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let field = format!("lighting.isosurfaces[{i}]");
            let isovalue = finite(s.isovalue, &format!("{field}.isovalue"))?;
            if isovalue <= 0.0 {
                return Err(invalid(
                    format!("{field}.isovalue"),
                    format!("{field}.isovalue must be positive"),
                ));
            }
            Ok(Isosurface {
                isovalue,
                material: material_index(s.material, count, format!("{field}.material"))?,
                color: None,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_f32_written_in_json_is_a_finite_f32() {
        // Python's repr of float(numpy.float32 max), as schemathesis sent it; serde_json
        // without `float_roundtrip` read it one ulp high, beyond f32, and the vertex was
        // refused as not finite.
        let v: f64 = serde_json::from_str("3.4028234663852886e38").expect("a number");
        assert_eq!(v, f64::from(f32::MAX));
        assert_eq!(to_f32(v), f32::MAX);
        let next: f64 = serde_json::from_str("3.4028234663852889e38").expect("a number");
        assert!(next > f64::from(f32::MAX) && to_f32(next).is_infinite());
    }
}
