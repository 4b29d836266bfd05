//! Legacy `.vtk` unstructured grids (ASCII and binary), read with vtkio, which reads them
//! correctly (its XML path is what `vtk_xml` replaces), into the same `Grid` as a `.vtu`.
//! Version 5.1 (VTK 9's and meshio's default) is read by rewriting its cells section into
//! the older layout vtkio knows ([`downgrade_version_5`]).

use super::vtk_grid::{pick_array, Grid, Picked};
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

/// Whether the file is legacy version 5: its first line (within 256 bytes) says so.
fn is_version_5(bytes: &[u8]) -> bool {
    let head = &bytes[..bytes.len().min(256)];
    let first = head.split(|&b| b == b'\n').next().unwrap_or_default();
    String::from_utf8_lossy(first)
        .trim()
        .strip_prefix("# vtk DataFile Version ")
        .is_some_and(|v| v.trim_start().starts_with('5'))
}

/// A cursor over a legacy file's bytes: keyword lines, and numbers in ASCII or binary
/// (big-endian, as the format stores them).
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Cursor<'_> {
    /// The next non-blank line, trimmed.
    fn line(&mut self) -> Result<String, String> {
        loop {
            let rest = self.bytes.get(self.pos..).unwrap_or_default();
            if rest.is_empty() {
                return Err("the file ends inside the CELLS section".into());
            }
            let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            self.pos += (end + 1).min(rest.len());
            let line = String::from_utf8_lossy(&rest[..end]).trim().to_string();
            if !line.is_empty() {
                return Ok(line);
            }
        }
    }

    /// `n` integers of `width` bytes (binary) or as text.
    fn ints(
        &mut self,
        n: usize,
        width: usize,
        binary: bool,
        what: &str,
    ) -> Result<Vec<i64>, String> {
        let short = || format!("{what}: the file ends before its {n} values");
        if binary {
            let end = n
                .checked_mul(width)
                .and_then(|len| self.pos.checked_add(len))
                .ok_or_else(short)?;
            let raw = self.bytes.get(self.pos..end).ok_or_else(short)?;
            self.pos = end;
            Ok(raw
                .chunks_exact(width)
                .map(|c| match width {
                    4 => i64::from(i32::from_be_bytes([c[0], c[1], c[2], c[3]])),
                    _ => i64::from_be_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]),
                })
                .collect())
        } else {
            let mut out = Vec::with_capacity(n.min(1 << 24));
            while out.len() < n {
                let rest = self.bytes.get(self.pos..).unwrap_or_default();
                let start = rest
                    .iter()
                    .position(|b| !b.is_ascii_whitespace())
                    .ok_or_else(short)?;
                let len = rest[start..]
                    .iter()
                    .position(u8::is_ascii_whitespace)
                    .unwrap_or(rest.len() - start);
                let word = String::from_utf8_lossy(&rest[start..start + len]);
                out.push(
                    word.parse().map_err(|_| {
                        format!("{what}[{}]: `{word}` is not an integer", out.len())
                    })?,
                );
                self.pos += start + len;
            }
            Ok(out)
        }
    }
}

/// The byte width of a version 5 array type.
fn int_width(header: &str, keyword: &str) -> Result<usize, String> {
    match header.strip_prefix(keyword).map(str::trim) {
        Some("vtktypeint64") => Ok(8),
        Some("vtktypeint32") => Ok(4),
        _ => Err(format!(
            "expected `{keyword} vtktypeint64` (or vtktypeint32), found `{header}`"
        )),
    }
}

