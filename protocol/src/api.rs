//! Types of the REST API v1 (`/api/v1`): what simulation codes send to create scenes and push
//! time steps, and what the server answers. Serde shapes only; the server validates values
//! (finiteness, ranges, limits) at its boundary and converts them to engine types there.
//!
//! With the `openapi` feature every type also derives `utoipa::ToSchema`, so the server's
//! generated OpenAPI document describes exactly these shapes.
//!
//! Binary step payloads are described in the README's API section and on [`RAW_STEP_MAGIC`]:
//! a NumPy `.npy` array or a raw little-endian array with a 16-byte header.

pub use crate::api_surfels::{JsonSurfelStep, SurfelData, SurfelMesh, SurfelPoints, SurfelSpec};
pub use crate::api_tets::{JsonTetStep, MeshInfo, TetMeshData, TetSpec};
pub use crate::effects::{
    ClipBoxSpec, EffectChanges, FloorSpec, GroupSpec, IsosurfaceSpec, LightKind, MaterialSpec,
    VolumeSpec,
};
use serde::{Deserialize, Serialize};

/// Media type of a NumPy `.npy` step body.
pub const NPY_MEDIA_TYPE: &str = "application/x-npy";
/// Media type of a raw step body (16-byte header, then little-endian values).
pub const RAW_MEDIA_TYPE: &str = "application/octet-stream";

/// First four bytes of a raw step body. The whole header is 16 bytes, little-endian:
///
/// | offset | size | field |
/// | --- | --- | --- |
/// | 0 | 4 | magic `ISRA` |
/// | 4 | 1 | header version, 1 |
/// | 5 | 1 | dtype: 1 = f32, 2 = f64 |
/// | 6 | 2 | columns (u16): 3, 4, 5 or 8 |
/// | 8 | 8 | rows (u64) |
///
/// then `rows × columns` values, row-major. Columns are `x y z [radius [strength [r g b]]]`.
pub const RAW_STEP_MAGIC: [u8; 4] = *b"ISRA";
/// Length of the raw step header.
pub const RAW_STEP_HEADER_LEN: usize = 16;

/// The primitive kinds a scene can hold: metaballs, tetrahedral meshes with a scalar field,
/// and deforming surfels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum SceneKind {
    Metaballs,
    Surfels,
    Tets,
}

impl SceneKind {
    pub fn as_str(self) -> &'static str {
        match self {
            SceneKind::Metaballs => "metaballs",
            SceneKind::Surfels => "surfels",
            SceneKind::Tets => "tets",
        }
    }

    /// Whether the kind's surface is an isosurface of a scalar field (metaballs, tets), which
    /// an isovalue, further isosurfaces and a colour map of the isovalue change; a surfel
    /// surface is none.
    pub fn has_field(self) -> bool {
        !matches!(self, SceneKind::Surfels)
    }
}

/// Body of `POST /api/v1/scenes`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct CreateScene {
    pub kind: SceneKind,
    /// Display name (at most 200 characters).
    #[serde(default)]
    pub name: Option<String>,
    #[serde(default)]
    pub description: Option<String>,
    /// Static data of a metaball scene: the defaults for columns a step leaves out.
    #[serde(default)]
    pub metaballs: Option<MetaballDefaults>,
    /// Static data of a tet scene: its mesh (or send it later) and colour range.
    #[serde(default)]
    pub tets: Option<TetSpec>,
    /// Static data of a surfel scene: its surfels and simulation nodes (required).
    #[serde(default)]
    pub surfels: Option<SurfelSpec>,
    #[serde(default)]
    pub lighting: Option<LightingSpec>,
    /// The camera viewers start with; one looking at the origin when absent.
    #[serde(default)]
    pub camera: Option<ApiCamera>,
    /// The isovalue viewers start with (default 0.5); refused for surfels, which have no
    /// scalar field (as are `isovalue_slider` and `lighting.isosurfaces`).
    #[serde(default)]
    pub isovalue: Option<f64>,
    /// Slider range offered to viewers (default [0.05, 1.5]).
    #[serde(default)]
    pub isovalue_slider: Option<[f64; 2]>,
}

/// Per-ball values used where a step's array has fewer columns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct MetaballDefaults {
    /// Radial falloff; only `wyvill` so far.
    #[serde(default = "default_kernel")]
    pub kernel: String,
    #[serde(default = "default_radius")]
    pub radius: f64,
    #[serde(default = "default_strength")]
    pub strength: f64,
    /// Linear-light RGB.
    #[serde(default = "default_color")]
    pub color: [f64; 3],
}

fn default_kernel() -> String {
    "wyvill".into()
}
fn default_radius() -> f64 {
    0.25
}
fn default_strength() -> f64 {
    1.0
}
fn default_color() -> [f64; 3] {
    [0.8, 0.35, 0.2]
}

impl Default for MetaballDefaults {
    fn default() -> MetaballDefaults {
        MetaballDefaults {
            kernel: default_kernel(),
            radius: default_radius(),
            strength: default_strength(),
            color: default_color(),
        }
    }
}

