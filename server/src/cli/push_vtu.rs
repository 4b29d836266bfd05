//! `isoray push` for a VTK series: `.vtu` unstructured grids of tetrahedra (or a `.pvd`
//! collection of them), one file per time step, as a tet scene.
//!
//! The first file's points and tetrahedra become the scene's mesh (sent once with
//! `PUT .../mesh` as two `.npy` arrays); every file's point scalar array becomes a step of one
//! value per vertex. A series keeps its connectivity: a file whose points or cells differ
//! from the first's is refused, naming it. Files are read with vtkio (ASCII, base64, raw
//! appended and zlib-compressed XML). Tets whose corners turn the wrong way for VTK's
//! convention are reordered (corners 1 and 2 swapped) and counted, since the server refuses
//! inverted tets.

use super::push_args::{create_scene, put_step, step_path, PushArgs};
use isoray_server::api::client::{npy_header, npy_header_f32, Body, Client};
use std::path::{Path, PathBuf};
use std::time::Instant;
use vtkio::model::{Attribute, CellType, DataSet, ElementType};
use vtkio::Vtk;

/// One file of the series: the mesh it holds and its scalars.
#[derive(Debug, PartialEq)]
pub struct VtuStep {
    pub points: Vec<[f64; 3]>,
    pub cells: Vec<[u64; 4]>,
    pub scalars: Vec<f64>,
    /// The scalar array used.
    pub array: String,
}

/// Whether `path` names a file this module reads.
pub fn is_vtk_series(path: &Path) -> bool {
    matches!(
        path.extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .as_deref(),
        Some("vtu" | "pvd")
    )
}

/// The `.vtu` files to push, in order, with the time a `.pvd` gives each.
pub fn expand(files: &[PathBuf]) -> Result<Vec<(PathBuf, Option<f64>)>, String> {
    let mut out = Vec::new();
    for file in files {
        let is_pvd = file
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("pvd"));
        if is_pvd {
            out.extend(read_pvd(file)?);
        } else {
            out.push((file.clone(), None));
        }
    }
    Ok(out)
}

/// The `<DataSet timestep=".." file=".."/>` entries of a ParaView collection, in order.
fn read_pvd(path: &Path) -> Result<Vec<(PathBuf, Option<f64>)>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let attr = |tag: &str, name: &str| {
        let key = format!("{name}=\"");
        tag.find(&key).and_then(|at| {
            let rest = &tag[at + key.len()..];
            rest.find('"').map(|end| rest[..end].to_string())
        })
    };
    let mut out = Vec::new();
    for (i, tag) in text.split("<DataSet").skip(1).enumerate() {
        let tag = tag.split('>').next().unwrap_or("");
        let file = attr(tag, "file")
            .ok_or_else(|| format!("{}: DataSet {i} has no file attribute", path.display()))?;
        let time = match attr(tag, "timestep") {
            Some(t) => Some(t.trim().parse::<f64>().map_err(|_| {
                format!(
                    "{}: DataSet {i} has timestep {t:?}, not a number",
                    path.display()
                )
            })?),
            None => None,
        };
        out.push((base.join(file), time));
    }
    if out.is_empty() {
        return Err(format!("{}: no DataSet entries", path.display()));
    }
    Ok(out)
}

