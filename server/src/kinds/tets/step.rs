//! A tet scene's steps: one scalar per mesh vertex (one column), or, for a deforming mesh,
//! the scalar and the vertex's position this step (four columns: `scalar x y z`). JSON steps
//! (`{"scalars": [...], "positions": [[x, y, z], ...]}`) are checked value by value, naming
//! `scalars[i]` or `positions[i]`, and become a raw `(V, 1)` or `(V, 4)` array that the store
//! ingests like any other. A step that moves the vertices is then checked as a whole, like
//! the mesh at creation ([`check_moved`]): no tet inverted or degenerate after the move,
//! named by tet and by the corner whose move did it.

use crate::kinds::error::KindError;
use glam::Vec3;
use isoray_protocol::api::{JsonTetStep, RAW_STEP_HEADER_LEN, RAW_STEP_MAGIC};
use isoray_render::kinds::tets::{check_tet, TetMesh};

/// The columns' names, for error messages.
pub const COLUMN_NAMES: [&str; 4] = ["scalar", "x", "y", "z"];

/// Column counts a tet step may have: scalars only, or scalars and positions.
pub const COLUMNS: [u32; 2] = [1, 4];

/// What the columns hold, for error messages.
pub const COLUMNS_HELP: &str = "a tet step has 1 column (the scalar at each mesh vertex) or 4 \
    (scalar x y z: the scalar and the vertex's position this step, for a deforming mesh)";

/// The name of column `col`.
pub fn column_name(col: usize) -> &'static str {
    COLUMN_NAMES.get(col).copied().unwrap_or("?")
}

/// Why a step of `rows` rows does not fit a mesh of `vertices` vertices (`None`: no mesh
/// yet), if it does not.
pub fn check_rows(vertices: Option<u64>, rows: u64) -> Option<String> {
    match vertices {
        None => Some("the scene has no mesh yet; send it with PUT .../mesh first".into()),
        Some(n) => (rows != n).then(|| {
            format!(
                "{rows} rows, but the mesh has {n} vertices: a tet step has one scalar per vertex"
            )
        }),
    }
}

/// A JSON step as a raw `ISRA` array of `(V, 1)` f32 (or `(V, 4)` with positions), every
/// value checked.
pub fn raw_from_json(step: &JsonTetStep, vertices: Option<u64>) -> Result<Vec<u8>, KindError> {
    let rows = step.scalars.len() as u64;
    if let Some(why) = check_rows(vertices, rows) {
        return Err(KindError::relational("bad_shape", format!("scalars: {why}")).field("scalars"));
    }
    if let Some(p) = &step.positions {
        if p.len() as u64 != rows {
            return Err(KindError::relational(
                "bad_shape",
                format!(
                    "positions: {} positions for {rows} scalars; a deforming step has one of each per vertex",
                    p.len()
                ),
            )
            .field("positions"));
        }
    }
    let columns: u16 = if step.positions.is_some() { 4 } else { 1 };
    let mut raw =
        Vec::with_capacity(RAW_STEP_HEADER_LEN + step.scalars.len() * 4 * usize::from(columns));
    raw.extend_from_slice(&RAW_STEP_MAGIC);
    raw.extend_from_slice(&[1, 1]);
    raw.extend_from_slice(&columns.to_le_bytes());
    raw.extend_from_slice(&rows.to_le_bytes());
    let finite = |v: f64, field: String| {
        let f = crate::kinds::convert::to_f32(v);
        if f.is_finite() {
            Ok(f)
        } else {
            Err(KindError::invalid(
                "invalid_value",
                format!("{field} = {v} is not a finite f32"),
            )
            .field(field))
        }
    };
    for (i, &v) in step.scalars.iter().enumerate() {
        raw.extend_from_slice(&finite(v, format!("scalars[{i}]"))?.to_le_bytes());
        if let Some(p) = &step.positions {
            for (axis, &c) in p[i].iter().enumerate() {
                let f = finite(c, format!("positions[{i}][{axis}]"))?;
                raw.extend_from_slice(&f.to_le_bytes());
            }
        }
    }
    Ok(raw)
}

/// The positions of a stored `(V, 4)` step payload (little-endian f32, `scalar x y z`).
pub fn positions_of(payload: &[u8]) -> Vec<Vec3> {
    payload
        .chunks_exact(16)
        .map(|row| {
            let f = |k: usize| f32::from_le_bytes([row[k], row[k + 1], row[k + 2], row[k + 3]]);
            Vec3::new(f(4), f(8), f(12))
        })
        .collect()
}

/// The scalars of a stored `(V, columns)` step payload.
pub fn scalars_of(payload: &[u8], columns: usize) -> Vec<f32> {
    payload
        .chunks_exact(4 * columns)
        .map(|row| f32::from_le_bytes([row[0], row[1], row[2], row[3]]))
        .collect()
}

