//! A tet scene's steps: one scalar per mesh vertex, one column. JSON steps
//! (`{"scalars": [...]}`) are checked value by value, naming `scalars[i]`, and become a raw
//! `(V, 1)` array that the store ingests like any other.

use crate::kinds::error::KindError;
use isoray_protocol::api::{JsonTetStep, RAW_STEP_HEADER_LEN, RAW_STEP_MAGIC};

/// The one column's name, for error messages.
pub const COLUMN_NAME: &str = "scalar";

/// What the columns hold, for error messages.
pub const COLUMNS_HELP: &str = "a tet step has 1 column: the scalar at each mesh vertex";

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

/// A JSON step as a raw `ISRA` array of `(V, 1)` f32, every value checked.
pub fn raw_from_json(step: &JsonTetStep, vertices: Option<u64>) -> Result<Vec<u8>, KindError> {
    let rows = step.scalars.len() as u64;
    if let Some(why) = check_rows(vertices, rows) {
        return Err(KindError::relational("bad_shape", format!("scalars: {why}")).field("scalars"));
    }
    let mut raw = Vec::with_capacity(RAW_STEP_HEADER_LEN + step.scalars.len() * 4);
    raw.extend_from_slice(&RAW_STEP_MAGIC);
    raw.extend_from_slice(&[1, 1]);
    raw.extend_from_slice(&1u16.to_le_bytes());
    raw.extend_from_slice(&rows.to_le_bytes());
    for (i, &v) in step.scalars.iter().enumerate() {
        let f = crate::kinds::convert::to_f32(v);
        if !f.is_finite() {
            return Err(KindError::invalid(
                "invalid_value",
                format!("scalars[{i}] = {v} is not a finite f32"),
            )
            .field(format!("scalars[{i}]")));
        }
        raw.extend_from_slice(&f.to_le_bytes());
    }
    Ok(raw)
}
