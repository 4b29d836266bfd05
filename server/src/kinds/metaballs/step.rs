//! A metaball step sent as JSON: `positions` and, optionally, `radii`, `strengths` and
//! `colors`, one entry per ball. Which arrays are there sets the column count (3, 4, 5 or 8,
//! as in a binary step); the store checks and writes the rows like any other step, and a bad
//! value is named by its JSON field ([`json_field`]).

use crate::kinds::error::KindError;
use isoray_protocol::api::JsonStep;

/// The column count of a JSON step, once its arrays agree in length and each optional array
/// has the ones before it.
pub fn json_columns(step: &JsonStep) -> Result<usize, KindError> {
    let rows = step.positions.len();
    let columns: usize = if step.colors.is_some() {
        8
    } else if step.strengths.is_some() {
        5
    } else if step.radii.is_some() {
        4
    } else {
        3
    };
    let lengths = [
        ("radii", step.radii.as_ref().map(Vec::len)),
        ("strengths", step.strengths.as_ref().map(Vec::len)),
        ("colors", step.colors.as_ref().map(Vec::len)),
    ];
    for (name, len) in lengths {
        if let Some(len) = len.filter(|&l| l != rows) {
            return Err(KindError::relational(
                "bad_shape",
                format!("{name} has {len} entries but positions has {rows}"),
            )
            .field(name));
        }
    }
    if columns == 8 && (step.radii.is_none() || step.strengths.is_none()) {
        return Err(KindError::relational(
            "bad_shape",
            "colors need radii and strengths too (rows are x y z radius strength r g b)",
        )
        .field("colors"));
    }
    if columns == 5 && step.radii.is_none() {
        return Err(
            KindError::relational("bad_shape", "strengths need radii too").field("strengths"),
        );
    }
    Ok(columns)
}

/// The step's rows, `columns` values each, as f32 (a finite f64 too large for f32 becomes
/// infinite, which the row check refuses).
pub fn json_rows(step: &JsonStep, columns: usize) -> Vec<f32> {
    let rows = step.positions.len();
    let mut values = Vec::with_capacity(rows * columns);
    for i in 0..rows {
        let mut row = [0f64; 8];
        row[..3].copy_from_slice(&step.positions[i]);
        if let Some(r) = &step.radii {
            row[3] = r[i];
        }
        if let Some(s) = &step.strengths {
            row[4] = s[i];
        }
        if let Some(c) = &step.colors {
            row[5..8].copy_from_slice(&c[i]);
        }
        values.extend(
            row[..columns]
                .iter()
                .map(|&v| crate::kinds::convert::to_f32(v)),
        );
    }
    values
}

/// The JSON field that holds row `row`, column `col` of a step.
pub fn json_field(row: usize, col: usize) -> String {
    match col {
        0..=2 => format!("positions[{row}][{col}]"),
        3 => format!("radii[{row}]"),
        4 => format!("strengths[{row}]"),
        _ => format!("colors[{row}][{}]", col - 5),
    }
}