/// Directional lights and background; absent fields keep the engine's defaults.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct LightingSpec {
    #[serde(default)]
    pub lights: Option<Vec<LightSpec>>,
    #[serde(default)]
    pub ambient: Option<[f64; 3]>,
    #[serde(default)]
    pub background_top: Option<[f64; 3]>,
    #[serde(default)]
    pub background_bottom: Option<[f64; 3]>,
    /// Specular exponent and weight of `materials[0]` (when `materials` is absent).
    #[serde(default)]
    pub shininess: Option<f64>,
    #[serde(default)]
    pub specular: Option<f64>,
    /// Materials; `materials[0]` shades every primitive outside `groups`.
    #[serde(default)]
    pub materials: Option<Vec<MaterialSpec>>,
    /// Ranges of primitives and their material.
    #[serde(default)]
    pub groups: Option<Vec<GroupSpec>>,
    #[serde(default)]
    pub floor: Option<FloorSpec>,
    #[serde(default)]
    pub clip_box: Option<ClipBoxSpec>,
    /// Further isosurfaces of the field.
    #[serde(default)]
    pub isosurfaces: Option<Vec<IsosurfaceSpec>>,
    /// Render the field as an absorbing volume when transparency is on.
    #[serde(default)]
    pub volume: Option<VolumeSpec>,
    /// Length of ambient-occlusion rays (default 1).
    #[serde(default)]
    pub occlusion_distance: Option<f64>,
    /// The effects viewers start with (default: none).
    #[serde(default)]
    pub effects: Option<EffectChanges>,
}

/// A light: directional (default), point, or sphere (an area light).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    #[serde(default)]
    pub kind: LightKind,
    /// Directional: direction from the surface towards the light (normalised by the server).
    #[serde(default)]
    pub to_light: Option<[f64; 3]>,
    /// Point and sphere: where the light is.
    #[serde(default)]
    pub position: Option<[f64; 3]>,
    /// Sphere: its radius, `> 0`.
    #[serde(default)]
    pub radius: Option<f64>,
    /// Linear-light colour, each channel `[0, 1]`.
    #[serde(default = "white")]
    pub color: [f64; 3],
    /// Scale of `color`, `≥ 0`: the irradiance of a directional light, the intensity (the
    /// irradiance at distance 1) of a point or sphere light.
    #[serde(default = "unit")]
    pub intensity: f64,
}

fn unit() -> f64 {
    1.0
}

fn white() -> [f64; 3] {
    [1.0, 1.0, 1.0]
}

/// A look-at pinhole camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ApiCamera {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    #[serde(default = "y_up")]
    pub up: [f64; 3],
    #[serde(default = "default_fov")]
    pub fov_y_deg: f64,
}

fn y_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}
fn default_fov() -> f64 {
    45.0
}

/// Answer to `POST /api/v1/scenes`: the scene and its write token, shown only this once.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct CreatedScene {
    pub scene: SceneInfo,
    /// Send as `Authorization: Bearer <write_token>` to push steps or delete.
    pub write_token: String,
}

/// One scene, built-in or pushed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SceneInfo {
    pub id: String,
    pub name: String,
    pub kind: SceneKind,
    pub description: String,
    /// Whether the scene changes over time (always, for now: demos animate, pushed scenes
    /// advance as steps arrive).
    pub animated: bool,
    /// `demo` (built in, animated by the server) or `stored` (pushed, on disk).
    pub source: String,
    /// Primitives in the newest state.
    pub primitives: u64,
    /// Stored steps (zero for demos).
    pub steps: u64,
    /// Lowest and highest stored step index, if any.
    pub first_step: Option<u64>,
    pub last_step: Option<u64>,
    /// Bytes of stored steps on disk.
    pub stored_bytes: u64,
    /// Axis-aligned bounds of the newest state's primitives (of the state at time 0 for
    /// demos); `GET /api/v1/scenes/{id}` only, absent for an empty scene. Viewers offer
    /// clip-box ranges from it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounds: Option<SceneBounds>,
}

/// An axis-aligned box.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SceneBounds {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// Body of `GET /api/v1/scenes`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SceneInfoList {
    pub scenes: Vec<SceneInfo>,
    /// Peers (`--peers`) that did not answer in time, by base URL (or `dns://` name, when it
    /// did not resolve): their scenes are missing from `scenes`. Empty when all answered.
    #[serde(default)]
    pub unreachable_shards: Vec<String>,
}

/// One stored step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct StepInfo {
    pub index: u64,
    /// Simulation time of the step (its index unless the push gave `?time=`).
    pub time: f64,
    /// Rows of the step's array: balls for metaballs.
    pub primitives: u64,
    /// Columns per row: 3 (`x y z`), 4 (+ radius), 5 (+ strength) or 8 (+ `r g b`).
    pub columns: u32,
    /// Size of the step file on disk.
    pub bytes: u64,
    /// XXH3-128 of the stored little-endian f32 values, hex.
    pub checksum: String,
}

