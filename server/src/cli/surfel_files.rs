//! Point clouds and triangle meshes for a surfel scene (`isoray push model.ply`): `.xyz`
//! (`x y z [nx ny nz]` per line), `.ply` (ascii or binary; a `face` element makes it a mesh,
//! otherwise its vertices are points, with `nx ny nz` if it has them), `.obj` (faces
//! triangulated) and `.off`. PLY goes through ply-rs-bw and OBJ through tobj, both
//! maintained parsers of formats with many variants; `.xyz` and `.off` are a few lines of
//! text with no crate worth the dependency.

use std::path::Path;

/// What a file holds.
#[derive(Debug, PartialEq)]
pub enum SurfelInput {
    Points {
        positions: Vec<[f64; 3]>,
        normals: Option<Vec<[f64; 3]>>,
    },
    Mesh {
        vertices: Vec<[f64; 3]>,
        triangles: Vec<[u64; 3]>,
    },
}

/// Whether `path` is a point cloud or mesh this module reads.
pub fn is_surfel_input(path: &Path) -> bool {
    matches!(
        path.extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref(),
        Some("xyz" | "ply" | "obj" | "off")
    )
}

/// Reads `path`; the error names the file and what is wrong.
pub fn read(path: &Path) -> Result<SurfelInput, String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let at = |e: String| format!("{}: {e}", path.display());
    match ext.as_str() {
        "xyz" => std::fs::read_to_string(path)
            .map_err(|e| e.to_string())
            .and_then(|t| parse_xyz(&t))
            .map_err(at),
        "off" => std::fs::read_to_string(path)
            .map_err(|e| e.to_string())
            .and_then(|t| parse_off(&t))
            .map_err(at),
        "ply" => read_ply(path).map_err(at),
        "obj" => read_obj(path).map_err(at),
        _ => Err(at(
            "not a point cloud or mesh (.xyz, .ply, .obj, .off)".into()
        )),
    }
}

fn numbers(line: &str, n: usize) -> Result<Vec<f64>, String> {
    line.split_whitespace()
        .take(n)
        .map(|w| {
            w.parse::<f64>()
                .map_err(|_| format!("`{w}` is not a number"))
        })
        .collect()
}

/// `x y z [nx ny nz ...]` per line; `#` starts a comment.
pub fn parse_xyz(text: &str) -> Result<SurfelInput, String> {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut with_normals = None;
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let v = numbers(line, 6).map_err(|e| format!("line {}: {e}", i + 1))?;
        let has = match v.len() {
            3 => false,
            6 => true,
            n => {
                return Err(format!(
                    "line {}: {n} numbers; want x y z or x y z nx ny nz",
                    i + 1
                ))
            }
        };
        if *with_normals.get_or_insert(has) != has {
            return Err(format!(
                "line {}: some points have normals and some not",
                i + 1
            ));
        }
        positions.push([v[0], v[1], v[2]]);
        if has {
            normals.push([v[3], v[4], v[5]]);
        }
    }
    Ok(SurfelInput::Points {
        normals: (with_normals == Some(true)).then_some(normals),
        positions,
    })
}

/// Object File Format: `OFF`, counts, vertices, then faces as `n i0 … in-1` (fanned into
/// triangles).
pub fn parse_off(text: &str) -> Result<SurfelInput, String> {
    let mut lines = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .filter(|l| !l.is_empty());
    let first = lines.next().ok_or("empty file")?;
    let counts = match first.strip_prefix("OFF") {
        Some(rest) if !rest.trim().is_empty() => rest.trim().to_string(),
        Some(_) => lines.next().ok_or("no counts line")?.to_string(),
        None => return Err("does not start with OFF".into()),
    };
    let c = numbers(&counts, 3)?;
    let count = |x: f64| (x >= 0.0 && x.fract() == 0.0).then_some(x as usize);
    let (nv, nf) = match c[..] {
        [v, f, ..] => count(v).zip(count(f)).ok_or(format!(
            "the counts line `{counts}` needs whole numbers of vertices and faces"
        ))?,
        _ => return Err("the counts line needs vertices and faces".into()),
    };
    // Each vertex line takes at least six bytes ("0 0 0\n"), so a count the text cannot hold
    // reserves no more than the text could give.
    let mut vertices = Vec::with_capacity(nv.min(text.len() / 6));
    for i in 0..nv {
        let v = numbers(lines.next().ok_or(format!("vertex {i} missing"))?, 3)?;
        if v.len() < 3 {
            return Err(format!("vertex {i} has {} coordinates", v.len()));
        }
        vertices.push([v[0], v[1], v[2]]);
    }
    let mut triangles = Vec::new();
    for f in 0..nf {
        let line = lines.next().ok_or(format!("face {f} missing"))?;
        let mut words = line.split_whitespace().map(str::parse::<u64>);
        let n = words
            .next()
            .and_then(Result::ok)
            .ok_or(format!("face {f} has no corner count"))?;
        let idx: Vec<u64> = words
            .take(n as usize)
            .collect::<Result<_, _>>()
            .map_err(|_| format!("face {f}: a corner is not an index"))?;
        if idx.len() != n as usize || n < 3 {
            return Err(format!("face {f} has {} corners", idx.len()));
        }
        for k in 1..idx.len() - 1 {
            triangles.push([idx[0], idx[k], idx[k + 1]]);
        }
    }
    Ok(SurfelInput::Mesh {
        vertices,
        triangles,
    })
}

