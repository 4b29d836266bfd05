//! Particle files read as metaball steps, for `isoray push` ([`super::push_points`]): CSV
//! (`.csv`, read with the `csv` crate), XYZ (`.xyz`) and NumPy archives (`.npz`: the zip
//! crate opens it, npyz reads each array). No network here, so the fuzz target
//! `points_file` runs these readers as they are.
//!
//! - CSV: a header row naming the columns (any order, any case, surrounding blanks trimmed,
//!   lines starting with `#` skipped): `x`, `y`, `z` and, optionally, `radius`, `strength`
//!   and `red`, `green`, `blue`; other columns are passed over. One file is one step.
//! - XYZ: frames of a count line, a comment line and one `label x y z` line per particle
//!   (further columns passed over); every frame is a step. (An `.xyz` file without the
//!   count line is a point cloud: `isoray push` makes it a surfel scene.)
//! - NPZ (`np.savez`): the array `positions` (also `points`, `pos` or `xyz`), `(N, 3)` for one
//!   step or `(S, N, 3)` for `S` steps, with optional `radius` (`(N,)` / `(S, N)`),
//!   `strength` (same) and `color` (`(N, 3)` / `(S, N, 3)`); float or integer dtypes.
//!
//! A ball's columns are the metaball step's `x y z [radius [strength [r g b]]]`, so a file
//! giving `strength` gives `radius` too (and colour needs both); without a radius the
//! scene's default applies. Errors name the file and the line (CSV, XYZ) or the array (NPZ).

use std::path::Path;

/// One step's rows, `columns` values each.
#[derive(Debug, PartialEq)]
pub struct PointStep {
    pub values: Vec<f32>,
    pub columns: u32,
}

/// Whether `path` names a particle file this module reads. An `.xyz` file is one when its
/// first line is a count (XYZ frames, as chemistry codes write them); `x y z` lines make
/// it a point cloud, for a surfel scene.
pub fn is_points(path: &Path) -> bool {
    match path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .as_deref()
    {
        Some("csv" | "npz") => true,
        Some("xyz") => xyz_has_frames(path),
        _ => false,
    }
}

/// Whether an `.xyz` file's first non-blank line is a single count.
fn xyz_has_frames(path: &Path) -> bool {
    use std::io::BufRead;
    let Ok(file) = std::fs::File::open(path) else {
        return true; // read_steps names the error
    };
    std::io::BufReader::new(file)
        .lines()
        .map_while(Result::ok)
        .find(|l| !l.trim().is_empty())
        .is_some_and(|l| l.trim().parse::<u64>().is_ok())
}

/// The steps of one particle file; errors name the file and where in it.
pub fn read_steps(path: &Path) -> Result<Vec<PointStep>, String> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let steps = match ext.as_str() {
        "csv" => read_csv(path).map(|s| vec![s]),
        "xyz" => std::fs::read_to_string(path)
            .map_err(|e| e.to_string())
            .and_then(|text| read_xyz(&text)),
        _ => read_npz(path),
    };
    steps.map_err(|e| format!("{}: {e}", path.display()))
}

/// The optional columns after `x y z`, in the metaball step's order.
const OPTIONAL: [&str; 5] = ["radius", "strength", "red", "green", "blue"];

/// How many columns a ball row has, given which optional columns are there (`present[k]`
/// for [`OPTIONAL`]`[k]`); a later column without the earlier ones is an error.
fn row_columns(present: [bool; 5]) -> Result<u32, String> {
    let columns = match present {
        [false, false, false, false, false] => 3,
        [true, false, false, false, false] => 4,
        [true, true, false, false, false] => 5,
        [true, true, true, true, true] => 8,
        _ => {
            return Err(format!(
                "columns {:?}: a ball's values are x y z [radius [strength [red green blue]]], \
                 so strength needs radius, and a colour needs radius, strength and all of red, \
                 green and blue",
                OPTIONAL
                    .iter()
                    .zip(present)
                    .filter(|(_, p)| *p)
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
            ))
        }
    };
    Ok(columns)
}