/// Reads one `.vtu`: its tetrahedra, points and the point array `array` (or the first
/// one-component point array).
pub fn read_vtu(path: &Path, array: Option<&str>) -> Result<VtuStep, String> {
    let at = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let vtk = Vtk::import(path).map_err(|e| at(&e))?;
    let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        return Err(at(&"not an unstructured grid (.vtu)"));
    };
    let mut step = VtuStep {
        points: Vec::new(),
        cells: Vec::new(),
        scalars: Vec::new(),
        array: String::new(),
    };
    for (p, piece) in pieces.into_iter().enumerate() {
        let piece = piece
            .into_loaded_piece_data(Some(path))
            .map_err(|e| at(&format!("piece {p}: {e}")))?;
        let base = step.points.len() as u64;
        let coords: Vec<f64> = piece
            .points
            .cast_into()
            .ok_or_else(|| at(&format!("piece {p}: points are not numbers")))?;
        if coords.len() % 3 != 0 {
            return Err(at(&format!(
                "piece {p}: {} point coordinates, not a multiple of 3",
                coords.len()
            )));
        }
        let count = coords.len() / 3;
        step.points
            .extend(coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        let types = piece.cells.types.clone();
        let (connectivity, offsets) = piece.cells.cell_verts.into_xml();
        if offsets.len() != types.len() {
            return Err(at(&format!(
                "piece {p}: {} cell offsets for {} cell types",
                offsets.len(),
                types.len()
            )));
        }
        let mut start = 0u64;
        for (c, (&end, kind)) in offsets.iter().zip(&types).enumerate() {
            let cell = step.cells.len();
            if *kind != CellType::Tetra {
                return Err(at(&format!(
                    "cell {cell} is a {kind:?}; only tetrahedra (VTK cell type 10) can be pushed"
                )));
            }
            let ids = connectivity
                .get(start as usize..end as usize)
                .filter(|ids| ids.len() == 4)
                .ok_or_else(|| at(&format!("piece {p}: cell {c} does not list 4 points")))?;
            if let Some((corner, id)) = ids.iter().enumerate().find(|(_, &id)| id >= count as u64) {
                return Err(at(&format!(
                    "tet {cell} (piece {p}, cell {c}) corner {corner} references point {id}, \
                     but the piece has {count} points"
                )));
            }
            step.cells
                .push([ids[0] + base, ids[1] + base, ids[2] + base, ids[3] + base]);
            start = end;
        }
        let (name, values) = scalar_array(&piece.data.point, count, array)
            .map_err(|e| at(&format!("piece {p}: {e}")))?;
        if p > 0 && name != step.array {
            return Err(at(&format!(
                "piece {p} uses point array {name:?}, piece 0 {:?}",
                step.array
            )));
        }
        step.array = name;
        step.scalars.extend(values);
    }
    if step.cells.is_empty() {
        return Err(at(&"no cells"));
    }
    Ok(step)
}

/// The named point array, or the first with one component, as f64.
fn scalar_array(
    arrays: &[Attribute],
    points: usize,
    wanted: Option<&str>,
) -> Result<(String, Vec<f64>), String> {
    let names: Vec<&str> = arrays.iter().map(Attribute::name).collect();
    for a in arrays {
        let Attribute::DataArray(d) = a else { continue };
        let one = matches!(
            d.elem,
            ElementType::Scalars { num_comp: 1, .. } | ElementType::Generic(1)
        );
        let pick = match wanted {
            Some(name) => d.name == name,
            None => one,
        };
        if !pick {
            continue;
        }
        if !one {
            return Err(format!(
                "point array {:?} has more than one component",
                d.name
            ));
        }
        let values: Vec<f64> = d
            .data
            .clone()
            .cast_into()
            .ok_or_else(|| format!("point array {:?} is not numeric", d.name))?;
        if values.len() != points {
            return Err(format!(
                "point array {:?} has {} values for {points} points",
                d.name,
                values.len()
            ));
        }
        return Ok((d.name.clone(), values));
    }
    Err(match wanted {
        Some(name) => format!("no point array named {name:?} (there are {names:?})"),
        None => format!("no one-component point array to push (there are {names:?})"),
    })
}

