//! REST API types of deforming surfel scenes (`"kind": "surfels"`,
//! deforming-point-sampled-surfaces.txt): the undeformed object, sent once at creation, and
//! per step the simulation nodes' positions. Serde shapes only; the server checks values at
//! its boundary.
//!
//! A surfel is an elliptical disc `centre + a·t1 + b·t2` with `a² + b² ≤ radius²`; its normal
//! is `t1 × t2` unless given (a given normal must not lie in the tangent plane: it picks the
//! outward side). The server embeds every surfel in its nearest simulation nodes and builds
//! the bounding-sphere hierarchy once, when the scene is created. Each step then moves the
//! nodes: a `(N, 3)` array of node positions in the order of [`SurfelSpec::nodes`] (JSON
//! [`JsonSurfelStep`], `.npy` or raw `ISRA`); the server estimates each node's displacement
//! gradient by least squares from its neighbours. A step whose deformation is so large that
//! the hierarchy's bounds stop pruning (a node's gradient of Frobenius norm above 4 relative
//! to its body's rigid motion, or a node moved more than two object radii from it) is still
//! drawn: that step's hierarchy is rebuilt from the deformed surfels instead (the documented
//! fallback), which costs time, never correctness.

use serde::{Deserialize, Serialize};

/// Static data of a surfel scene: the undeformed object.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SurfelSpec {
    /// The surfels (at least one, unless `mesh` is given).
    #[serde(default)]
    pub surfels: Vec<SurfelData>,
    /// A point cloud the server turns into surfels (added to `surfels`).
    #[serde(default)]
    pub points: Option<SurfelPoints>,
    /// A triangle mesh the server samples into surfels (added to `surfels`).
    #[serde(default)]
    pub mesh: Option<SurfelMesh>,
    /// Rest positions of the simulation nodes (at least one); steps move them.
    pub nodes: Vec<[f64; 3]>,
    /// Masses of the nodes (for the optimal rigid frame); all 1 when absent.
    #[serde(default)]
    pub node_mass: Option<Vec<f64>>,
    /// Clipping relations `[a, b]`: surfels of group `a` are cut by the surface of group `b`
    /// (sharp edges where two surfaces meet).
    #[serde(default)]
    pub clip: Option<Vec<[u16; 2]>>,
    /// How the hierarchy follows each step: `auto` (default: lazy or eager refit per step,
    /// by the share of surfels the previous step touched), `lazy`, `eager` or `rebuild`.
    #[serde(default)]
    pub update: Option<String>,
}

/// A point cloud to turn into surfels: each point's disc is tangent to its normal and reaches
/// its sixth nearest neighbour. Without normals (or for a zero normal), the normal is the
/// plane fitted to the point's 12 nearest neighbours, oriented away from the cloud's centre.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SurfelPoints {
    pub positions: Vec<[f64; 3]>,
    /// One per position, when the cloud has them.
    #[serde(default)]
    pub normals: Option<Vec<[f64; 3]>>,
    /// Linear-light RGB of the surfels.
    #[serde(default)]
    pub color: Option<[f64; 3]>,
}

/// A triangle mesh to sample into surfels: area-weighted points with their faces' normals
/// (faces wound counter-clockwise seen from outside), radii from the points' spacing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SurfelMesh {
    pub vertices: Vec<[f64; 3]>,
    /// Vertex indices of each triangle (at least one triangle).
    pub triangles: Vec<[u64; 3]>,
    /// Surfels to sample (default 20,000).
    #[serde(default)]
    pub count: Option<u64>,
    /// Linear-light RGB of the sampled surfels.
    #[serde(default)]
    pub color: Option<[f64; 3]>,
}

/// One surfel of the undeformed object.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SurfelData {
    pub centre: [f64; 3],
    /// First tangent axis (non-zero).
    pub t1: [f64; 3],
    /// Second tangent axis (non-zero, not parallel to `t1`).
    pub t2: [f64; 3],
    /// Outward normal; `t1 × t2` when absent.
    #[serde(default)]
    pub normal: Option<[f64; 3]>,
    /// Disc radius in units of the tangent axes, `> 0`.
    pub radius: f64,
    /// Linear-light RGB, each `[0, 1]` (default a light grey).
    #[serde(default)]
    pub color: Option<[f64; 3]>,
    /// The surface this surfel belongs to (clipping relations are between groups; default 0).
    #[serde(default)]
    pub group: Option<u16>,
}

/// JSON body of a surfel scene's step: every simulation node's position, in the order of the
/// scene's `nodes`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct JsonSurfelStep {
    pub positions: Vec<[f64; 3]>,
}