fn read_csv(path: &Path) -> Result<PointStep, String> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_path(path)
        .map_err(|e| e.to_string())?;
    let headers = reader.headers().map_err(|e| e.to_string())?.clone();
    let find = |name: &str| headers.iter().position(|h| h.eq_ignore_ascii_case(name));
    let mut wanted = Vec::new();
    for axis in ["x", "y", "z"] {
        wanted.push(find(axis).ok_or_else(|| {
            format!(
                "line 1: no column `{axis}` in the header ({}); a particle CSV names x, y, z \
                 [radius, strength, red, green, blue]",
                headers.iter().collect::<Vec<_>>().join(", ")
            )
        })?);
    }
    let present = OPTIONAL.map(|name| find(name).is_some());
    let columns = row_columns(present).map_err(|e| format!("line 1: {e}"))?;
    wanted.extend(OPTIONAL.iter().filter_map(|name| find(name)));
    wanted.truncate(columns as usize);
    let mut values = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| match e.position() {
            Some(p) => format!("line {}: {e}", p.line()),
            None => e.to_string(),
        })?;
        let line = record.position().map_or(0, csv::Position::line);
        for &c in &wanted {
            let text = record.get(c).unwrap_or_default();
            let v: f32 = text.parse().map_err(|_| {
                format!(
                    "line {line}, column `{}`: `{text}` is not a number",
                    &headers[c]
                )
            })?;
            if !v.is_finite() {
                return Err(format!(
                    "line {line}, column `{}`: {text} is not finite",
                    &headers[c]
                ));
            }
            values.push(v);
        }
    }
    if values.is_empty() {
        return Err("no particles: the file has a header and no rows".into());
    }
    Ok(PointStep { values, columns })
}

/// XYZ frames: a count, a comment, then `label x y z` lines.
fn read_xyz(text: &str) -> Result<Vec<PointStep>, String> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l)).peekable();
    let mut steps = Vec::new();
    while let Some((n, count_line)) = lines.next() {
        if count_line.trim().is_empty() && lines.peek().is_none_or(|(_, l)| l.trim().is_empty()) {
            continue;
        }
        let count: usize = count_line.trim().parse().map_err(|_| {
            format!(
                "line {n}: `{}` is not a particle count (an XYZ frame starts with the number of \
                 particles, then a comment line)",
                count_line.trim()
            )
        })?;
        let frame = steps.len();
        if lines.next().is_none() {
            return Err(format!(
                "line {}: frame {frame} ends before its comment line",
                n + 1
            ));
        }
        // The count is the file's word: reserve what a frame of at most a million particles
        // needs and grow with the lines there are (`10000000000` asked for 120 GB at once
        // and aborted).
        let mut values = Vec::with_capacity(count.min(1 << 20) * 3);
        for k in 0..count {
            let Some((n, line)) = lines.next() else {
                return Err(format!(
                    "the file ends inside frame {frame}: {k} of {count} particles"
                ));
            };
            let fields: Vec<&str> = line.split_whitespace().collect();
            if fields.len() < 4 {
                return Err(format!("line {n}: `{}` is not `label x y z`", line.trim()));
            }
            for (axis, text) in ["x", "y", "z"].iter().zip(&fields[1..4]) {
                let v: f32 = text
                    .parse()
                    .ok()
                    .filter(|v: &f32| v.is_finite())
                    .ok_or_else(|| format!("line {n}: {axis} `{text}` is not a finite number"))?;
                values.push(v);
            }
        }
        if count == 0 {
            return Err(format!("line {n}: frame {frame} has no particles"));
        }
        steps.push(PointStep { values, columns: 3 });
    }
    if steps.is_empty() {
        return Err("no frames".into());
    }
    Ok(steps)
}

/// An `.npz` archive: a zip of `NAME.npy` files (`np.savez` stores them, `np.savez_compressed`
/// deflates them).
type Npz = zip::ZipArchive<std::io::BufReader<std::fs::File>>;

/// An array's shape and its values as f64, in C order.
type Array = (Vec<u64>, Vec<f64>);

/// An array of an archive as f64, with its shape (`None`: no such array); errors name it.
fn npz_array(archive: &mut Npz, name: &str) -> Result<Option<Array>, String> {
    let at = |e: &dyn std::fmt::Display| format!("array `{name}`: {e}");
    let entry = match archive.by_name(&format!("{name}.npy")) {
        Ok(entry) => entry,
        Err(zip::result::ZipError::FileNotFound) => return Ok(None),
        Err(e) => return Err(at(&e)),
    };
    let file = npyz::NpyFile::new(entry).map_err(|e| at(&e))?;
    let shape = file.shape().to_vec();
    let npyz::DType::Plain(ts) = file.dtype() else {
        return Err(at(&"a structured array; give plain numbers"));
    };
    let values: Vec<f64> = match (ts.type_char(), ts.size_field()) {
        (npyz::TypeChar::Float, 8) => file.into_vec::<f64>().map_err(|e| at(&e))?,
        (npyz::TypeChar::Float, 4) => file
            .into_vec::<f32>()
            .map_err(|e| at(&e))?
            .into_iter()
            .map(f64::from)
            .collect(),
        (npyz::TypeChar::Int, 8) => file
            .into_vec::<i64>()
            .map_err(|e| at(&e))?
            .into_iter()
            .map(|v| v as f64)
            .collect(),
        (npyz::TypeChar::Int, 4) => file
            .into_vec::<i32>()
            .map_err(|e| at(&e))?
            .into_iter()
            .map(f64::from)
            .collect(),
        _ => return Err(at(&format!("dtype {ts}: give float32/64 or int32/64"))),
    };
    if let Some(i) = values.iter().position(|v| !(*v as f32).is_finite()) {
        return Err(at(&format!(
            "value {i} ({}) is not a finite f32",
            values[i]
        )));
    }
    Ok(Some((shape, values)))
}

