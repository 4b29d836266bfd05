//! Scene kinds served from pushed data, in one closed set matched in this file: what a scene's
//! creation request holds for its kind, the layout of its step arrays, and how a stored step
//! becomes an engine scene.
//!
//! A new primitive kind (tetrahedral meshes, surfels) joins by adding a variant to
//! [`KindSetup`] and [`StepLayout`] and an arm to each match below: the REST API, the ingest
//! parsers, the store and the scene registry reach the kind only through these types. Static
//! data that is checked once at creation (a tet mesh's connectivity, say: "a tet referencing a
//! missing vertex" is refused by [`SceneSetup::from_spec`]) lives in the kind's setup; what
//! changes per step is a `rows × columns` f32 array whose columns the layout names and checks.

use crate::api::convert::{camera, finite, lighting, vec3};
use crate::api::error::ApiError;
use crate::api::tets::{mesh_from_spec, MeshSlot, TetSetup};
use crate::effects::EffectLimits;
use glam::Vec3;
use isoray_protocol::api::{CreateScene, SceneKind};
use isoray_render::metaball::{Kernel, Metaball, MetaballScene};
use isoray_render::scene::Geometry;
use isoray_render::{Camera, Lighting, Scene};
use std::sync::Arc;

/// The columns of a step array for one kind, and the checks its values get beyond finiteness.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepLayout {
    /// Rows are balls: `x y z [radius [strength [r g b]]]`.
    Metaballs,
    /// Rows are the mesh's vertices, one column: the scalar (`vertices`: how many, once the
    /// mesh is there).
    Tets { vertices: Option<u64> },
}

/// Metaball step column counts: positions, + radius, + strength, + linear RGB.
const METABALL_COLUMNS: [u32; 4] = [3, 4, 5, 8];
const METABALL_COLUMN_NAMES: [&str; 8] = ["x", "y", "z", "radius", "strength", "r", "g", "b"];

impl StepLayout {
    /// The layout of `kind`'s steps, or `None` while the engine cannot trace that kind.
    pub fn of(kind: SceneKind) -> Option<StepLayout> {
        match kind {
            SceneKind::Metaballs => Some(StepLayout::Metaballs),
            SceneKind::Tets => Some(StepLayout::Tets { vertices: None }),
            SceneKind::Surfels => None,
        }
    }

    /// Column counts a step of this kind may have.
    pub fn allowed_columns(self) -> &'static [u32] {
        match self {
            StepLayout::Metaballs => &METABALL_COLUMNS,
            StepLayout::Tets { .. } => &[1],
        }
    }

    /// What the columns hold, for error messages.
    pub fn columns_help(self) -> &'static str {
        match self {
            StepLayout::Metaballs => {
                "a metaball step has 3 (x y z), 4 (+ radius), 5 (+ strength) or 8 (+ r g b) columns"
            }
            StepLayout::Tets { .. } => "a tet step has 1 column: the scalar at each mesh vertex",
        }
    }

    /// The name of column `col`.
    pub fn column_name(self, col: usize) -> &'static str {
        match self {
            StepLayout::Metaballs => METABALL_COLUMN_NAMES.get(col).copied().unwrap_or("?"),
            StepLayout::Tets { .. } => "scalar",
        }
    }

    /// Whether a batch of whole, finite rows passes the kind's own checks. A branch-free pass
    /// (it vectorises); on `false` the caller finds the culprit with [`StepLayout::check_value`].
    pub fn rows_valid(self, values: &[f32], columns: usize) -> bool {
        match self {
            StepLayout::Metaballs => {
                columns < 4
                    || values
                        .chunks_exact(columns)
                        .fold(true, |ok, row| ok & (row[3] > 0.0))
            }
            // Any finite scalar will do.
            StepLayout::Tets { .. } => true,
        }
    }

    /// Why a step of `rows` rows does not fit, if it does not: a tet step has one row per
    /// mesh vertex.
    pub fn check_rows(self, rows: u64) -> Option<String> {
        match self {
            StepLayout::Metaballs => None,
            StepLayout::Tets { vertices: None } => {
                Some("the scene has no mesh yet; send it with PUT .../mesh first".into())
            }
            StepLayout::Tets {
                vertices: Some(n),
            } => (rows != n).then(|| {
                format!("{rows} rows, but the mesh has {n} vertices: a tet step has one scalar per vertex")
            }),
        }
    }

    /// Why the finite value `v` in column `col` is not allowed, if it is not.
    pub fn check_value(self, col: usize, v: f32) -> Option<String> {
        match self {
            StepLayout::Metaballs => {
                (col == 3 && v <= 0.0).then(|| format!("is {v}; a radius must be positive"))
            }
            StepLayout::Tets { .. } => None,
        }
    }
}