/// VTK 9 and meshio write legacy version 5.1 by default, which keeps a grid's cells as two
/// arrays, OFFSETS and CONNECTIVITY; vtkio 0.6.3 reads only the older layout, one list of
/// `count id id ...` rows. This rewrites the CELLS section into that layout (checking the
/// offsets: from 0, not decreasing, ending at the connectivity's length) and the first line
/// to version 4.2; every other byte stays as it was. The answer is a reader over the file's
/// own bytes with the new first line and cells section spliced in, so the file is not
/// copied again before vtkio reads it.
fn downgrade_version_5(bytes: &[u8]) -> Result<impl std::io::Read + '_, String> {
    let binary = bytes.split(|&b| b == b'\n').nth(2).is_some_and(|l| {
        String::from_utf8_lossy(l)
            .trim()
            .eq_ignore_ascii_case("BINARY")
    });
    let cells_at = bytes
        .windows(7)
        .position(|w| w == b"\nCELLS ")
        .map(|p| p + 1)
        .ok_or("version 5: no CELLS section")?;
    let mut cur = Cursor {
        bytes,
        pos: cells_at,
    };
    let header = cur.line()?;
    let sizes: Vec<usize> = header
        .split_whitespace()
        .skip(1)
        .map(str::parse)
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{header}`: expected CELLS <offsets> <connectivity>"))?;
    let [n_offsets, n_conn] = sizes[..] else {
        return Err(format!(
            "`{header}`: expected CELLS <offsets> <connectivity>"
        ));
    };
    let width = int_width(&cur.line()?, "OFFSETS")?;
    let offsets = cur.ints(n_offsets, width, binary, "OFFSETS")?;
    let width = int_width(&cur.line()?, "CONNECTIVITY")?;
    let conn = cur.ints(n_conn, width, binary, "CONNECTIVITY")?;
    if offsets.first().is_some_and(|&o| o != 0)
        || offsets.last().is_some_and(|&o| o != n_conn as i64)
    {
        return Err(format!(
            "OFFSETS must run from 0 to the connectivity's length {n_conn}"
        ));
    }
    let cells = n_offsets.saturating_sub(1);
    let mut out = Vec::with_capacity(4 * (cells + n_conn) + 32);
    out.extend_from_slice(format!("CELLS {cells} {}\n", cells + n_conn).as_bytes());
    for (c, pair) in offsets.windows(2).enumerate() {
        let (a, b) = (pair[0], pair[1]);
        if b < a || b > n_conn as i64 {
            return Err(format!(
                "OFFSETS[{}] = {b} is below OFFSETS[{c}] = {a} or past the connectivity",
                c + 1
            ));
        }
        let ids = &conn[a as usize..b as usize];
        let count = i32::try_from(ids.len()).map_err(|_| format!("cell {c} is too large"))?;
        let id =
            |v: i64| i32::try_from(v).map_err(|_| format!("cell {c}: vertex {v} is out of range"));
        if binary {
            out.extend_from_slice(&count.to_be_bytes());
            for &v in ids {
                out.extend_from_slice(&id(v)?.to_be_bytes());
            }
        } else {
            let row: Vec<String> = std::iter::once(count.to_string())
                .chain(ids.iter().map(i64::to_string))
                .collect();
            out.extend_from_slice(row.join(" ").as_bytes());
            out.push(b'\n');
        }
    }
    out.push(b'\n');
    use std::io::Read;
    let first_line = bytes.iter().position(|&b| b == b'\n').unwrap_or(0);
    Ok((&b"# vtk DataFile Version 4.2"[..])
        .chain(&bytes[first_line..cells_at])
        .chain(std::io::Cursor::new(out))
        .chain(&bytes[cur.pos..]))
}

/// Refuses a file whose sections declare more values than its bytes could hold, before vtkio
/// reads it: vtkio reserves a section's declared count up front, so a 4 KiB file declaring
/// `CELL_TYPES 3251968700` made it ask for gigabytes and abort (found by the `vtk_file`
/// fuzz target). Every value takes at least one byte, binary or text, so in a real file
/// `POINTS n` has `3n`, `CELLS n size` has `size`, a `FIELD` array `name c t type` has `c·t`
/// and every other count at most the file's length. Counts are read from the lines that
/// start with a keyword (or, inside a `FIELD`, a name) followed by integers; a line of
/// binary data that happens to look like one is checked too, which can only refuse a file
/// whose numbers there exceed its length.
fn check_counts(bytes: &[u8]) -> Result<(), String> {
    let len = bytes.len() as u128;
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate().skip(2) {
        let Ok(line) = std::str::from_utf8(line) else {
            continue;
        };
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some(first) = words.first() else { continue };
        if !first.starts_with(|c: char| c.is_ascii_alphabetic()) {
            continue;
        }
        let ints: Vec<u128> = words.iter().filter_map(|w| w.parse().ok()).collect();
        let values = match *first {
            "CELLS" => ints.iter().copied().max().unwrap_or(0),
            "POINTS" => ints.first().map_or(0, |n| n.saturating_mul(3)),
            _ => ints.iter().fold(1u128, |p, &n| p.saturating_mul(n)),
        };
        if !ints.is_empty() && (values > len || ints.iter().any(|&n| n > len)) {
            return Err(format!(
                "line {}: `{}` declares {values} values, more than the file's {len} bytes could hold",
                i + 1,
                line.trim()
            ));
        }
    }
    Ok(())
}

/// Reads a legacy `.vtk` unstructured grid with the scalar array `wanted` (or the first
/// one-component point array, else cell array).
pub fn read(path: &Path, wanted: Option<&str>) -> Result<Grid, String> {
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    check_counts(&bytes)?;
    let vtk = if is_version_5(&bytes) {
        let older = downgrade_version_5(&bytes).map_err(|e| format!("legacy VTK 5.1: {e}"))?;
        Vtk::parse_legacy_be(older)
    } else {
        Vtk::parse_legacy_be(&bytes[..])
    }
    .map_err(|e| e.to_string())?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-tet legacy 5.1 file as meshio writes it, with `cell_types` as its CELL_TYPES
    /// line's count.
    fn file(cell_types: &str) -> String {
        format!(
            "# vtk DataFile Version 5.1\nwritten by meshio v5.3.5\nASCII\n\
             DATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n0 0 0 1 0 0 0 1 0 0 0 1\n\
             CELLS 2 4\nOFFSETS vtktypeint64\n0 4\nCONNECTIVITY vtktypeint64\n0 1 2 3\n\
             CELL_TYPES {cell_types}\n10\n\nPOINT_DATA 4\nFIELD FieldData 1\n\
             u 1 4 double\n0 0.5 1 1.5\n"
        )
    }

    #[test]
    fn a_count_the_file_cannot_hold_is_refused_before_vtkio_reserves_it() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("tet.vtk");
        std::fs::write(&path, file("1")).expect("written");
        let grid = read(&path, None).expect("the honest file reads");
        assert_eq!(grid.into_tets().expect("one tet").cells, vec![[0, 1, 2, 3]]);
        // The extension's case does not matter (vtkio's own import wanted `.vtk`).
        let upper = dir.path().join("TET.VTK");
        std::fs::write(&upper, file("1")).expect("written");
        assert!(read(&upper, None).is_ok());

        // The fuzz target's input (a 4 KiB meshio file) declared 3,251,968,700 cell types:
        // vtkio asked for gigabytes and the process aborted.
        std::fs::write(&path, file("3251968700")).expect("written");
        let e = read(&path, None).expect_err("more cell types than bytes");
        assert!(
            e.contains("line 12") && e.contains("CELL_TYPES 3251968700"),
            "{e}"
        );

        // Points count three values each; a field array its components times its tuples.
        let lying = file("1").replace("POINTS 4 double", "POINTS 100 double");
        assert!(check_counts(lying.as_bytes())
            .expect_err("3 × 100")
            .contains("300 values"));
        let lying = file("1").replace("u 1 4 double", "u 1000 400 double");
        assert!(
            check_counts(lying.as_bytes()).is_err(),
            "400,000 field values"
        );
        // Every count within the file's length, whatever the cells' two sizes multiply to.
        let fine = file("1").replace("CELLS 2 4", "CELLS 40 100");
        assert!(check_counts(fine.as_bytes()).is_ok());
    }
}
