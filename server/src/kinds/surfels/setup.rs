//! The static part of a surfel scene (deforming-point-sampled-surfaces.txt): the undeformed
//! object, checked and precomputed once when the scene is created (the surfels embedded in
//! their nearest simulation nodes, the fixed neighbourhoods and the bounding-sphere
//! hierarchy), the state shared by its steps (the per-pixel sphere-node cache), and the
//! engine scene of one step from its node positions.

use crate::kinds::convert::{finite, vec3};
use crate::kinds::error::KindError;
use glam::{Mat3, Vec3};
use isoray_protocol::api::{SurfelData, SurfelMesh, SurfelPoints, SurfelSpec};
use isoray_render::kinds::surfels::deform::gradients_by_least_squares;
use isoray_render::kinds::surfels::input::{from_points, sample_mesh, InputError};
use isoray_render::kinds::surfels::model::{Surfel, SurfelError, SurfelModel, SurfelSet};
use isoray_render::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, SurfelScene, UpdateMode};
use std::sync::Arc;

/// Most surfels a scene may have.
pub const MAX_SURFELS: usize = 2_000_000;
/// Most simulation nodes a scene may have (each step estimates a gradient per node).
pub const MAX_NODES: usize = 200_000;
/// Smallest radius and node mass (the document's `minimum`): positive and still positive as
/// an `f32`.
pub const MIN_POSITIVE: f64 = 1.0e-30;
/// Surfels sampled from a mesh that does not say how many.
const DEFAULT_MESH_SURFELS: u64 = 20_000;
/// Colour of a surfel that names none.
const DEFAULT_COLOUR: Vec3 = Vec3::new(0.75, 0.72, 0.68);

/// The static part of a surfel scene.
#[derive(Clone)]
pub struct SurfelSetup {
    pub model: Arc<SurfelModel>,
    pub options: SurfelOptions,
    /// Shared by every step: the sphere-node cache and the heuristic's statistics.
    pub runtime: Arc<SurfelRuntime>,
}

impl std::fmt::Debug for SurfelSetup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SurfelSetup")
            .field("surfels", &self.model.len())
            .field("nodes", &self.model.nodes.len())
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

impl PartialEq for SurfelSetup {
    fn eq(&self, o: &SurfelSetup) -> bool {
        Arc::ptr_eq(&self.model, &o.model) && self.options == o.options
    }
}

impl SurfelSetup {
    /// Simulation nodes: the rows of every step.
    pub fn nodes(&self) -> u64 {
        self.model.nodes.len() as u64
    }

    /// The engine scene of one step: `payload` holds `nodes × 3` little-endian f32 node
    /// positions; before the first step (or for a stored step that does not fit), the
    /// undeformed object.
    pub fn scene(&self, step: Option<(u32, &[u8])>) -> SurfelScene {
        let rest = &self.model.nodes;
        let moved = step.and_then(|(columns, payload)| {
            if columns != 3 || payload.len() != rest.len() * 12 {
                tracing::warn!(
                    columns,
                    bytes = payload.len(),
                    "a stored surfel step does not match its nodes; showing the rest shape"
                );
                return None;
            }
            let values: Vec<f32> = payload
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            Some(
                values
                    .chunks_exact(3)
                    .map(|p| Vec3::new(p[0], p[1], p[2]))
                    .collect::<Vec<Vec3>>(),
            )
        });
        let (u, g): (Vec<Vec3>, Vec<Mat3>) = match moved {
            Some(moved) => (
                moved.iter().zip(rest).map(|(p, r)| *p - *r).collect(),
                gradients_by_least_squares(rest, &moved),
            ),
            None => (vec![Vec3::ZERO; rest.len()], vec![Mat3::ZERO; rest.len()]),
        };
        SurfelScene {
            model: Arc::clone(&self.model),
            displacement: u.into(),
            gradient: g.into(),
            options: self.options,
            runtime: Arc::clone(&self.runtime),
        }
    }

    /// Memory of a prepared step, roughly: a deformed surfel and two lazily filled spheres
    /// per surfel, a displacement and a gradient per node.
    pub fn prepared_bytes(&self) -> u64 {
        self.model.len() as u64 * 160 + self.nodes() * 48
    }
}

/// Whether every component is finite and of magnitude at most 1e6 (the fast path; the slow
/// one names the field).
fn ok3(v: [f64; 3]) -> bool {
    v.iter().all(|c| c.is_finite() && c.abs() <= 1.0e6)
}

fn surfel_from(i: usize, d: &SurfelData) -> Result<Surfel, KindError> {
    let field = |name: &str| format!("surfels.surfels[{i}].{name}");
    let get = |v: [f64; 3], name: &str| -> Result<Vec3, KindError> {
        if ok3(v) {
            Ok(Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32))
        } else {
            vec3(v, &field(name))
        }
    };
    let centre = get(d.centre, "centre")?;
    let t1 = get(d.t1, "t1")?;
    let t2 = get(d.t2, "t2")?;
    for (axis, name) in [(t1, "t1"), (t2, "t2")] {
        if axis.length_squared() <= 1e-20 {
            return Err(KindError::relational(
                "degenerate_surfel",
                format!("{} is a zero-length tangent axis", field(name)),
            )
            .field(field(name)));
        }
    }
    let normal = match d.normal {
        Some(n) => get(n, "normal")?,
        None => t1.cross(t2),
    };
    let colour = match d.color {
        Some(c) if ok3(c) && c.iter().all(|v| (0.0..=1.0).contains(v)) => {
            Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)
        }
        c => colour_of(c, &field("color"))?,
    };
    let radius = positive(d.radius, &field("radius"))?;
    Ok(Surfel {
        centre,
        t1,
        t2,
        normal,
        colour,
        radius,
        group: d.group.unwrap_or(0),
    })
}