/// Per-ball values for columns a metaball step leaves out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BallDefaults {
    pub kernel: Kernel,
    pub radius: f32,
    pub strength: f32,
    pub color: Vec3,
}

/// The static, validated part of a scene, by kind.
#[derive(Clone, Debug, PartialEq)]
pub enum KindSetup {
    Metaballs(BallDefaults),
    Tets(TetSetup),
}

/// Everything a scene was created with, validated and converted to engine types.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSetup {
    /// The camera viewers start with.
    pub camera: Camera,
    /// The isovalue viewers start with.
    pub isovalue: f32,
    /// The isovalue slider's range.
    pub slider: (f32, f32),
    pub lighting: Lighting,
    pub kind: KindSetup,
}

/// Kernel names accepted in `metaballs.kernel`.
const KERNEL_NAMES: &str = "wyvill, quartic, tutorial, power1, power2, power3, power4";

fn kernel(name: &str) -> Result<Kernel, ApiError> {
    Ok(match name {
        "wyvill" => Kernel::Wyvill,
        "quartic" => Kernel::Quartic,
        "tutorial" => Kernel::Tutorial,
        "power1" => Kernel::Power { alpha: 1 },
        "power2" => Kernel::Power { alpha: 2 },
        "power3" => Kernel::Power { alpha: 3 },
        "power4" => Kernel::Power { alpha: 4 },
        other => {
            return Err(ApiError::bad_request(
                "invalid_value",
                format!("kernel `{other}` is not known; the engine has {KERNEL_NAMES}"),
            )
            .field("metaballs.kernel"))
        }
    })
}

impl SceneSetup {
    /// Validates a creation request and converts it, with effect quality checked against
    /// `limits` (the server's configured ones, or [`EffectLimits::ENGINE`]); every error names
    /// its field.
    pub fn from_spec(spec: &CreateScene, limits: &EffectLimits) -> Result<SceneSetup, ApiError> {
        let Some(layout) = StepLayout::of(spec.kind) else {
            return Err(ApiError::new(
                axum::http::StatusCode::UNPROCESSABLE_ENTITY,
                "unsupported_kind",
                format!(
                    "kind `{}` is not supported yet: this server's engine traces `metaballs` only",
                    spec.kind.as_str()
                ),
            )
            .field("kind"));
        };
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
        // A metaball field is positive; a tet scene's scalar may take any sign.
        let positive = layout == StepLayout::Metaballs;
        if positive && isovalue <= 0.0 {
            return Err(
                ApiError::bad_request("invalid_value", "isovalue must be positive")
                    .field("isovalue"),
            );
        }
        let slider = match spec.isovalue_slider {
            Some([lo, hi]) => {
                let (lo, hi) = (
                    finite(lo, "isovalue_slider[0]")?,
                    finite(hi, "isovalue_slider[1]")?,
                );
                if !(lo < hi && (!positive || 0.0 < lo)) {
                    let rule = if positive { "0 < lo < hi" } else { "lo < hi" };
                    return Err(ApiError::bad_request(
                        "invalid_value",
                        format!("isovalue_slider must be [lo, hi] with {rule}"),
                    )
                    .field("isovalue_slider"));
                }
                (lo, hi)
            }
            None => (0.05, 1.5),
        };
        let lighting = lighting(&spec.lighting.clone().unwrap_or_default(), limits)?;
        let kind = match layout {
            StepLayout::Metaballs => {
                let d = spec.metaballs.clone().unwrap_or_default();
                let radius = finite(d.radius, "metaballs.radius")?;
                if radius <= 0.0 {
                    return Err(ApiError::bad_request(
                        "invalid_value",
                        "metaballs.radius must be positive",
                    )
                    .field("metaballs.radius"));
                }
                KindSetup::Metaballs(BallDefaults {
                    kernel: kernel(&d.kernel)?,
                    radius,
                    strength: finite(d.strength, "metaballs.strength")?,
                    color: vec3(d.color, "metaballs.color")?,
                })
            }
            StepLayout::Tets { .. } => {
                let t = spec.tets.clone().unwrap_or_default();
                let color_range = match t.color_range {
                    Some([lo, hi]) => {
                        let (lo, hi) = (
                            finite(lo, "tets.color_range[0]")?,
                            finite(hi, "tets.color_range[1]")?,
                        );
                        if lo == hi {
                            return Err(ApiError::bad_request(
                                "invalid_value",
                                "tets.color_range must be two different values",
                            )
                            .field("tets.color_range"));
                        }
                        (lo, hi)
                    }
                    None => slider,
                };
                let mesh = MeshSlot::default();
                if let Some(data) = &t.mesh {
                    mesh.set(Arc::new(mesh_from_spec(data)?));
                }
                KindSetup::Tets(TetSetup {
                    mesh: Arc::new(mesh),
                    color_range,
                })
            }
        };
        Ok(SceneSetup {
            camera,
            isovalue,
            slider,
            lighting,
            kind,
        })
    }

