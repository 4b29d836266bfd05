//! From API types to engine types, validating at the boundary: every non-finite or
//! out-of-range value is refused with the field that holds it.

use super::error::ApiError;
use crate::scenes::BallDefaults;
use glam::Vec3;
use isoray_protocol::api::{ApiCamera, CreateScene, LightingSpec};
use isoray_render::metaball::Kernel;
use isoray_render::shade::DirectionalLight;
use isoray_render::{Camera, Lighting};

/// Largest coordinate accepted: keeps values exact enough in f32.
const MAX_COORDINATE: f64 = 1.0e6;

fn finite(v: f64, field: &str) -> Result<f32, ApiError> {
    if v.is_finite() && v.abs() <= MAX_COORDINATE {
        Ok(v as f32)
    } else {
        Err(ApiError::bad_request(
            "invalid_value",
            format!("{field} is {v}; it must be a finite number of magnitude at most 1e6"),
        )
        .field(field))
    }
}

fn vec3(v: [f64; 3], field: &str) -> Result<Vec3, ApiError> {
    Ok(Vec3::new(
        finite(v[0], &format!("{field}[0]"))?,
        finite(v[1], &format!("{field}[1]"))?,
        finite(v[2], &format!("{field}[2]"))?,
    ))
}

/// A camera with a usable basis.
pub fn camera(c: &ApiCamera, field: &str) -> Result<Camera, ApiError> {
    let eye = vec3(c.eye, &format!("{field}.eye"))?;
    let target = vec3(c.target, &format!("{field}.target"))?;
    let up = vec3(c.up, &format!("{field}.up"))?;
    let fov = finite(c.fov_y_deg, &format!("{field}.fov_y_deg"))?;
    let forward = target - eye;
    if forward.length() < 1e-6 || forward.normalize().cross(up).length() < 1e-6 {
        return Err(ApiError::bad_request(
            "invalid_value",
            format!("{field}: eye and target must differ and up must not be parallel to the view"),
        )
        .field(field));
    }
    if !(1.0..=170.0).contains(&fov) {
        return Err(ApiError::bad_request(
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

fn lighting(spec: &LightingSpec) -> Result<Lighting, ApiError> {
    let mut l = Lighting::default();
    if let Some(lights) = &spec.lights {
        if lights.len() > 8 {
            return Err(
                ApiError::bad_request("invalid_value", "at most 8 lights").field("lighting.lights")
            );
        }
        l.lights = lights
            .iter()
            .enumerate()
            .map(|(i, light)| {
                let dir = vec3(light.to_light, &format!("lighting.lights[{i}].to_light"))?;
                if dir.length() < 1e-6 {
                    return Err(ApiError::bad_request(
                        "invalid_value",
                        "a light direction must not be zero",
                    )
                    .field(format!("lighting.lights[{i}].to_light")));
                }
                Ok(DirectionalLight {
                    to_light: dir.normalize(),
                    color: vec3(light.color, &format!("lighting.lights[{i}].color"))?,
                })
            })
            .collect::<Result<_, _>>()?;
    }
    if let Some(v) = spec.ambient {
        l.ambient = vec3(v, "lighting.ambient")?;
    }
    if let Some(v) = spec.background_top {
        l.background_top = vec3(v, "lighting.background_top")?;
    }
    if let Some(v) = spec.background_bottom {
        l.background_bottom = vec3(v, "lighting.background_bottom")?;
    }
    if let Some(v) = spec.shininess {
        l.shininess = finite(v, "lighting.shininess")?.max(1.0);
    }
    if let Some(v) = spec.specular {
        l.specular = finite(v, "lighting.specular")?;
    }
    Ok(l)
}

/// What a new scene's viewers start with, how it is lit, and its ball defaults.
pub type SceneSetup = ((Camera, f32, (f32, f32)), Lighting, BallDefaults);

/// Validates a creation request's settings and converts them.
pub fn scene_setup(spec: &CreateScene) -> Result<SceneSetup, ApiError> {
    let camera = match &spec.camera {
        Some(c) => camera(c, "camera")?,
        None => Camera {
            eye: Vec3::new(0.0, 1.5, 7.5),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 45.0,
        },
    };
    let isovalue = finite(spec.isovalue.unwrap_or(0.5), "isovalue")?;
    if isovalue <= 0.0 {
        return Err(
            ApiError::bad_request("invalid_value", "isovalue must be positive").field("isovalue"),
        );
    }
    let slider = match spec.isovalue_slider {
        Some([lo, hi]) => {
            let (lo, hi) = (
                finite(lo, "isovalue_slider[0]")?,
                finite(hi, "isovalue_slider[1]")?,
            );
            if !(0.0 < lo && lo < hi) {
                return Err(ApiError::bad_request(
                    "invalid_value",
                    "isovalue_slider must be [lo, hi] with 0 < lo < hi",
                )
                .field("isovalue_slider"));
            }
            (lo, hi)
        }
        None => (0.05, 1.5),
    };
    let lighting = lighting(&spec.lighting.clone().unwrap_or_default())?;
    let d = spec.metaballs.clone().unwrap_or_default();
    let kernel = match d.kernel.as_str() {
        "wyvill" => Kernel::Wyvill,
        other => {
            return Err(ApiError::bad_request(
                "invalid_value",
                format!("kernel `{other}` is not known; the engine has `wyvill`"),
            )
            .field("metaballs.kernel"))
        }
    };
    let radius = finite(d.radius, "metaballs.radius")?;
    if radius <= 0.0 {
        return Err(
            ApiError::bad_request("invalid_value", "metaballs.radius must be positive")
                .field("metaballs.radius"),
        );
    }
    let defaults = BallDefaults {
        kernel,
        radius,
        strength: finite(d.strength, "metaballs.strength")?,
        color: vec3(d.color, "metaballs.color")?,
    };
    Ok(((camera, isovalue, slider), lighting, defaults))
}
