//! A tet mesh sent as a binary body: two arrays back to back, `.npy` (`np.save(f, vertices);
//! np.save(f, cells)`) or raw `ISRA` arrays (see `isoray_protocol::api_tets`), read as a
//! stream within the push size limit. Cells are range-checked as they arrive; the first
//! problem is named by field and byte offset.

use crate::body::{BodyError, BodyReader};
use crate::kinds::error::KindError;
use crate::kinds::tets::mesh::{mesh_error, Offsets};
use crate::npy;
use glam::Vec3;
use isoray_protocol::api::{RAW_STEP_HEADER_LEN, RAW_STEP_MAGIC};
use isoray_render::kinds::tets::{TetError, TetMesh};

/// How a body read failure reads in a mesh upload.
impl From<BodyError> for KindError {
    fn from(e: BodyError) -> KindError {
        let message = e.to_string();
        match e {
            BodyError::Truncated { offset, .. } => {
                KindError::invalid("truncated", message).offset(offset)
            }
            BodyError::Trailing { offset, .. } => {
                KindError::invalid("trailing_bytes", message).offset(offset)
            }
            BodyError::Read { at_end: true, .. } => KindError::invalid("body_read_failed", message),
            BodyError::Read { offset, .. } => KindError::invalid(
                "body_read_failed",
                format!("reading the body failed at byte offset {offset}: {message}"),
            )
            .offset(offset),
        }
    }
}

/// The limits a mesh upload is read within.
#[derive(Clone, Copy, Debug)]
pub struct MeshLimits {
    pub max_tets: u64,
    pub max_vertices: u64,
}

pub fn too_many_tets(n: u64, limit: u64) -> KindError {
    KindError::invalid(
        "too_many_primitives",
        format!("{n} tets exceed the limit of {limit} (--max-primitives)"),
    )
    .field("cells")
}

/// Element types a mesh array may have.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Element {
    F32,
    F64,
    U32,
    U64,
    I32,
    I64,
}

impl Element {
    fn size(self) -> usize {
        match self {
            Element::F32 | Element::U32 | Element::I32 => 4,
            Element::F64 | Element::U64 | Element::I64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Element::F32 | Element::F64)
    }

    /// The value at `b` (little-endian) as f64 (floats) or i128 (integers).
    fn float(self, b: &[u8]) -> f64 {
        match self {
            Element::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            _ => f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
        }
    }