    /// The layout of this scene's steps.
    pub fn layout(&self) -> StepLayout {
        match &self.kind {
            KindSetup::Metaballs(_) => StepLayout::Metaballs,
            KindSetup::Tets(t) => StepLayout::Tets {
                vertices: t.mesh.get().map(|m| m.vertices().len() as u64),
            },
        }
    }

    /// Open interval of isovalues a viewer of a pushed scene may pick: the field's range
    /// changes per step, so the bound is generous and the slider carries the useful range. A
    /// metaball field is positive; a tet scalar may take any sign.
    pub fn isovalue_range(&self) -> (f32, f32) {
        match self.kind {
            KindSetup::Metaballs(_) => (0.0, 1.0e6),
            KindSetup::Tets(_) => (-1.0e6, 1.0e6),
        }
    }

    /// Primitives of a step of `rows` rows: balls, or the mesh's tets.
    pub fn primitives(&self, rows: u64) -> u64 {
        match &self.kind {
            KindSetup::Metaballs(_) => rows,
            KindSetup::Tets(t) => t.mesh.get().map_or(0, |m| m.tets().len() as u64),
        }
    }

    /// The engine scene of one step: `payload` holds `rows × columns` little-endian f32 (read
    /// straight from the memory-mapped step file), or `None` before the first step.
    pub fn scene(&self, step: Option<(u32, &[u8])>) -> Scene {
        let geometry = match &self.kind {
            KindSetup::Metaballs(d) => {
                let balls = step.map_or_else(Vec::new, |(columns, payload)| {
                    balls_from_rows(columns as usize, payload, d)
                });
                let mut m = MetaballScene::new(d.kernel, balls);
                m.min_isovalue = self.slider.0.min(self.isovalue);
                Geometry::Metaballs(m)
            }
            KindSetup::Tets(t) => Geometry::Tets(t.scene(step)),
        };
        Scene {
            geometry,
            lighting: self.lighting.clone(),
        }
    }

    /// Memory a prepared step of `rows` rows takes, roughly, for the prepared-state cache.
    pub fn prepared_bytes(&self, rows: u64) -> u64 {
        match &self.kind {
            // The balls plus about as much again for the acceleration structure.
            KindSetup::Metaballs(_) => rows * 2 * std::mem::size_of::<Metaball>() as u64,
            KindSetup::Tets(t) => t.prepared_bytes(),
        }
    }
}

