//! A tet mesh's checks, named for the client: a mesh from JSON (`tets.mesh` in a scene
//! description, or the JSON body of `PUT .../mesh`), and the engine's mesh errors as
//! [`KindError`]s that name the field (tet and corner) and, for a binary body, the byte
//! offset of the value.

use crate::kinds::convert::to_f32;
use crate::kinds::error::KindError;
use glam::Vec3;
use isoray_protocol::api::TetMeshData;
use isoray_render::kinds::tets::{TetError, TetMesh};

/// A mesh from the JSON of `tets.mesh` in a creation request (fields named under it).
pub fn mesh_from_spec(data: &TetMeshData) -> Result<TetMesh, KindError> {
    mesh_from_json(data, "tets.mesh.")
}

pub fn mesh_from_json(data: &TetMeshData, prefix: &str) -> Result<TetMesh, KindError> {
    let mut vertices = Vec::with_capacity(data.vertices.len());
    for (i, v) in data.vertices.iter().enumerate() {
        let p = Vec3::new(to_f32(v[0]), to_f32(v[1]), to_f32(v[2]));
        if !p.is_finite() {
            return Err(KindError::invalid(
                "invalid_value",
                format!("vertex {i}: {v:?} is not a finite f32 position"),
            )
            .field(format!("{prefix}vertices[{i}]")));
        }
        vertices.push(p);
    }
    TetMesh::from_indices(vertices, &data.cells).map_err(|e| mesh_error(e, prefix, &Offsets::NONE))
}

/// Where a binary body's arrays start, to name byte offsets in errors.
pub struct Offsets {
    pub vertices: Option<(u64, u64)>,
    pub cells: Option<(u64, u64)>,
}

impl Offsets {
    pub const NONE: Offsets = Offsets {
        vertices: None,
        cells: None,
    };
}

/// A mesh check's error as a kind error naming the field (and the byte offset of the value
/// in a binary body).
pub fn mesh_error(e: TetError, prefix: &str, at: &Offsets) -> KindError {
    let cell_offset = |tet: usize, corner: usize| {
        at.cells
            .map(|(start, size)| start + (tet as u64 * 4 + corner as u64) * size)
    };
    let (field, offset) = match &e {
        TetError::VertexOutOfRange { tet, corner, .. } => (
            format!("{prefix}cells[{tet}][{corner}]"),
            cell_offset(*tet, *corner),
        ),
        TetError::RepeatedVertex { tet, .. }
        | TetError::Degenerate { tet, .. }
        | TetError::Inverted { tet, .. } => (format!("{prefix}cells[{tet}]"), cell_offset(*tet, 0)),
        TetError::NotFinite { vertex, .. } => (
            format!("{prefix}vertices[{vertex}]"),
            at.vertices
                .map(|(start, size)| start + *vertex as u64 * 3 * size),
        ),
        TetError::TooManyVertices { .. } | TetError::WrongLength { .. } => {
            (format!("{prefix}vertices"), None)
        }
        _ => (format!("{prefix}cells"), None),
    };
    // Which vertices a tet joins, and the tet's shape, are rules between values (422); a
    // position that is not a finite f32, or a mesh too large, breaks the document's schema.
    let err = match &e {
        TetError::NotFinite { .. } | TetError::TooManyVertices { .. } => {
            KindError::invalid("invalid_mesh", e.to_string())
        }
        _ => KindError::relational("invalid_mesh", e.to_string()),
    }
    .field(field);
    match offset {
        Some(o) => err.offset(o),
        None => err,
    }
}