/// Six times the signed volume of a tet, VTK's sign.
/// Corners missing from `points` count as the origin; `read_vtu` has checked them.
fn volume6(points: &[[f64; 3]], cell: &[u64; 4]) -> f64 {
    let p = cell.map(|i| points.get(i as usize).copied().unwrap_or([0.0; 3]));
    let d = |a: [f64; 3], b: [f64; 3]| [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let (a, b, c) = (d(p[0], p[1]), d(p[0], p[2]), d(p[0], p[3]));
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}

/// The body of `PUT .../mesh`: points `(V, 3)` float64, then cells `(T, 4)` int64.
pub fn mesh_body(points: &[[f64; 3]], cells: &[[u64; 4]]) -> Vec<u8> {
    let mut out = npy_header("<f8", points.len() as u64, 3);
    out.extend(points.iter().flatten().flat_map(|v| v.to_le_bytes()));
    out.extend(npy_header("<i8", cells.len() as u64, 4));
    out.extend(
        cells
            .iter()
            .flatten()
            .flat_map(|&v| (v as i64).to_le_bytes()),
    );
    out
}

/// Pushes a series of `.vtu` files as a tet scene.
pub fn run(args: &PushArgs) -> Result<(), String> {
    let files = expand(&args.files)?;
    let client = Client::new(&args.server).map_err(|e| e.to_string())?;
    let Some((first_path, _)) = files.first() else {
        return Err("no .vtu files to push".into());
    };
    let mut first = read_vtu(first_path, args.array.as_deref())?;
    let mut flipped = 0usize;
    for cell in &mut first.cells {
        if volume6(&first.points, cell) < 0.0 {
            cell.swap(1, 2);
            flipped += 1;
        }
    }
    if flipped > 0 {
        println!(
            "{flipped} of {} tets turned the other way from VTK's convention; corners 1 and 2 swapped",
            first.cells.len()
        );
    }
    let (scene, token) = match (&args.scene, &args.token) {
        (Some(scene), Some(token)) => (scene.clone(), token.clone()),
        (Some(_), None) => {
            return Err("--scene needs --token (or ISORAY_TOKEN): the scene's write token".into())
        }
        (None, _) => {
            let (lo, hi) = first
                .scalars
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &s| {
                    (lo.min(s), hi.max(s))
                });
            let default = if lo < hi {
                format!(
                    r#"{{"kind":"tets","isovalue":{},"isovalue_slider":[{lo},{hi}]}}"#,
                    0.5 * (lo + hi)
                )
            } else {
                r#"{"kind":"tets"}"#.to_string()
            };
            create_scene(&client, args, default.as_bytes())?
        }
    };
    let auth = format!("Bearer {token}");
    let started = Instant::now();
    let body = mesh_body(&first.points, &first.cells);
    let r = client
        .request(
            "PUT",
            &format!("/api/v1/scenes/{scene}/mesh"),
            &[
                ("Content-Type", "application/x-npy"),
                ("Authorization", &auth),
            ],
            Body::Bytes(&body),
        )
        .map_err(|e| format!("mesh ({}): {e}", first_path.display()))?;
    if !(r.status == 200 || r.status == 201) {
        return Err(format!(
            "mesh ({}): the server answered {}: {}",
            first_path.display(),
            r.status,
            r.text()
        ));
    }
    println!(
        "mesh: {} vertices, {} tets ({})",
        first.points.len(),
        first.cells.len(),
        if r.status == 201 {
            "stored"
        } else {
            "already there"
        }
    );
    let mut total_bytes = body.len() as u64;
    for (i, (file, pvd_time)) in files.iter().enumerate() {
        let index = args.start + i as u64;
        let step = if i == 0 {
            None
        } else {
            let mut s = read_vtu(file, Some(&first.array))?;
            for cell in &mut s.cells {
                if volume6(&s.points, cell) < 0.0 {
                    cell.swap(1, 2);
                }
            }
            if s.points != first.points || s.cells != first.cells {
                return Err(format!(
                    "{}: its mesh differs from {}'s; a series keeps the first file's points and cells",
                    file.display(),
                    first_path.display()
                ));
            }
            Some(s)
        };
        let scalars = step.as_ref().map_or(&first.scalars, |s| &s.scalars);
        let mut payload = npy_header_f32(scalars.len() as u64, 1);
        for &v in scalars {
            payload.extend_from_slice(&(v as f32).to_le_bytes());
        }
        let time = pvd_time.or(args.time_step.map(|dt| index as f64 * dt));
        let path = step_path(&scene, index, time, args.replace);
        let answer = put_step(
            &client,
            &path,
            &auth,
            "application/x-npy",
            Body::Bytes(&payload),
            &format!("step {index} ({})", file.display()),
        )?;
        println!(
            "step {index}: {} ({} scalars of {:?}, checksum {})",
            answer["outcome"].as_str().unwrap_or("?"),
            scalars.len(),
            first.array,
            answer["step"]["checksum"].as_str().unwrap_or("?")
        );
        total_bytes += payload.len() as u64;
    }
    let secs = started.elapsed().as_secs_f64().max(1e-9);
    println!(
        "pushed a mesh and {} steps to scene {scene}: {:.1} MB in {secs:.2} s",
        files.len(),
        total_bytes as f64 / 1e6
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtkio::model::*;

    /// Writes a one-piece `.vtu` of `cells` over the unit tet's four corners.
    fn write(path: &Path, cells: &[[u64; 4]], types: Vec<CellType>, values: Vec<f32>) {
        let points = vec![0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1.];
        let vtk = Vtk {
            version: Version::new((1, 0)),
            title: String::new(),
            byte_order: ByteOrder::LittleEndian,
            file_path: None,
            data: DataSet::inline(UnstructuredGridPiece {
                points: IOBuffer::F64(points),
                cells: Cells {
                    cell_verts: VertexNumbers::XML {
                        connectivity: cells.iter().flatten().copied().collect(),
                        offsets: (1..=cells.len() as u64).map(|i| 4 * i).collect(),
                    },
                    types,
                },
                data: Attributes {
                    point: vec![Attribute::DataArray(DataArray {
                        name: "p".into(),
                        elem: ElementType::Scalars {
                            num_comp: 1,
                            lookup_table: None,
                        },
                        data: IOBuffer::F32(values),
                    })],
                    cell: vec![],
                },
            }),
        };
        vtk.export(path).expect("vtkio writes");
    }

    #[test]
    fn reads_tets_and_refuses_missing_points_non_tets_and_short_arrays() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("a.vtu");
        let tet = vec![CellType::Tetra];
        write(
            &path,
            &[[0, 1, 2, 3]],
            tet.clone(),
            vec![0.0, 1.0, 2.0, 3.0],
        );
        let step = read_vtu(&path, None).expect("a good file");
        assert_eq!(step.cells, vec![[0, 1, 2, 3]]);
        assert_eq!(step.scalars, vec![0.0, 1.0, 2.0, 3.0]);
        assert_eq!(step.array, "p");
        assert!(volume6(&step.points, &step.cells[0]) > 0.0);

        let two = vec![CellType::Tetra; 2];
        write(&path, &[[0, 1, 2, 3], [0, 1, 7, 3]], two, vec![0.0; 4]);
        let e = read_vtu(&path, None).expect_err("point 7 of 4");
        assert!(
            e.contains("a.vtu") && e.contains("tet 1") && e.contains("corner 2"),
            "{e}"
        );
        assert!(e.contains("point 7"), "{e}");

        write(
            &path,
            &[[0, 1, 2, 3]],
            vec![CellType::Pyramid],
            vec![0.0; 4],
        );
        let e = read_vtu(&path, None).expect_err("not a tet");
        assert!(e.contains("cell 0") && e.contains("tetrahedra"), "{e}");

        write(&path, &[[0, 1, 2, 3]], tet, vec![0.0; 3]);
        // vtkio drops an array of the wrong length; either way the file is refused.
        let e = read_vtu(&path, None).expect_err("3 values for 4 points");
        assert!(e.contains("a.vtu") && e.contains("point array"), "{e}");
        let e = read_vtu(&path, Some("q")).expect_err("no such array");
        assert!(e.contains("\"q\""), "{e}");
    }

    #[test]
    fn pvd_collections_list_files_and_times_in_order() {
        let dir = tempfile::tempdir().expect("temp dir");
        let pvd = dir.path().join("s.pvd");
        std::fs::write(
            &pvd,
            r#"<VTKFile type="Collection"><Collection>
            <DataSet timestep="0.5" file="a.vtu"/><DataSet file="b.vtu" timestep="1"/>
            </Collection></VTKFile>"#,
        )
        .expect("write");
        let files = expand(std::slice::from_ref(&pvd)).expect("read");
        assert_eq!(
            files,
            vec![
                (dir.path().join("a.vtu"), Some(0.5)),
                (dir.path().join("b.vtu"), Some(1.0))
            ]
        );
        std::fs::write(&pvd, r#"<DataSet timestep="soon" file="a.vtu"/>"#).expect("write");
        let e = expand(&[pvd]).expect_err("not a number");
        assert!(e.contains("DataSet 0") && e.contains("soon"), "{e}");
    }
}