/// Engine balls from a metaball step's f32 rows.
fn balls_from_rows(columns: usize, payload: &[u8], d: &BallDefaults) -> Vec<Metaball> {
    let mut row = [0f32; 8];
    payload
        .chunks_exact(columns.max(1) * 4)
        .map(|bytes| {
            for (v, b) in row.iter_mut().zip(bytes.chunks_exact(4)) {
                *v = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            }
            Metaball::sphere(
                Vec3::new(row[0], row[1], row[2]),
                if columns >= 4 { row[3] } else { d.radius },
                if columns >= 5 { row[4] } else { d.strength },
                if columns >= 8 {
                    Vec3::new(row[5], row[6], row[7])
                } else {
                    d.color
                },
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(json: &str) -> CreateScene {
        serde_json::from_str(json).expect("valid JSON")
    }

    #[test]
    fn metaball_setup_builds_balls_with_defaults() {
        let setup = SceneSetup::from_spec(
            &spec(r#"{"kind":"metaballs","metaballs":{"radius":0.5,"kernel":"quartic"}}"#),
            &EffectLimits::ENGINE,
        )
        .expect("valid spec");
        assert_eq!(setup.layout(), StepLayout::Metaballs);
        let payload: Vec<u8> = [1.0f32, 2.0, 3.0, 0.0, 0.0, 0.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let scene = setup.scene(Some((3, &payload)));
        let Geometry::Metaballs(m) = &scene.geometry else {
            panic!("a metaball scene gives metaball geometry");
        };
        assert_eq!(m.kernel, Kernel::Quartic);
        assert_eq!(m.balls.len(), 2);
        assert_eq!(m.balls[0].center, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(m.balls[1].radius, 0.5);
    }

    #[test]
    fn setup_errors_name_the_field() {
        for (json, field) in [
            (r#"{"kind":"surfels"}"#, "kind"),
            (
                r#"{"kind":"tets","tets":{"mesh":{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],"cells":[[0,1,2,7]]}}}"#,
                "tets.mesh.cells[0][3]",
            ),
            (
                r#"{"kind":"tets","tets":{"mesh":{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],"cells":[[0,2,1,3]]}}}"#,
                "tets.mesh.cells[0]",
            ),
            (
                r#"{"kind":"tets","tets":{"mesh":{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1e39]],"cells":[[0,1,2,3]]}}}"#,
                "tets.mesh.vertices[3]",
            ),
            (
                r#"{"kind":"tets","tets":{"color_range":[1,1]}}"#,
                "tets.color_range",
            ),
            (
                r#"{"kind":"tets","isovalue_slider":[1,-1]}"#,
                "isovalue_slider",
            ),
            (
                r#"{"kind":"metaballs","metaballs":{"kernel":"gauss"}}"#,
                "metaballs.kernel",
            ),
            (
                r#"{"kind":"metaballs","metaballs":{"radius":-1}}"#,
                "metaballs.radius",
            ),
            (r#"{"kind":"metaballs","isovalue":0}"#, "isovalue"),
            (
                r#"{"kind":"metaballs","isovalue_slider":[2,1]}"#,
                "isovalue_slider",
            ),
        ] {
            let e = SceneSetup::from_spec(&spec(json), &EffectLimits::ENGINE).expect_err(json);
            assert_eq!(e.field.as_deref(), Some(field), "{json}");
        }
    }

    #[test]
    fn tet_setup_takes_negative_isovalues_and_builds_steps_on_the_mesh() {
        let setup = SceneSetup::from_spec(
            &spec(
                r#"{"kind":"tets","isovalue":-0.5,"isovalue_slider":[-1,1],
                    "tets":{"mesh":{"vertices":[[0,0,0],[1,0,0],[0,1,0],[0,0,1],[1,1,1]],
                                    "cells":[[0,1,2,3],[1,4,2,3]]}}}"#,
            ),
            &EffectLimits::ENGINE,
        )
        .expect("valid spec");
        assert_eq!(setup.layout(), StepLayout::Tets { vertices: Some(5) });
        assert_eq!(setup.primitives(5), 2);
        assert!(setup.isovalue_range().0 < -0.5);
        assert_eq!(setup.layout().check_rows(5), None);
        assert!(setup.layout().check_rows(4).is_some());
        let payload: Vec<u8> = [0.0f32, 1.0, -1.0, 0.5, 2.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let Geometry::Tets(t) = setup.scene(Some((1, &payload))).geometry else {
            panic!("a tet scene gives tet geometry");
        };
        assert_eq!(t.tet_count(), 2);
        assert_eq!(t.scalars(), &[0.0, 1.0, -1.0, 0.5, 2.0]);
        // Before the first step (and for a payload that does not fit): nothing to draw.
        let Geometry::Tets(empty) = setup.scene(None).geometry else {
            panic!("tet geometry");
        };
        assert_eq!(empty.tet_count(), 0);
        // Without a mesh, steps are refused until it comes.
        let bare = SceneSetup::from_spec(&spec(r#"{"kind":"tets"}"#), &EffectLimits::ENGINE)
            .expect("valid spec");
        assert_eq!(bare.layout(), StepLayout::Tets { vertices: None });
        assert!(bare.layout().check_rows(5).is_some());
        assert_eq!(
            crate::api::tets::check_ready(&bare)
                .expect_err("no mesh")
                .status,
            axum::http::StatusCode::CONFLICT
        );
    }

    #[test]
    fn radius_check_finds_the_bad_row() {
        let l = StepLayout::Metaballs;
        assert!(l.rows_valid(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 2.0], 4));
        assert!(!l.rows_valid(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0], 4));
        assert!(l.check_value(3, 0.0).is_some());
        assert!(l.check_value(2, 0.0).is_none());
    }
}