fn read_ply(path: &Path) -> Result<SurfelInput, String> {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::{DefaultElement, Property};
    let mut f = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut f)
        .map_err(|e| format!("not a PLY file: {e}"))?;
    let empty = Vec::new();
    let vertex = ply.payload.get("vertex").unwrap_or(&empty);
    let scalar = |e: &DefaultElement, k: &str| e.get(k).and_then(Property::to_f32_lossy);
    let mut positions = Vec::with_capacity(vertex.len());
    let mut normals = Vec::new();
    for (i, v) in vertex.iter().enumerate() {
        let p = [scalar(v, "x"), scalar(v, "y"), scalar(v, "z")];
        let [Some(x), Some(y), Some(z)] = p else {
            return Err(format!("vertex {i} has no x, y, z"));
        };
        positions.push([x as f64, y as f64, z as f64]);
        if let [Some(a), Some(b), Some(c)] = [scalar(v, "nx"), scalar(v, "ny"), scalar(v, "nz")] {
            normals.push([a as f64, b as f64, c as f64]);
        }
    }
    let Some(faces) = ply.payload.get("face") else {
        let has_normals = !normals.is_empty() && normals.len() == positions.len();
        return Ok(SurfelInput::Points {
            positions,
            normals: has_normals.then_some(normals),
        });
    };
    let mut triangles = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        let list = face
            .get("vertex_indices")
            .or_else(|| face.get("vertex_index"));
        let idx: Vec<i64> = match list {
            Some(Property::ListInt(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListUInt(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListShort(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListUShort(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListChar(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListUChar(v)) => v.iter().map(|&i| i as i64).collect(),
            _ => return Err(format!("face {f} has no integer vertex_indices list")),
        };
        if idx.len() < 3 || idx.iter().any(|&i| i < 0) {
            return Err(format!(
                "face {f}: {idx:?} is not a polygon of vertex indices"
            ));
        }
        for k in 1..idx.len() - 1 {
            triangles.push([idx[0] as u64, idx[k] as u64, idx[k + 1] as u64]);
        }
    }
    Ok(SurfelInput::Mesh {
        vertices: positions,
        triangles,
    })
}

fn read_obj(path: &Path) -> Result<SurfelInput, String> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj(path, &options).map_err(|e| e.to_string())?;
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for m in &models {
        let base = vertices.len() as u64;
        vertices.extend(
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]),
        );
        triangles.extend(
            m.mesh
                .indices
                .chunks_exact(3)
                .map(|t| [base + t[0] as u64, base + t[1] as u64, base + t[2] as u64]),
        );
    }
    Ok(SurfelInput::Mesh {
        vertices,
        triangles,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xyz_and_off_parse_and_bad_lines_are_named() {
        let SurfelInput::Points { positions, normals } =
            parse_xyz("# cloud\n0 0 1 0 0 1\n1 0 0 1 0 0\n").expect("valid")
        else {
            panic!("points");
        };
        assert_eq!(positions.len(), 2);
        assert_eq!(normals.map(|n| n[1]), Some([1.0, 0.0, 0.0]));
        assert!(parse_xyz("0 0 1\n1 0\n")
            .expect_err("short")
            .contains("line 2"));
        assert!(parse_xyz("0 0 1\n1 0 0 1 0 0\n")
            .expect_err("mixed")
            .contains("line 2"));
        let SurfelInput::Mesh { triangles, .. } =
            parse_off("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n").expect("valid")
        else {
            panic!("mesh");
        };
        assert_eq!(triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(parse_off("OFF\n3 1 0\n0 0 0\n")
            .expect_err("short")
            .contains("vertex 1"));
        // A count far beyond the file is a missing vertex, not a reservation of its size.
        assert!(parse_off("OFF\n4000000000000 1 0\n0 0 0\n")
            .expect_err("bomb")
            .contains("vertex 1 missing"));
        assert!(parse_off("OFF\n2.5 1 0\n0 0 0\n")
            .expect_err("fraction")
            .contains("whole numbers"));
    }
}