/// A radius or mass in `[MIN_POSITIVE, 1e6]`, or the error naming `field`.
fn positive(v: f64, field: &str) -> Result<f32, KindError> {
    if (MIN_POSITIVE..=1.0e6).contains(&v) {
        return Ok(v as f32);
    }
    let v = finite(v, field)?;
    Err(KindError::invalid(
        "invalid_value",
        format!("{field} is {v}; it must be positive (at least {MIN_POSITIVE})"),
    )
    .field(field))
}

/// More than the limit of `what` in `field` (the document's `maxItems`).
fn too_many(count: usize, limit: usize, field: &str) -> KindError {
    KindError::invalid(
        "too_many",
        format!("{field}: {count} entries exceed the limit of {limit}"),
    )
    .field(field)
}

/// `v` as a vector, or the error naming `field[i]`.
fn checked(v: &[[f64; 3]], field: &str) -> Result<Vec<Vec3>, KindError> {
    v.iter()
        .enumerate()
        .map(|(i, &p)| {
            if ok3(p) {
                Ok(Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32))
            } else {
                vec3(p, &format!("{field}[{i}]"))
            }
        })
        .collect()
}

fn colour_of(c: Option<[f64; 3]>, field: &str) -> Result<Vec3, KindError> {
    match c {
        Some(c) => {
            let c = vec3(c, field)?;
            if !(c.min_element() >= 0.0 && c.max_element() <= 1.0) {
                return Err(KindError::invalid(
                    "invalid_value",
                    format!("{field} must be linear-light RGB in [0, 1]"),
                )
                .field(field));
            }
            Ok(c)
        }
        None => Ok(DEFAULT_COLOUR),
    }
}

/// The surfels of a point cloud, normals estimated where it has none.
fn from_cloud(points: &SurfelPoints) -> Result<Vec<Surfel>, KindError> {
    if points.positions.len() > MAX_SURFELS {
        return Err(too_many(
            points.positions.len(),
            MAX_SURFELS,
            "surfels.points.positions",
        ));
    }
    let positions = checked(&points.positions, "surfels.points.positions")?;
    let normals = match &points.normals {
        Some(n) => {
            if n.len() != positions.len() {
                return Err(KindError::relational(
                    "bad_shape",
                    format!(
                        "surfels.points.normals has {} entries for {} positions",
                        n.len(),
                        positions.len()
                    ),
                )
                .field("surfels.points.normals"));
            }
            Some(checked(n, "surfels.points.normals")?)
        }
        None => None,
    };
    let colour = colour_of(points.color, "surfels.points.color")?;
    from_points(&positions, normals.as_deref(), colour).map_err(|e| {
        let error = match e {
            InputError::NormalCount { .. } | InputError::ZeroArea => KindError::relational,
            InputError::NoPoints
            | InputError::NoFaces
            | InputError::BadIndex { .. }
            | InputError::NotFinite { .. } => KindError::invalid,
        };
        error("invalid_points", format!("surfels.points: {e}")).field("surfels.points.positions")
    })
}

/// The surfels sampled from `mesh`, or why it cannot be sampled (naming the face, corner or
/// field).
fn sampled(mesh: &SurfelMesh) -> Result<Vec<Surfel>, KindError> {
    let count = mesh.count.unwrap_or(DEFAULT_MESH_SURFELS);
    if count == 0 || count > MAX_SURFELS as u64 {
        return Err(KindError::invalid(
            "invalid_value",
            format!("surfels.mesh.count must be 1 to {MAX_SURFELS}"),
        )
        .field("surfels.mesh.count"));
    }
    let vertices = checked(&mesh.vertices, "surfels.mesh.vertices")?;
    let colour = colour_of(mesh.color, "surfels.mesh.color")?;
    let named = |e: InputError| {
        let field = match &e {
            InputError::BadIndex { face, corner, .. } => {
                format!("surfels.mesh.triangles[{face}][{corner}]")
            }
            InputError::NoFaces | InputError::ZeroArea => "surfels.mesh.triangles".to_string(),
            InputError::NoPoints
            | InputError::NotFinite { .. }
            | InputError::NormalCount { .. } => "surfels.mesh".to_string(),
        };
        // No faces breaks the schema (minItems); the others break a rule between values.
        let error = match &e {
            InputError::NoPoints | InputError::NoFaces | InputError::NotFinite { .. } => {
                KindError::invalid
            }
            InputError::BadIndex { .. } | InputError::ZeroArea | InputError::NormalCount { .. } => {
                KindError::relational
            }
        };
        error("invalid_mesh", format!("{field}: {e}")).field(field)
    };
    let (points, normals) =
        sample_mesh(&vertices, &mesh.triangles, count as usize, 0x5EED).map_err(named)?;
    from_points(&points, Some(&normals), colour).map_err(named)
}

