//! Legacy `.vtk` unstructured grids (ASCII and binary), read with vtkio, which reads them
//! correctly (its XML path is what `vtk_xml` replaces), into the same `Grid` as a `.vtu`.

use super::vtk_grid::{pick_array, Grid, Picked};
use std::io::Read;
use std::path::Path;
use vtkio::model::{Attribute, DataSet};
use vtkio::Vtk;

/// `(name, components)` of each array of an attribute list, legacy fields flattened.
fn names(arrays: &[Attribute]) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    for a in arrays {
        match a {
            Attribute::DataArray(d) => out.push((d.name.clone(), d.num_comp())),
            Attribute::Field { data_array, .. } => {
                out.extend(data_array.iter().map(|f| (f.name.clone(), f.num_comp())));
            }
        }
    }
    out
}

/// The values of the array named `name`.
fn values(arrays: &[Attribute], name: &str) -> Option<Vec<f64>> {
    for a in arrays {
        match a {
            Attribute::DataArray(d) if d.name == name => return d.data.clone().cast_into(),
            Attribute::DataArray(_) => {}
            Attribute::Field { data_array, .. } => {
                if let Some(f) = data_array.iter().find(|f| f.name == name) {
                    return f.data.clone().cast_into();
                }
            }
        }
    }
    None
}

/// Refuses version 5 files (VTK 9's and meshio's default: offsets and connectivity apart),
/// which vtkio 0.6.3 cannot parse, with a message saying what to write instead.
fn check_version(path: &Path) -> Result<(), String> {
    use std::io::BufRead;
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut first = Vec::new();
    std::io::BufReader::new(file)
        .take(256)
        .read_until(b'\n', &mut first)
        .map_err(|e| e.to_string())?;
    let line = String::from_utf8_lossy(&first);
    let version = line
        .trim()
        .strip_prefix("# vtk DataFile Version ")
        .unwrap_or("");
    if version.trim_start().starts_with('5') {
        return Err(format!(
            "line 1: legacy VTK version {} is not read; write version 4.2 (VTK: \
             vtkUnstructuredGridWriter.SetFileVersion(42); meshio: file_format=\"vtk42\") or a \
             .vtu file",
            version.trim()
        ));
    }
    Ok(())
}

/// Reads a legacy `.vtk` unstructured grid with the scalar array `wanted` (or the first
/// one-component point array, else cell array).
pub fn read(path: &Path, wanted: Option<&str>) -> Result<Grid, String> {
    check_version(path)?;
    let vtk = Vtk::import(path).map_err(|e| e.to_string())?;
    let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        return Err("not an unstructured grid (DATASET UNSTRUCTURED_GRID)".into());
    };
    let mut grid = Grid::default();
    for (p, piece) in pieces.into_iter().enumerate() {
        let piece = piece
            .into_loaded_piece_data(Some(path))
            .map_err(|e| format!("piece {p}: {e}"))?;
        let coords: Vec<f64> = piece
            .points
            .cast_into()
            .ok_or("the points are not numbers")?;
        let types: Vec<f64> = piece
            .cells
            .types
            .iter()
            .map(|&t| f64::from(t as u8))
            .collect();
        let (connectivity, offsets) = piece.cells.cell_verts.into_xml();
        let connectivity: Vec<f64> = connectivity.iter().map(|&v| v as f64).collect();
        let offsets: Vec<f64> = offsets.iter().map(|&v| v as f64).collect();
        let picked = pick_array(&names(&piece.data.point), &names(&piece.data.cell), wanted)?;
        let (arrays, count) = match &picked {
            Picked::Point(_) => (&piece.data.point, coords.len() / 3),
            Picked::Cell(_) => (&piece.data.cell, types.len()),
        };
        let scalars = values(arrays, picked.name())
            .ok_or_else(|| format!("array {:?} is not numeric", picked.name()))?;
        if scalars.len() != count {
            return Err(format!(
                "array {:?} has {} values for {count} {}",
                picked.name(),
                scalars.len(),
                match picked {
                    Picked::Point(_) => "points",
                    Picked::Cell(_) => "cells",
                }
            ));
        }
        grid.append(&coords, &connectivity, &offsets, &types, picked, scalars)?;
    }
    Ok(grid)
}
