//! Scene kinds served from pushed data, in one closed set whose dispatch is in this file:
//! what a scene's creation request holds for its kind, the layout of its step arrays, how a
//! stored step becomes an engine scene, and the histogram of a kind's field. Each kind's own
//! code is in its folder (`metaballs/`, `tets/`); this file only matches and delegates.
//!
//! A new primitive kind (surfels) joins by adding a folder beside `metaballs/` and `tets/`, a
//! variant to [`KindSetup`] and [`StepLayout`] and an arm to each match below: the REST API,
//! the ingest parsers, the store and the scene registry reach the kind only through these
//! types. Static data that is checked once at creation (a tet mesh's connectivity, say: "a
//! tet referencing a missing vertex" is refused by [`SceneSetup::from_spec`]) lives in the
//! kind's setup; what changes per step is a `rows × columns` f32 array whose columns the
//! layout names and checks.
//!
//! Layering: `kinds` imports neither the HTTP layer (`api`, `error`) nor the store; its
//! checks return [`KindError`], which the HTTP layer maps to its one error type.

pub mod convert;
pub mod error;
pub mod histogram;
pub mod metaballs;
pub mod surfels;
pub mod tets;

use crate::effects::EffectLimits;
use crate::kinds::convert::{camera, finite, lighting};
use crate::kinds::error::{KindError, KindErrorKind};
use crate::kinds::histogram::Histogram;
use crate::kinds::metaballs::histogram::field_histogram;
use crate::kinds::metaballs::setup::{self as ball_setup, BallDefaults};
use crate::kinds::surfels::histogram::displacement_histogram;
use crate::kinds::surfels::setup::{self as surfel_setup, SurfelSetup};
use crate::kinds::surfels::step as surfel_step;
use crate::kinds::tets::histogram::vertex_histogram;
use crate::kinds::tets::setup::{self as tet_setup, MeshSlot, TetSetup};
use crate::kinds::tets::step as tet_step;
use glam::Vec3;
use isoray_protocol::api::{CreateScene, SceneKind};
use isoray_render::scene::Geometry;
use isoray_render::scenes::DemoScene;
use isoray_render::{Camera, Lighting, Scene};
use std::sync::Arc;

/// The columns of a step array for one kind, and the checks its values get beyond finiteness.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepLayout {
    /// Rows are balls: `x y z [radius [strength [r g b]]]`.
    Metaballs,
    /// Rows are the mesh's vertices: the scalar, and for a deforming mesh the vertex's
    /// position this step (`scalar [x y z]`; `vertices`: how many, once the mesh is there).
    Tets { vertices: Option<u64> },
    /// Rows are the simulation nodes (`nodes`: how many), three columns: their positions.
    Surfels { nodes: u64 },
}

impl StepLayout {
    /// The layout of `kind`'s steps before the scene's static data is known, or `None` while
    /// the engine cannot trace that kind.
    pub fn of(kind: SceneKind) -> Option<StepLayout> {
        match kind {
            SceneKind::Metaballs => Some(StepLayout::Metaballs),
            SceneKind::Tets => Some(StepLayout::Tets { vertices: None }),
            SceneKind::Surfels => Some(StepLayout::Surfels { nodes: 0 }),
        }
    }