/// Body of `GET /api/v1/scenes/{id}/steps`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct StepList {
    pub steps: Vec<StepInfo>,
}

/// Answer to a push: the step, and whether it was new, unchanged or replaced.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PushResult {
    pub step: StepInfo,
    /// `created`, `unchanged` (same index, same content: a no-op) or `replaced`.
    pub outcome: String,
    /// Steps evicted by the retention policy to make room, by index.
    pub evicted: Vec<u64>,
}

/// A JSON step body for small data: one row per ball. Optional arrays, when present, have
/// one entry per row of `positions`, and all rows use the same columns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct JsonStep {
    pub positions: Vec<[f64; 3]>,
    #[serde(default)]
    pub radii: Option<Vec<f64>>,
    #[serde(default)]
    pub strengths: Option<Vec<f64>>,
    #[serde(default)]
    pub colors: Option<Vec<[f64; 3]>>,
}

/// Image format of a one-shot render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum ImageFormat {
    #[default]
    Png,
    Jpeg,
    /// NumPy `.npy`: an `(H, W, 4)` little-endian `f32` array per pixel of the hit distance
    /// along the ray from the eye and the outward unit normal (x, y, z), `[inf, 0, 0, 0]`
    /// where the ray misses. The primary rays' isosurface only (no floor, no further
    /// isosurfaces, no shading), cut by the clip box where `effects` turn it on, as the image
    /// is; one pass (`passes` above 1 is refused).
    Npy,
}

/// Body of `POST /api/v1/scenes/{id}/render`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct RenderRequest {
    /// Stored step to render (default: the newest). Stored scenes only.
    #[serde(default)]
    pub step: Option<u64>,
    /// Time in seconds, 0 to 1e9 (default 0): a built-in scene at that time; for a stored
    /// scene, instead of `step`, its latest step at or before that time (the first if none
    /// is), as a viewer's time input picks it.
    #[serde(default)]
    pub time: Option<f64>,
    #[serde(default)]
    pub camera: Option<ApiCamera>,
    /// Inside the scene's isovalue range (default: the scene's); refused for a surfel scene,
    /// which has no scalar field.
    #[serde(default)]
    pub isovalue: Option<f64>,
    /// Image size in pixels (default 640 × 480, at most the server's `--max-size`).
    #[serde(default)]
    pub width: Option<u32>,
    #[serde(default)]
    pub height: Option<u32>,
    #[serde(default)]
    pub format: ImageFormat,
    /// JPEG quality 1–100 (default 90).
    #[serde(default)]
    pub quality: Option<u8>,
    /// Effect changes over the scene's own starting effects (as in the `effects` websocket
    /// message).
    #[serde(default)]
    pub effects: Option<crate::effects::EffectChanges>,
    /// Passes to average, 1 to the server's `--max-refine-passes` (default 1: one pass, the
    /// pixels' centres): as on a still view, soft shadows and occlusion get that many samples
    /// a pixel and the image is antialiased over that many sub-pixel positions.
    #[serde(default)]
    pub passes: Option<u32>,
}

/// Every API error: a stable code, a message for people, and where the input was wrong.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ApiErrorBody {
    pub code: String,
    pub message: String,
    /// The offending field, as a path such as `positions[3][1]` or `index`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// The byte offset in the request body where the problem is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<u64>,
}

/// Body of `GET /api/v1/scenes/{id}/histogram`: how the scalar field's values are spread,
/// sampled on a regular grid over the scene's bounds at the points inside at least one
/// primitive's support, in `counts.len()` equal bins over `[lo, hi)`. A viewer draws it
/// behind the isovalue slider.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FieldHistogram {
    pub lo: f64,
    pub hi: f64,
    pub counts: Vec<u64>,
    /// Samples inside a support whose value lies below `lo` or at or above `hi`.
    pub below: u64,
    pub above: u64,
    /// Grid points inside at least one support (`below + above + Σ counts`).
    pub samples: u64,
    /// Grid points along x, y and z.
    pub grid: [u32; 3],
    /// The state sampled: scene time in seconds (the step's time for a pushed scene).
    pub time: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn create_scene_needs_only_a_kind() {
        let c: CreateScene =
            serde_json::from_str(r#"{"kind":"metaballs"}"#).expect("minimal body parses");
        assert_eq!(c.kind, SceneKind::Metaballs);
        assert!(serde_json::from_str::<CreateScene>(r#"{"kind":"quads"}"#).is_err());
    }

    #[test]
    fn error_body_omits_absent_locations() {
        let e = ApiErrorBody {
            code: "x".into(),
            message: "m".into(),
            field: None,
            offset: Some(7),
        };
        assert_eq!(
            serde_json::to_string(&e).expect("serializes"),
            r#"{"code":"x","message":"m","offset":7}"#
        );
    }
}