/// Checks a step that moves the mesh's vertices (`columns` 4) as the mesh was checked at
/// creation: every position finite, no tet inverted or degenerate at its new corners. The
/// error names the tet, the corner whose move did it (the first corner that, put back where
/// the mesh has it, makes the tet sound again; else the one that moved farthest), and its
/// vertex, as the field `positions[vertex]`. A scalar-only step passes.
pub fn check_moved(mesh: &TetMesh, columns: u32, payload: &[u8]) -> Result<(), KindError> {
    if columns != 4 {
        return Ok(());
    }
    let moved = positions_of(payload);
    if moved.len() != mesh.vertices().len() {
        return Err(KindError::relational(
            "bad_shape",
            format!(
                "{} positions, but the mesh has {} vertices",
                moved.len(),
                mesh.vertices().len()
            ),
        )
        .field("positions"));
    }
    if let Some(v) = moved.iter().position(|p| !p.is_finite()) {
        return Err(KindError::invalid(
            "invalid_value",
            format!("vertex {v}: its position {} is not finite", moved[v]),
        )
        .field(format!("positions[{v}]")));
    }
    for (tet, ids) in mesh.tets().iter().enumerate() {
        let corners = ids.map(|v| moved[v as usize]);
        let Err(why) = check_tet(tet, corners) else {
            continue;
        };
        let rest = mesh.vertices();
        let corner = (0..4)
            .find(|&k| {
                let mut fixed = corners;
                fixed[k] = rest[ids[k] as usize];
                check_tet(tet, fixed).is_ok()
            })
            .unwrap_or_else(|| {
                (0..4)
                    .map(|k| (k, corners[k].distance(rest[ids[k] as usize])))
                    .fold((0, -1.0f32), |best, c| if c.1 > best.1 { c } else { best })
                    .0
            });
        let vertex = ids[corner];
        // A tet's shape is a rule between values (422), as at the mesh's creation.
        return Err(KindError::relational(
            "invalid_step",
            format!(
                "corner {corner} of {why} after this step's move (vertex {vertex}, moved to {})",
                moved[vertex as usize]
            ),
        )
        .field(format!("positions[{vertex}]")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn payload(rows: &[[f32; 4]]) -> Vec<u8> {
        rows.iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    }

    #[test]
    fn json_positions_become_four_columns_and_bad_ones_are_named() {
        let step = |positions: Option<Vec<[f64; 3]>>| JsonTetStep {
            scalars: vec![0.0, 1.0],
            positions,
        };
        let raw =
            raw_from_json(&step(Some(vec![[0.0; 3], [1.0, 2.0, 3.0]])), Some(2)).expect("valid");
        assert_eq!(u16::from_le_bytes([raw[6], raw[7]]), 4);
        assert_eq!(raw.len(), RAW_STEP_HEADER_LEN + 2 * 16);
        let e = raw_from_json(&step(Some(vec![[0.0; 3], [1.0, 1e300, 3.0]])), Some(2))
            .expect_err("too big for f32");
        assert_eq!(e.field.as_deref(), Some("positions[1][1]"));
        let e = raw_from_json(&step(Some(vec![[0.0; 3]])), Some(2)).expect_err("one short");
        assert_eq!(e.field.as_deref(), Some("positions"));
        let raw = raw_from_json(&step(None), Some(2)).expect("scalars only");
        assert_eq!(u16::from_le_bytes([raw[6], raw[7]]), 1);
    }

    #[test]
    fn a_move_that_inverts_a_tet_names_the_tet_the_corner_and_the_vertex() {
        let mesh = TetMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE],
            vec![[0, 1, 2, 3], [1, 4, 2, 3]],
        )
        .expect("a valid mesh");
        let rows = |moved_z: f32| {
            payload(&[
                [0.0, 0.0, 0.0, 0.0],
                [1.0, 1.0, 0.0, 0.0],
                [2.0, 0.0, 1.0, 0.0],
                [3.0, 0.0, 0.0, moved_z],
                [4.0, 1.0, 1.0, 1.0],
            ])
        };
        // Vertex 3 moved up: both tets still sound.
        check_moved(&mesh, 4, &rows(1.5)).expect("a sound move");
        // Scalar-only steps are not checked for moves.
        check_moved(&mesh, 1, &[0; 20]).expect("no positions");
        // Vertex 3 pushed through the face 0-1-2: tet 0 inverts at its corner 3.
        let e = check_moved(&mesh, 4, &rows(-0.5)).expect_err("inverted");
        assert_eq!(e.field.as_deref(), Some("positions[3]"));
        assert!(
            e.message.contains("corner 3 of tet 0") && e.message.contains("inverted"),
            "{}",
            e.message
        );
        // Flattened onto that face: degenerate.
        let e = check_moved(&mesh, 4, &rows(0.0)).expect_err("degenerate");
        assert!(e.message.contains("degenerate"), "{}", e.message);
        // A vertex moved to infinity is named too.
        let e = check_moved(&mesh, 4, &rows(f32::INFINITY)).expect_err("not finite");
        assert_eq!(e.field.as_deref(), Some("positions[3]"));
    }
}