    fn integer(self, b: &[u8]) -> i128 {
        let w4 = || [b[0], b[1], b[2], b[3]];
        let w8 = || [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        match self {
            Element::U32 => u32::from_le_bytes(w4()) as i128,
            Element::I32 => i32::from_le_bytes(w4()) as i128,
            Element::U64 => u64::from_le_bytes(w8()) as i128,
            _ => i64::from_le_bytes(w8()) as i128,
        }
    }
}

/// One array's header: element type and shape, and where its values start.
struct ArrayHead {
    element: Element,
    rows: u64,
    columns: u64,
    data_offset: u64,
}

/// Reads an array header (`.npy` or raw), naming `which` (`vertices` or `cells`) in errors.
fn read_head(r: &mut BodyReader, npy: bool, which: &str) -> Result<ArrayHead, KindError> {
    let start = r.offset();
    let bad = |code: &'static str, message: String, at: u64| {
        KindError::invalid(code, format!("{which}: {message}"))
            .field(which.to_string())
            .offset(at)
    };
    let (element, rows, columns) = if npy {
        let mut pre = [0u8; 10];
        r.fill(&mut pre, &format!("the {which} .npy preamble"))?;
        if &pre[..6] != b"\x93NUMPY" {
            return Err(bad(
                "bad_npy",
                "does not start with the .npy magic \\x93NUMPY".into(),
                start,
            ));
        }
        let len = match pre[6] {
            1 => u16::from_le_bytes([pre[8], pre[9]]) as usize,
            2 | 3 => {
                let mut rest = [0u8; 2];
                r.fill(&mut rest, &format!("the {which} .npy header length"))?;
                u32::from_le_bytes([pre[8], pre[9], rest[0], rest[1]]) as usize
            }
            v => {
                return Err(bad(
                    "bad_npy",
                    format!(".npy format version {v} is not supported (1, 2 or 3)"),
                    start + 6,
                ))
            }
        };
        if len > 64 * 1024 {
            return Err(bad(
                "bad_npy",
                format!("a .npy header of {len} bytes is implausibly long"),
                start + 8,
            ));
        }
        let header_at = r.offset();
        let mut text = vec![0u8; len];
        r.fill(&mut text, &format!("the {which} .npy header"))?;
        let text = String::from_utf8_lossy(&text);
        let value = |key: &str| npy::dict_value(&text, key);
        let descr = value("descr").unwrap_or("");
        let element = [
            ("f4", Element::F32),
            ("f8", Element::F64),
            ("u4", Element::U32),
            ("u8", Element::U64),
            ("i4", Element::I32),
            ("i8", Element::I64),
        ]
        .into_iter()
        .find(|(code, _)| {
            descr.starts_with(&format!("'<{code}'")) || descr.starts_with(&format!("'|{code}'"))
        })
        .map(|(_, e)| e)
        .ok_or_else(|| {
            let shown: String = descr.chars().take(12).collect();
            bad(
                "bad_dtype",
                format!("dtype {shown}: little-endian f4/f8 vertices, i4/i8/u4/u8 cells"),
                header_at,
            )
        })?;
        if !value("fortran_order").is_some_and(|v| v.starts_with("False")) {
            return Err(bad(
                "bad_npy",
                "Fortran order; send C-ordered arrays (numpy.ascontiguousarray)".into(),
                header_at,
            ));
        }
        let dims = value("shape").and_then(|s| npy::shape(s).ok());
        match dims.as_deref() {
            Some([rows, columns]) => (element, *rows, *columns),
            _ => {
                return Err(bad(
                    "bad_shape",
                    "the shape must be 2-D: (V, 3) vertices, then (T, 4) cells".into(),
                    header_at,
                ))
            }
        }
    } else {
        let mut h = [0u8; RAW_STEP_HEADER_LEN];
        r.fill(&mut h, &format!("the {which} raw header"))?;
        if h[0..4] != RAW_STEP_MAGIC {
            return Err(bad(
                "bad_raw_header",
                "does not start with the raw magic `ISRA`".into(),
                start,
            ));
        }
        if h[4] != 1 {
            return Err(bad(
                "bad_raw_header",
                format!("raw header version {} is not supported (1)", h[4]),
                start + 4,
            ));
        }
        let element = match h[5] {
            1 => Element::F32,
            2 => Element::F64,
            3 => Element::U32,
            4 => Element::U64,
            5 => Element::I32,
            6 => Element::I64,
            d => {
                return Err(bad(
                    "bad_dtype",
                    format!("dtype code {d}: 1 f32, 2 f64, 3 u32, 4 u64, 5 i32, 6 i64"),
                    start + 5,
                ))
            }
        };
        let columns = u64::from(u16::from_le_bytes([h[6], h[7]]));
        let rows = u64::from_le_bytes([h[8], h[9], h[10], h[11], h[12], h[13], h[14], h[15]]);
        (element, rows, columns)
    };
    Ok(ArrayHead {
        element,
        rows,
        columns,
        data_offset: r.offset(),
    })
}