    /// Column counts a step of this kind may have.
    pub fn allowed_columns(self) -> &'static [u32] {
        match self {
            StepLayout::Metaballs => &ball_setup::COLUMNS,
            StepLayout::Tets { .. } => &tet_step::COLUMNS,
            StepLayout::Surfels { .. } => &[3],
        }
    }

    /// What the columns hold, for error messages.
    pub fn columns_help(self) -> &'static str {
        match self {
            StepLayout::Metaballs => ball_setup::COLUMNS_HELP,
            StepLayout::Tets { .. } => tet_step::COLUMNS_HELP,
            StepLayout::Surfels { .. } => surfel_step::COLUMNS_HELP,
        }
    }

    /// The name of column `col`.
    pub fn column_name(self, col: usize) -> &'static str {
        match self {
            StepLayout::Metaballs => ball_setup::column_name(col),
            StepLayout::Tets { .. } => tet_step::column_name(col),
            StepLayout::Surfels { .. } => surfel_step::column_name(col),
        }
    }

    /// Whether a batch of whole, finite rows passes the kind's own checks. A branch-free pass
    /// (it vectorises); on `false` the caller finds the culprit with [`StepLayout::check_value`].
    pub fn rows_valid(self, values: &[f32], columns: usize) -> bool {
        match self {
            StepLayout::Metaballs => ball_setup::rows_valid(values, columns),
            // Any finite scalar will do; any finite position.
            StepLayout::Tets { .. } | StepLayout::Surfels { .. } => true,
        }
    }

    /// Why a step of `rows` rows does not fit, if it does not: a tet step has one row per
    /// mesh vertex.
    pub fn check_rows(self, rows: u64) -> Option<String> {
        match self {
            StepLayout::Metaballs => None,
            StepLayout::Tets { vertices } => tet_step::check_rows(vertices, rows),
            StepLayout::Surfels { nodes } => surfel_step::check_rows(nodes, rows),
        }
    }

    /// Whether a step of `columns` columns needs [`SceneSetup::check_step`] once its values
    /// passed one by one: a tet step that moves the vertices does.
    pub fn checks_whole_step(self, columns: u32) -> bool {
        match self {
            StepLayout::Metaballs | StepLayout::Surfels { .. } => false,
            StepLayout::Tets { .. } => columns == 4,
        }
    }

    /// Why the finite value `v` in column `col` is not allowed, if it is not.
    pub fn check_value(self, col: usize, v: f32) -> Option<String> {
        match self {
            StepLayout::Metaballs => ball_setup::check_value(col, v),
            StepLayout::Tets { .. } | StepLayout::Surfels { .. } => None,
        }
    }
}