fn read_npz(path: &Path) -> Result<Vec<PointStep>, String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut archive: Npz = zip::ZipArchive::new(std::io::BufReader::new(file))
        .map_err(|e| format!("not an .npz (zip) archive: {e}"))?;
    let names: Vec<String> = archive
        .file_names()
        .filter_map(|n| {
            n.ok()
                .and_then(|n| n.strip_suffix(".npy").map(str::to_string))
        })
        .collect();
    let Some(pos_name) = ["positions", "points", "pos", "xyz"]
        .into_iter()
        .find(|n| names.iter().any(|m| m == n))
    else {
        return Err(format!(
            "no array `positions` (or `points`, `pos`, `xyz`); the archive holds {names:?}"
        ));
    };
    let Some((shape, positions)) = npz_array(&mut archive, pos_name)? else {
        return Err(format!("array `{pos_name}` is listed but cannot be read"));
    };
    let (steps, n) = match shape[..] {
        [n, 3] => (1, n),
        [s, n, 3] => (s, n),
        _ => {
            return Err(format!(
                "array `{pos_name}` has shape {shape:?}; give (N, 3) for one step or (S, N, 3)"
            ))
        }
    };
    if steps == 0 || n == 0 {
        return Err(format!("array `{pos_name}` is empty (shape {shape:?})"));
    }
    let mut extra: Vec<(Vec<f64>, usize)> = Vec::new();
    let mut present = [false; 5];
    for (k, (name, width)) in [("radius", 1usize), ("strength", 1), ("color", 3)]
        .into_iter()
        .enumerate()
    {
        let Some((shape, values)) = npz_array(&mut archive, name)? else {
            continue;
        };
        let per_step = n * width as u64;
        let ok = values.len() as u64 == per_step || values.len() as u64 == per_step * steps;
        let last = if width == 1 { n } else { 3 };
        if !ok || shape.last() != Some(&last) {
            return Err(format!(
                "array `{name}` has shape {shape:?}; with `{pos_name}` of shape {:?} it must be \
                 ({n}{}) or ({steps}, {n}{})",
                [steps, n, 3],
                if width == 1 { "," } else { ", 3" },
                if width == 1 { "" } else { ", 3" }
            ));
        }
        if k < 2 {
            present[k] = true;
        } else {
            present[2..].fill(true);
        }
        extra.push((values, width));
    }
    let columns = row_columns(present).map_err(|e| format!("arrays: {e}"))?;
    let n = n as usize;
    let mut out = Vec::with_capacity(steps as usize);
    for s in 0..steps as usize {
        let mut values = Vec::with_capacity(n * columns as usize);
        for i in 0..n {
            let p = (s * n + i) * 3;
            values.extend(positions[p..p + 3].iter().map(|&v| v as f32));
            for (data, width) in &extra {
                let per_step = n * width;
                let base = if data.len() == per_step {
                    0
                } else {
                    s * per_step
                };
                let at = base + i * width;
                values.extend(data[at..at + width].iter().map(|&v| v as f32));
            }
        }
        out.push(PointStep { values, columns });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xyz_frames_are_steps_and_bad_lines_are_named() {
        let steps = read_xyz("2\nwater\nO 0 0 0\nH 1 0 0.5\n1\nnext\nC 1 2 3\n").expect("valid");
        assert_eq!(steps.len(), 2);
        assert_eq!(steps[0].values, vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.5]);
        assert_eq!(steps[1].values, vec![1.0, 2.0, 3.0]);
        let e = read_xyz("2\nc\nO 0 0 0\nH 1 zero 0\n").expect_err("bad y");
        assert!(e.contains("line 4") && e.contains("y `zero`"), "{e}");
        let e = read_xyz("3\nc\nO 0 0 0\n").expect_err("short");
        assert!(e.contains("frame 0") && e.contains("1 of 3"), "{e}");
        let e = read_xyz("two\nc\n").expect_err("count");
        assert!(e.contains("line 1"), "{e}");
        // A count far past the file: refused as a short frame, nothing reserved for it.
        for count in ["10000000000", "18446744073709551615"] {
            let e = read_xyz(&format!("{count}\nc\nC 0 0 0\n")).expect_err("short");
            assert!(e.contains(&format!("1 of {count}")), "{e}");
        }
    }

    #[test]
    fn optional_columns_follow_the_metaball_order() {
        assert_eq!(row_columns([false; 5]), Ok(3));
        assert_eq!(row_columns([true, true, false, false, false]), Ok(5));
        assert_eq!(row_columns([true; 5]), Ok(8));
        assert!(row_columns([false, true, false, false, false]).is_err());
        assert!(row_columns([true, true, true, false, false]).is_err());
    }
}