/// Reads the two arrays of a binary mesh body and checks the mesh, naming the first problem
/// by field and byte offset.
pub fn read_binary_mesh(
    r: &mut BodyReader,
    npy: bool,
    limits: &MeshLimits,
) -> Result<TetMesh, KindError> {
    const BATCH: usize = 1 << 16;
    let head = read_head(r, npy, "vertices")?;
    if head.columns != 3 || !head.element.is_float() {
        return Err(KindError::invalid(
            "bad_shape",
            format!(
                "vertices: a ({}, {}) array of {:?}; the first array is (V, 3) float32 or float64",
                head.rows, head.columns, head.element
            ),
        )
        .field("vertices")
        .offset(head.data_offset));
    }
    if head.rows > limits.max_vertices {
        return Err(KindError::invalid(
            "too_many_vertices",
            format!(
                "{} vertices exceed the limit of {}",
                head.rows, limits.max_vertices
            ),
        )
        .field("vertices"));
    }
    let size = head.element.size();
    let mut vertices = Vec::with_capacity((head.rows as usize).min(1 << 24));
    let mut buf = vec![0u8; BATCH * 3 * size];
    let mut done = 0u64;
    while done < head.rows {
        let n = ((head.rows - done) as usize).min(BATCH);
        let bytes = &mut buf[..n * 3 * size];
        r.fill(bytes, "the vertices")?;
        for (i, row) in bytes.chunks_exact(3 * size).enumerate() {
            let v = [0, 1, 2].map(|k| head.element.float(&row[k * size..]) as f32);
            let p = Vec3::from_array(v);
            if !p.is_finite() {
                let vertex = done + i as u64;
                return Err(KindError::invalid(
                    "invalid_value",
                    format!("vertex {vertex}: {v:?} is not a finite f32 position"),
                )
                .field(format!("vertices[{vertex}]"))
                .offset(head.data_offset + vertex * 3 * size as u64));
            }
            vertices.push(p);
        }
        done += n as u64;
    }
    let cells_head = read_head(r, npy, "cells")?;
    if cells_head.columns != 4 || cells_head.element.is_float() {
        return Err(KindError::invalid(
            "bad_shape",
            format!(
                "cells: a ({}, {}) array of {:?}; the second array is (T, 4) of integers",
                cells_head.rows, cells_head.columns, cells_head.element
            ),
        )
        .field("cells")
        .offset(cells_head.data_offset));
    }
    if cells_head.rows > limits.max_tets {
        return Err(too_many_tets(cells_head.rows, limits.max_tets));
    }
    let size = cells_head.element.size();
    let vertex_count = vertices.len();
    let at = Offsets {
        vertices: Some((head.data_offset, head.element.size() as u64)),
        cells: Some((cells_head.data_offset, size as u64)),
    };
    let mut cells = Vec::with_capacity((cells_head.rows as usize).min(1 << 24));
    let mut buf = vec![0u8; BATCH * 4 * size];
    let mut done = 0u64;
    while done < cells_head.rows {
        let n = ((cells_head.rows - done) as usize).min(BATCH);
        let bytes = &mut buf[..n * 4 * size];
        r.fill(bytes, "the cells")?;
        for (i, row) in bytes.chunks_exact(4 * size).enumerate() {
            let tet = (done + i as u64) as usize;
            let mut cell = [0u32; 4];
            for (corner, c) in cell.iter_mut().enumerate() {
                let v = cells_head.element.integer(&row[corner * size..]);
                if !(0..vertex_count as i128).contains(&v) {
                    // Named like the engine's own check, with the value as sent.
                    let e = TetError::VertexOutOfRange {
                        tet,
                        corner,
                        vertex: v.clamp(0, u64::MAX as i128) as u64,
                        vertex_count,
                    };
                    let err = mesh_error(e, "", &at);
                    return Err(if v < 0 {
                        err.with_message(format!(
                            "tet {tet}: corner {corner} refers to vertex {v}; indices are not negative"
                        ))
                    } else {
                        err
                    });
                }
                *c = v as u32;
            }
            cells.push(cell);
        }
        done += n as u64;
    }
    r.expect_end("the cells")?;
    TetMesh::new(vertices, cells).map_err(|e| mesh_error(e, "", &at))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(descr: &str, shape: (usize, usize), bytes: &[u8]) -> Vec<u8> {
        let mut header = format!(
            "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}, {}), }}",
            shape.0, shape.1
        );
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(bytes);
        out
    }

    fn body(vertices: &[[f32; 3]], cells: &[[i64; 4]]) -> Vec<u8> {
        let v: Vec<u8> = vertices
            .iter()
            .flatten()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let c: Vec<u8> = cells
            .iter()
            .flatten()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let mut out = npy("<f4", (vertices.len(), 3), &v);
        out.extend(npy("<i8", (cells.len(), 4), &c));
        out
    }

    const LIMITS: MeshLimits = MeshLimits {
        max_tets: 100,
        max_vertices: 100,
    };

    const UNIT: [[f32; 3]; 5] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
    ];

    fn read(bytes: Vec<u8>) -> Result<TetMesh, KindError> {
        read_binary_mesh(&mut BodyReader::from_bytes(bytes.into()), true, &LIMITS)
    }

    #[test]
    fn binary_meshes_read_and_name_the_bad_index_with_its_offset() {
        let mesh = read(body(&UNIT, &[[0, 1, 2, 3], [1, 4, 2, 3]])).expect("valid");
        assert_eq!((mesh.vertices().len(), mesh.tets().len()), (5, 2));
        let bytes = body(&UNIT, &[[0, 1, 2, 3], [1, 2, 3, 7]]);
        let e = read(bytes.clone()).expect_err("index 7 of 5 vertices");
        assert_eq!(e.field.as_deref(), Some("cells[1][3]"));
        assert!(
            e.message.contains("tet 1") && e.message.contains("vertex 7"),
            "{}",
            e.message
        );
        // The offset points at the bad value: 7 as a little-endian i64.
        let at = e.offset.expect("an offset") as usize;
        assert_eq!(&bytes[at..at + 8], &7i64.to_le_bytes());
        let e = read(body(&UNIT, &[[0, 1, 2, -1]])).expect_err("negative");
        assert_eq!(e.field.as_deref(), Some("cells[0][3]"));
        assert!(e.message.contains("-1"), "{}", e.message);
        let e = read(body(&UNIT, &[[0, 2, 1, 3]])).expect_err("inverted");
        assert_eq!(e.field.as_deref(), Some("cells[0]"));
        assert!(e.message.contains("inverted"), "{}", e.message);
        let mut nan = UNIT;
        nan[2][1] = f32::NAN;
        let e = read(body(&nan, &[[0, 1, 2, 3]])).expect_err("NaN");
        assert_eq!(e.field.as_deref(), Some("vertices[2]"));
        let mut truncated = body(&UNIT, &[[0, 1, 2, 3]]);
        truncated.truncate(truncated.len() - 3);
        assert_eq!(read(truncated).expect_err("short").code, "truncated");
        let mut extra = body(&UNIT, &[[0, 1, 2, 3]]);
        extra.push(0);
        assert_eq!(read(extra).expect_err("long").code, "trailing_bytes");
        let v: Vec<u8> = UNIT
            .iter()
            .flatten()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let e = read(npy("<f4", (5, 3), &v)).expect_err("no cells");
        assert_eq!(e.code, "truncated");
        let many: Vec<[i64; 4]> = (0..101).map(|_| [0, 1, 2, 3]).collect();
        assert_eq!(
            read(body(&UNIT, &many)).expect_err("limit").code,
            "too_many_primitives"
        );
    }

    #[test]
    fn raw_meshes_read_too() {
        let mut out = Vec::new();
        let head = |out: &mut Vec<u8>, dtype: u8, columns: u16, rows: u64| {
            out.extend_from_slice(&RAW_STEP_MAGIC);
            out.extend_from_slice(&[1, dtype]);
            out.extend_from_slice(&columns.to_le_bytes());
            out.extend_from_slice(&rows.to_le_bytes());
        };
        head(&mut out, 2, 3, 4);
        for v in &UNIT[..4] {
            for x in v {
                out.extend_from_slice(&(*x as f64).to_le_bytes());
            }
        }
        head(&mut out, 3, 4, 1);
        for i in [0u32, 1, 2, 3] {
            out.extend_from_slice(&i.to_le_bytes());
        }
        let mesh = read_binary_mesh(&mut BodyReader::from_bytes(out.into()), false, &LIMITS)
            .expect("valid");
        assert_eq!(mesh.tets(), &[[0, 1, 2, 3]]);
    }
}
