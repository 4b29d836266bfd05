//! `isoray push` for a VTK series: `.vtu` (XML) or `.vtk` (legacy) unstructured grids, or a
//! `.pvd` collection of them, one file per time step, as a tet scene.
//!
//! The first file's points and cells become the scene's mesh (sent once with `PUT .../mesh`
//! as two `.npy` arrays; hexahedra, wedges and pyramids split into tets, see `vtk_grid`);
//! every file's scalar array becomes a step of one value per vertex (a cell array is moved
//! to the points). A series keeps its connectivity: a file whose cells differ from the
//! first's is refused, naming it. A file whose points moved (a deforming mesh) sends them
//! with its scalars, as a `(V, 4)` step of `scalar x y z`; the server checks that the move
//! inverts no tet. `.vtu` files are read by `vtk_xml` (every
//! encoding and compressor VTK writes), legacy files by vtkio (`vtk_legacy`). Tets whose
//! corners turn the wrong way for VTK's convention are reordered (corners 1 and 2 swapped)
//! and counted, since the server refuses inverted tets.

use super::push_args::{create_scene, put_step, step_path, PushArgs};
use super::vtk_grid::TetGrid;
use isoray_server::api::client::{npy_header, npy_header_f32, Body, Client};
use quick_xml::events::Event;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Whether `path` names a file this module reads.
pub fn is_vtk_series(path: &Path) -> bool {
    matches!(
        path.extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .as_deref(),
        Some("vtu" | "pvd" | "vtk")
    )
}

/// The `.vtu`/`.vtk` files to push, in order, with the time a `.pvd` gives each.
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