/// The static, validated part of a scene, by kind.
#[derive(Clone, Debug, PartialEq)]
pub enum KindSetup {
    Metaballs(BallDefaults),
    Tets(TetSetup),
    Surfels(SurfelSetup),
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

/// Refuses a new surfel scene description that sets an isovalue, its slider or further
/// isosurfaces: surfels have no field, so they would go unused, and settings that go unused
/// are refused like another kind's. Checked where a description comes in (the API, `isoray
/// render`), not when the store reloads one that an older server took.
pub fn refuse_field_settings(spec: &CreateScene) -> Result<(), KindError> {
    if spec.kind != SceneKind::Surfels {
        return Ok(());
    }
    let isosurfaces = spec
        .lighting
        .as_ref()
        .is_some_and(|l| l.isosurfaces.as_ref().is_some_and(|s| !s.is_empty()));
    let field = [
        ("isovalue", spec.isovalue.is_some()),
        ("isovalue_slider", spec.isovalue_slider.is_some()),
        ("lighting.isosurfaces", isosurfaces),
    ];
    match field.into_iter().find(|(_, given)| *given) {
        Some((name, _)) => Err(KindError::relational(
            "invalid_value",
            format!("{name}: a surfel scene has no scalar field to take isovalues of"),
        )
        .field(name)),
        None => Ok(()),
    }
}

impl SceneSetup {
    /// Validates a creation request and converts it, with effect quality checked against
    /// `limits` (the server's configured ones, or [`EffectLimits::ENGINE`]); every error names
    /// its field.
    pub fn from_spec(spec: &CreateScene, limits: &EffectLimits) -> Result<SceneSetup, KindError> {
        let Some(layout) = StepLayout::of(spec.kind) else {
            return Err(KindError::new(
                KindErrorKind::Unsupported,
                "unsupported_kind",
                format!(
                    "kind `{}` is not supported yet: this server's engine traces `metaballs`, `tets` and `surfels`",
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
        // A metaball field is positive; a tet scene's scalar may take any sign; surfels have
        // no field (the isovalue is unused).
        let positive = match layout {
            StepLayout::Metaballs => true,
            StepLayout::Tets { .. } | StepLayout::Surfels { .. } => false,
        };
        if positive && isovalue <= 0.0 {
            return Err(KindError::relational(
                "invalid_value",
                "isovalue must be positive in a metaball scene",
            )
            .field("isovalue"));
        }
        let slider = match spec.isovalue_slider {
            Some([lo, hi]) => {
                let (lo, hi) = (
                    finite(lo, "isovalue_slider[0]")?,
                    finite(hi, "isovalue_slider[1]")?,
                );
                if !(lo < hi && (!positive || 0.0 < lo)) {
                    let rule = if positive { "0 < lo < hi" } else { "lo < hi" };
                    return Err(KindError::relational(
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
        // Another kind's settings are refused rather than ignored (they would go unchecked).
        let others = [
            ("metaballs", spec.metaballs.is_some(), SceneKind::Metaballs),
            ("tets", spec.tets.is_some(), SceneKind::Tets),
            ("surfels", spec.surfels.is_some(), SceneKind::Surfels),
        ];
        let this = spec.kind;
        if let Some((field, _, _)) = others.iter().find(|(_, given, k)| *given && *k != this) {
            return Err(KindError::relational(
                "wrong_kind",
                format!(
                    "`{field}` holds the settings of {field} scenes; this scene's kind is `{}`",
                    this.as_str()
                ),
            )
            .field(*field));
        }
        let kind = match layout {
            StepLayout::Metaballs => KindSetup::Metaballs(ball_setup::setup_from_spec(
                &spec.metaballs.clone().unwrap_or_default(),
            )?),
            StepLayout::Tets { .. } => KindSetup::Tets(tet_setup::setup_from_spec(
                &spec.tets.clone().unwrap_or_default(),
                slider,
            )?),
            StepLayout::Surfels { .. } => {
                KindSetup::Surfels(surfel_setup::setup_from_spec(spec.surfels.as_ref())?)
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
            KindSetup::Surfels(s) => StepLayout::Surfels { nodes: s.nodes() },
        }
    }

    /// Open interval of isovalues a viewer of a pushed scene may pick: the field's range
    /// changes per step, so the bound is generous and the slider carries the useful range. A
    /// metaball field is positive; a tet scalar may take any sign.
    pub fn isovalue_range(&self) -> (f32, f32) {
        match self.kind {
            KindSetup::Metaballs(_) => (0.0, 1.0e6),
            KindSetup::Tets(_) | KindSetup::Surfels(_) => (-1.0e6, 1.0e6),
        }
    }

    /// Primitives of a step of `rows` rows: balls, or the mesh's tets.
    pub fn primitives(&self, rows: u64) -> u64 {
        match &self.kind {
            KindSetup::Metaballs(_) => rows,
            KindSetup::Tets(t) => t.mesh.get().map_or(0, |m| m.tets().len() as u64),
            KindSetup::Surfels(s) => s.model.len() as u64,
        }
    }

    /// The engine scene of one step: `payload` holds `rows × columns` little-endian f32 (read
    /// straight from the memory-mapped step file), or `None` before the first step.
    pub fn scene(&self, step: Option<(u32, &[u8])>) -> Scene {
        let geometry = match &self.kind {
            KindSetup::Metaballs(d) => {
                let min_isovalue = self.slider.0.min(self.isovalue);
                Geometry::Metaballs(ball_setup::scene(d, step, min_isovalue))
            }
            KindSetup::Tets(t) => Geometry::Tets(t.scene(step)),
            KindSetup::Surfels(s) => Geometry::Surfels(s.scene(step)),
        };
        Scene {
            geometry,
            lighting: self.lighting.clone(),
        }
    }

    /// The checks of a whole step, once its values passed one by one: a tet step that moves
    /// the vertices may not invert or flatten a tet ([`tet_step::check_moved`]). `payload`
    /// holds `rows × columns` little-endian f32, as stored.
    pub fn check_step(&self, columns: u32, payload: &[u8]) -> Result<(), KindError> {
        match &self.kind {
            KindSetup::Metaballs(_) => Ok(()),
            KindSetup::Tets(t) => match t.mesh.get() {
                Some(mesh) => tet_step::check_moved(mesh, columns, payload),
                None => Ok(()),
            },
            KindSetup::Surfels(_) => Ok(()),
        }
    }

    /// The slot of the static mesh, for a kind that has one (tets); `None` for the others.
    pub fn mesh_slot(&self) -> Option<&Arc<MeshSlot>> {
        match &self.kind {
            KindSetup::Tets(t) => Some(&t.mesh),
            KindSetup::Metaballs(_) | KindSetup::Surfels(_) => None,
        }
    }

    /// Memory a prepared step of `rows` rows takes, roughly, for the prepared-state cache.
    pub fn prepared_bytes(&self, rows: u64) -> u64 {
        match &self.kind {
            KindSetup::Metaballs(_) => ball_setup::prepared_bytes(rows),
            KindSetup::Tets(t) => t.prepared_bytes(),
            KindSetup::Surfels(s) => s.prepared_bytes(),
        }
    }
}

/// Whether a scene takes steps yet: a tet scene needs its mesh first
/// ([`KindErrorKind::NotReady`], a 409); a metaball scene always does.
pub fn check_ready(setup: &SceneSetup) -> Result<(), KindError> {
    match &setup.kind {
        KindSetup::Tets(t) if t.mesh.get().is_none() => Err(KindError::new(
            KindErrorKind::NotReady,
            "no_mesh",
            "this tet scene has no mesh yet: send it with PUT /api/v1/scenes/{id}/mesh, then its steps",
        )
        .field("mesh")),
        KindSetup::Tets(_) | KindSetup::Metaballs(_) | KindSetup::Surfels(_) => Ok(()),
    }
}

/// The histogram of a scene's field over `[lo, hi)` in `bins` bins, by kind: the metaball
/// field sampled on a grid, or a tet mesh's scalars at its vertices.
pub fn histogram_of(geometry: &Geometry, lo: f32, hi: f32, bins: usize) -> Histogram {
    match geometry {
        Geometry::Metaballs(m) => field_histogram(m, lo, hi, bins),
        Geometry::Tets(t) => vertex_histogram(t.scalars(), lo, hi, bins),
        Geometry::Surfels(s) => displacement_histogram(s, lo, hi, bins),
    }
}

/// The kind of a built-in demo's primitives; every demo is named, so a new demo (or kind)
/// is a compile error here rather than a metaball scene by default.
pub fn demo_kind(demo: DemoScene) -> SceneKind {
    match demo {
        DemoScene::TetGyroid | DemoScene::TetBucky => SceneKind::Tets,
        DemoScene::Blobs
        | DemoScene::Scattered30k
        | DemoScene::Scattered100k
        | DemoScene::Scattered1k
        | DemoScene::Tornado4k
        | DemoScene::Tornado128k
        | DemoScene::Molecule
        | DemoScene::Pool
        | DemoScene::Glass
        | DemoScene::Clouds
        | DemoScene::Shells => SceneKind::Metaballs,
        DemoScene::SurfelBalls | DemoScene::SurfelImpact | DemoScene::SurfelHeads => {
            SceneKind::Surfels
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use isoray_render::kinds::metaballs::Kernel;

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

    /// A valid surfel scene description with `extra` fields beside its surfels.
    fn surfels_with(extra: &str) -> String {
        let surfel = r#"{"centre":[0,0,0],"t1":[0.1,0,0],"t2":[0,0.1,0],"radius":0.1}"#;
        format!(
            r#"{{"kind":"surfels","surfels":{{"surfels":[{surfel},{surfel}],"nodes":[[0,0,0],[1,0,0]]}},{extra}}}"#
        )
    }

    #[test]
    fn a_surfel_description_refuses_field_settings() {
        let ok = surfels_with(r#""name":"two""#);
        refuse_field_settings(&spec(&ok)).expect("valid");
        SceneSetup::from_spec(&spec(&ok), &EffectLimits::ENGINE).expect("valid");
        for (extra, field) in [
            (r#""isovalue":0.5"#, "isovalue"),
            (r#""isovalue_slider":[0.1,1]"#, "isovalue_slider"),
            (
                r#""lighting":{"isosurfaces":[{"isovalue":0.2,"material":0}]}"#,
                "lighting.isosurfaces",
            ),
        ] {
            let json = surfels_with(extra);
            let e = refuse_field_settings(&spec(&json)).expect_err(&json);
            assert_eq!(e.field.as_deref(), Some(field), "{json}");
            // A store written by an older server that took them still loads.
            SceneSetup::from_spec(&spec(&json), &EffectLimits::ENGINE).expect(&json);
            assert!(e.message.contains("surfel"), "{json}: {}", e.message);
        }
    }

    #[test]
    fn setup_errors_name_the_field() {
        for (json, field) in [
            (r#"{"kind":"surfels"}"#, "surfels"),
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
        // The assertion as it was before the kinds left the HTTP layer: through the one
        // HTTP error type, a missing mesh is a 409.
        assert_eq!(
            crate::error::AppError::from(check_ready(&bare).expect_err("no mesh")).status,
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