/// The engine's verdict on the object, naming the API field it is about.
fn model_error(e: SurfelError) -> KindError {
    let field = match &e {
        SurfelError::NoSurfels | SurfelError::TooMany { .. } => "surfels.surfels".to_string(),
        SurfelError::NoNodes => "surfels.nodes".to_string(),
        SurfelError::NotFinite { what, index } => match *what {
            "node" => format!("surfels.nodes[{index}]"),
            _ => format!("surfels.surfels[{index}]"),
        },
        SurfelError::DegenerateTangents { index } => format!("surfels.surfels[{index}].t2"),
        SurfelError::DegenerateNormal { index } => format!("surfels.surfels[{index}].normal"),
        SurfelError::BadRadius { index, .. } => format!("surfels.surfels[{index}].radius"),
        SurfelError::BadMass { index, .. } => format!("surfels.node_mass[{index}]"),
        SurfelError::MassCount { .. } => "surfels.node_mass".to_string(),
        SurfelError::BodyCount { .. } => "surfels.nodes".to_string(),
        SurfelError::UnknownGroup { .. } => "surfels.clip".to_string(),
        SurfelError::StepCount { .. } | SurfelError::StepNotFinite { .. } => {
            "positions".to_string()
        }
    };
    // What the document's schema states (a node, a limit, a range) is a 400; a rule between
    // values that it states in prose (tangent axes not parallel, counts that agree, a group
    // that exists, at least one surfel from any source) a 422.
    let error = match &e {
        SurfelError::NoNodes
        | SurfelError::NotFinite { .. }
        | SurfelError::BadRadius { .. }
        | SurfelError::BadMass { .. }
        | SurfelError::StepNotFinite { .. } => KindError::invalid,
        SurfelError::NoSurfels
        | SurfelError::TooMany { .. }
        | SurfelError::DegenerateTangents { .. }
        | SurfelError::DegenerateNormal { .. }
        | SurfelError::MassCount { .. }
        | SurfelError::BodyCount { .. }
        | SurfelError::UnknownGroup { .. }
        | SurfelError::StepCount { .. } => KindError::relational,
    };
    error("invalid_surfels", format!("{field}: {e}")).field(field)
}

/// The surfel part of a scene description, checked and precomputed: this embeds the surfels
/// and builds the hierarchy (seconds for a large object: call it off the async runtime).
pub fn setup_from_spec(spec: Option<&SurfelSpec>) -> Result<SurfelSetup, KindError> {
    let Some(spec) = spec else {
        return Err(KindError::relational(
            "missing_field",
            "a surfel scene needs `surfels`: its surfels and simulation nodes",
        )
        .field("surfels"));
    };
    if spec.surfels.len() > MAX_SURFELS {
        return Err(too_many(spec.surfels.len(), MAX_SURFELS, "surfels.surfels"));
    }
    if spec.nodes.len() > MAX_NODES {
        return Err(too_many(spec.nodes.len(), MAX_NODES, "surfels.nodes"));
    }
    let mut surfels = spec
        .surfels
        .iter()
        .enumerate()
        .map(|(i, d)| surfel_from(i, d))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(points) = &spec.points {
        surfels.extend(from_cloud(points)?);
    }
    if let Some(mesh) = &spec.mesh {
        surfels.extend(sampled(mesh)?);
    }
    let nodes = spec
        .nodes
        .iter()
        .enumerate()
        .map(|(i, &p)| vec3(p, &format!("surfels.nodes[{i}]")))
        .collect::<Result<Vec<_>, _>>()?;
    let node_mass = match &spec.node_mass {
        Some(m) => m
            .iter()
            .enumerate()
            .map(|(i, &v)| positive(v, &format!("surfels.node_mass[{i}]")))
            .collect::<Result<Vec<_>, _>>()?,
        None => Vec::new(),
    };
    let clip = spec.clip.iter().flatten().map(|&[a, b]| (a, b)).collect();
    let mode = match spec.update.as_deref() {
        None | Some("auto") => UpdateMode::Auto,
        Some("lazy") => UpdateMode::Lazy,
        Some("eager") => UpdateMode::Eager,
        Some("rebuild") => UpdateMode::Rebuild,
        Some(other) => {
            return Err(KindError::invalid(
                "invalid_value",
                format!("surfels.update `{other}` is not one of auto, lazy, eager, rebuild"),
            )
            .field("surfels.update"))
        }
    };
    let set = SurfelSet {
        surfels,
        nodes,
        node_mass,
        clip,
        node_body: Vec::new(),
        closed: false,
    };
    let model = SurfelModel::new(set, MAX_SURFELS).map_err(model_error)?;
    Ok(SurfelSetup {
        model: Arc::new(model),
        options: SurfelOptions::new(mode, true),
        runtime: Arc::new(SurfelRuntime::default()),
    })
}