/// The `<DataSet timestep=".." file=".."/>` entries of a ParaView collection, in order,
/// read with quick-xml.
fn read_pvd(path: &Path) -> Result<Vec<(PathBuf, Option<f64>)>, String> {
    let at = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let text = std::fs::read(path).map_err(|e| at(&e))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut reader = quick_xml::Reader::from_reader(text.as_slice());
    let mut out = Vec::new();
    loop {
        match reader
            .read_event()
            .map_err(|e| at(&format!("XML error: {e}")))?
        {
            Event::Start(e) | Event::Empty(e) if e.name().as_ref() == b"DataSet" => {
                let i = out.len();
                let value = |name: &str| -> Result<Option<String>, String> {
                    match e.try_get_attribute(name) {
                        Ok(Some(a)) => a
                            .unescape_value()
                            .map(|v| Some(v.into_owned()))
                            .map_err(|err| at(&format!("DataSet {i}: {name}: {err}"))),
                        Ok(None) => Ok(None),
                        Err(err) => Err(at(&format!("DataSet {i}: {err}"))),
                    }
                };
                let file = value("file")?
                    .ok_or_else(|| at(&format!("DataSet {i} has no file attribute")))?;
                let time = match value("timestep")? {
                    Some(t) => Some(t.trim().parse::<f64>().map_err(|_| {
                        at(&format!("DataSet {i} has timestep {t:?}, not a number"))
                    })?),
                    None => None,
                };
                out.push((base.join(file), time));
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if out.is_empty() {
        return Err(at(&"no DataSet entries"));
    }
    Ok(out)
}

/// Reads one file of a series as tets, with the scalar array `array` (or the first
/// one-component point array, else cell array); errors name the file.
pub fn read_tets(path: &Path, array: Option<&str>) -> Result<TetGrid, String> {
    let legacy = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vtk"));
    let grid = if legacy {
        super::vtk_legacy::read(path, array)
    } else {
        super::vtk_xml::read(path, array)
    };
    grid.and_then(super::vtk_grid::Grid::into_tets)
        .map_err(|e| format!("{}: {e}", path.display()))
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

/// Why `cells` (a later file's tets) are not `first`'s, if they are not. A tet whose corners 1
/// and 2 come swapped is the same tet: `vtk_grid` turns each tet by its file's own points,
/// so a tet the move inverted comes back turned; it keeps the first file's order here, and
/// the server refuses the step, naming the tet.
fn same_cells(cells: &[[u64; 4]], first: &[[u64; 4]]) -> Result<(), String> {
    if cells.len() != first.len() {
        return Err(format!("{} tets, not {}", cells.len(), first.len()));
    }
    match cells
        .iter()
        .zip(first)
        .position(|(c, f)| c != f && [c[0], c[2], c[1], c[3]] != *f)
    {
        Some(t) => Err(format!("tet {t} is {:?}, not {:?}", cells[t], first[t])),
        None => Ok(()),
    }
}

/// Pushes a series of `.vtu` files as a tet scene.
pub fn run(args: &PushArgs) -> Result<(), String> {
    let files = expand(&args.files)?;
    let client = Client::new(&args.server).map_err(|e| e.to_string())?;
    let Some((first_path, _)) = files.first() else {
        return Err("no .vtu files to push".into());
    };
    let first = read_tets(first_path, args.array.as_deref())?;
    for note in first.notes() {
        println!("{}: {note}", first_path.display());
    }
    let array = first.picked.name().to_string();
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
            Some(read_tets(file, Some(&array))?)
        };
        if let Some(s) = &step {
            same_cells(&s.cells, &first.cells).map_err(|why| {
                format!(
                    "{}: its cells differ from {}'s ({why}); a series keeps the first file's \
                     cells (its points may move)",
                    file.display(),
                    first_path.display()
                )
            })?;
        }
        let scalars = step.as_ref().map_or(&first.scalars, |s| &s.scalars);
        // Moving points (Lagrangian and ALE codes): each row carries the vertex's position.
        let moved = step
            .as_ref()
            .map(|s| &s.points)
            .filter(|p| **p != first.points);
        let columns = if moved.is_some() { 4 } else { 1 };
        let mut payload = npy_header_f32(scalars.len() as u64, columns);
        for (v, &value) in scalars.iter().enumerate() {
            payload.extend_from_slice(&(value as f32).to_le_bytes());
            if let Some(points) = moved {
                for c in points[v] {
                    payload.extend_from_slice(&(c as f32).to_le_bytes());
                }
            }
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
            "step {index}: {} ({} scalars of {:?}{}, checksum {})",
            answer["outcome"].as_str().unwrap_or("?"),
            scalars.len(),
            array,
            if moved.is_some() {
                " and moved points"
            } else {
                ""
            },
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
    fn reads_tets_and_refuses_missing_points_unknown_cells_and_short_arrays() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("a.vtu");
        let tet = vec![CellType::Tetra];
        write(
            &path,
            &[[0, 1, 2, 3]],
            tet.clone(),
            vec![0.0, 1.0, 2.0, 3.0],
        );
        let step = read_tets(&path, None).expect("a good file");
        assert_eq!(step.cells, vec![[0, 1, 2, 3]]);
        assert_eq!(step.scalars, vec![0.0, 1.0, 2.0, 3.0]);
        assert_eq!(step.picked.name(), "p");

        let two = vec![CellType::Tetra; 2];
        write(&path, &[[0, 1, 2, 3], [0, 1, 7, 3]], two, vec![0.0; 4]);
        let e = read_tets(&path, None).expect_err("point 7 of 4");
        assert!(e.contains("a.vtu") && e.contains("connectivity[6]"), "{e}");
        assert!(e.contains("is 7"), "{e}");

        write(
            &path,
            &[[0, 1, 2, 3]],
            vec![CellType::Polyhedron],
            vec![0.0; 4],
        );
        let e = read_tets(&path, None).expect_err("not a volume cell isoray reads");
        assert!(e.contains("cell 0") && e.contains("tetrahedra"), "{e}");

        write(&path, &[[0, 1, 2, 3]], tet, vec![0.0; 3]);
        let e = read_tets(&path, None).expect_err("3 values for 4 points");
        assert!(e.contains("a.vtu") && e.contains("\"p\""), "{e}");
        let e = read_tets(&path, Some("q")).expect_err("no such array");
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
