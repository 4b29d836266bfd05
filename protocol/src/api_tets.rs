//! REST API types of tetrahedral scenes (`"kind": "tets"`): the static mesh, sent once, and
//! the per-step scalar fields. Serde shapes only; the server checks values at its boundary.
//!
//! A tet scene's mesh (vertex positions and, per tet, four vertex indices) is static: it is
//! given inline when the scene is created ([`TetSpec::mesh`]), or sent once afterwards with
//! `PUT /api/v1/scenes/{id}/mesh` as JSON ([`TetMeshData`]), as two NumPy arrays written one
//! after the other into one body (`np.save(f, vertices); np.save(f, cells)`: float32/float64
//! `(V, 3)`, then int32/int64/uint32/uint64 `(T, 4)`), or as two raw arrays with the 16-byte
//! `ISRA` header (dtype codes 1 = f32, 2 = f64 for the vertices; 3 = u32, 4 = u64, 5 = i32,
//! 6 = i64 for the cells). Each step then holds one scalar per vertex: a `(V, 1)` array, or
//! [`JsonTetStep`]. A deforming mesh's step holds each vertex's scalar and position: a
//! `(V, 4)` array of columns `scalar x y z`, or `positions` in [`JsonTetStep`].

use serde::{Deserialize, Serialize};

/// Static data of a tet scene.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct TetSpec {
    /// The mesh, for small meshes; otherwise send it with `PUT /api/v1/scenes/{id}/mesh`.
    #[serde(default)]
    pub mesh: Option<TetMeshData>,
    /// Scalar values at the two ends of the colour map (default: the isovalue slider's range).
    #[serde(default)]
    pub color_range: Option<[f64; 2]>,
}

/// A tetrahedral mesh. Each cell lists four vertex indices in VTK's order: corners 0, 1, 2
/// turn counter-clockwise seen from corner 3 (a positive volume); degenerate and inverted
/// cells are refused.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct TetMeshData {
    pub vertices: Vec<[f64; 3]>,
    pub cells: Vec<[u64; 4]>,
}

/// JSON body of a tet scene's step: one scalar per mesh vertex and, for a deforming mesh
/// (Lagrangian and ALE codes move their vertices every step), each vertex's position this
/// step. Moved positions are checked like the mesh: no tet may become inverted or
/// degenerate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct JsonTetStep {
    pub scalars: Vec<f64>,
    /// This step's vertex positions, one per mesh vertex (default: the mesh's own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub positions: Option<Vec<[f64; 3]>>,
}

/// Answer of `PUT /api/v1/scenes/{id}/mesh`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct MeshInfo {
    pub vertices: u64,
    pub tets: u64,
    /// Hex XXH3-128 of the stored mesh.
    pub checksum: String,
    /// `created`, or `unchanged` when the same mesh was already there.
    pub outcome: String,
}
