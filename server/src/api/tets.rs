//! Tetrahedral scenes in the REST API: the static mesh (inline at creation or sent once with
//! `PUT /api/v1/scenes/{id}/mesh`), its checks, and per-step scalar fields as JSON.
//!
//! A tet scene's mesh is static data: it is checked once in full (every index in range, no
//! repeated vertex, no degenerate or inverted tet, finite positions; the first problem is
//! named by field, tet and corner, and for binary bodies by byte offset), written crash-safely
//! beside `scene.json` (see `store::mesh`), and never changes afterwards: sending the same mesh
//! again is a no-op, a different one a 409. Steps are refused until the mesh is there, and
//! each holds exactly one scalar per mesh vertex (`StepLayout::Tets`).
//!
//! Binary mesh bodies are two arrays back to back: `.npy` (`np.save(f, vertices);
//! np.save(f, cells)`) or raw `ISRA` arrays (see `isoray_protocol::api_tets`). The body is
//! read as a stream within the push size limit; cells are range-checked as they arrive.

use super::error::ApiError;
use super::{
    blocking, check_write, forward_body, push_format, read_json, scene_of, stored_of, too_large,
    ApiShared, ClientAddr, PushFormat, BODY_QUEUE,
};
use crate::kind::KindSetup;
use crate::store::ingest::{
    ingest_raw, npy_dict_value, npy_shape, BodyReader, IngestError, IngestLimits, Target,
    WrittenStep,
};
use crate::AppState;
use axum::body::Body;
use axum::extract::rejection::PathRejection;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::{Extension, Json};
use glam::Vec3;
use isoray_protocol::api::{
    ApiErrorBody, JsonTetStep, MeshInfo, TetMeshData, RAW_STEP_HEADER_LEN, RAW_STEP_MAGIC,
};
use isoray_render::tet::{TetError, TetMesh, TetScene};
use std::io::Read;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

/// The static part of a tet scene: its mesh once known, and the colour map's range.
#[derive(Clone, Debug, PartialEq)]
pub struct TetSetup {
    pub mesh: Arc<MeshSlot>,
    pub color_range: (f32, f32),
}

/// A scene's mesh: set once (at creation, on upload or when the store loads), then fixed.
#[derive(Default)]
pub struct MeshSlot {
    mesh: OnceLock<Arc<TetMesh>>,
    /// Serialises uploads, so exactly one writes the mesh file.
    upload: Mutex<()>,
}

impl std::fmt::Debug for MeshSlot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("MeshSlot").field(&self.mesh.get()).finish()
    }
}

impl PartialEq for MeshSlot {
    fn eq(&self, other: &MeshSlot) -> bool {
        self.mesh.get() == other.mesh.get()
    }
}

impl MeshSlot {
    pub fn get(&self) -> Option<&Arc<TetMesh>> {
        self.mesh.get()
    }

    /// Sets the mesh unless one is there already (then it is kept).
    pub fn set(&self, mesh: Arc<TetMesh>) {
        let _ = self.mesh.set(mesh);
    }
}

impl TetSetup {
    /// The engine scene of one step: the mesh with `payload`'s `rows × 1` scalars, or an
    /// empty scene before the mesh or the first step.
    pub fn scene(&self, step: Option<(u32, &[u8])>) -> TetScene {
        let built = self.mesh.get().and_then(|mesh| {
            let (columns, payload) = step?;
            if columns != 1 || payload.len() != mesh.vertices().len() * 4 {
                tracing::warn!(
                    columns,
                    bytes = payload.len(),
                    "a stored tet step does not match its mesh; showing nothing"
                );
                return None;
            }
            let scalars: Vec<f32> = payload
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            TetScene::new(Arc::clone(mesh), scalars.into()).ok()
        });
        let scene = built.unwrap_or_else(empty_scene);
        scene.with_color_range(self.color_range.0, self.color_range.1)
    }

    /// Memory of a prepared step, roughly: 4-D vertices and gradients per vertex, BVH nodes
    /// (about one per six tets) per tet.
    pub fn prepared_bytes(&self) -> u64 {
        self.mesh.get().map_or(0, |m| {
            m.vertices().len() as u64 * 28 + m.tets().len() as u64 * 8
        })
    }
}

fn empty_scene() -> TetScene {
    let mesh = TetMesh::new(Vec::new(), Vec::new()).expect("an empty mesh is valid");
    TetScene::new(Arc::new(mesh), Vec::new().into()).expect("no vertices, no scalars")
}

/// A mesh from the JSON of `tets.mesh` in a creation request (fields named under it).
pub fn mesh_from_spec(data: &TetMeshData) -> Result<TetMesh, ApiError> {
    mesh_from_json(data, "tets.mesh.")
}

fn mesh_from_json(data: &TetMeshData, prefix: &str) -> Result<TetMesh, ApiError> {
    let mut vertices = Vec::with_capacity(data.vertices.len());
    for (i, v) in data.vertices.iter().enumerate() {
        let p = Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
        if !p.is_finite() {
            return Err(ApiError::bad_request(
                "invalid_value",
                format!("vertex {i}: {v:?} is not a finite f32 position"),
            )
            .field(format!("{prefix}vertices[{i}]")));
        }
        vertices.push(p);
    }
    TetMesh::from_indices(vertices, &data.cells).map_err(|e| mesh_error(e, prefix, &Offsets::NONE))
}

/// Where a binary body's arrays start, to name byte offsets in errors.
struct Offsets {
    vertices: Option<(u64, u64)>,
    cells: Option<(u64, u64)>,
}

impl Offsets {
    const NONE: Offsets = Offsets {
        vertices: None,
        cells: None,
    };
}

/// A mesh check's error as an API error naming the field (and the byte offset of the value
/// in a binary body).
fn mesh_error(e: TetError, prefix: &str, at: &Offsets) -> ApiError {
    let cell_offset = |tet: usize, corner: usize| {
        at.cells
            .map(|(start, size)| start + (tet as u64 * 4 + corner as u64) * size)
    };
    let (field, offset) = match &e {
        TetError::VertexOutOfRange { tet, corner, .. } => (
            format!("{prefix}cells[{tet}][{corner}]"),
            cell_offset(*tet, *corner),
        ),
        TetError::RepeatedVertex { tet, .. }
        | TetError::Degenerate { tet, .. }
        | TetError::Inverted { tet, .. } => (format!("{prefix}cells[{tet}]"), cell_offset(*tet, 0)),
        TetError::NotFinite { vertex, .. } => (
            format!("{prefix}vertices[{vertex}]"),
            at.vertices
                .map(|(start, size)| start + *vertex as u64 * 3 * size),
        ),
        TetError::TooManyVertices { .. } | TetError::WrongLength { .. } => {
            (format!("{prefix}vertices"), None)
        }
        _ => (format!("{prefix}cells"), None),
    };
    let err = ApiError::bad_request("invalid_mesh", e.to_string()).field(field);
    match offset {
        Some(o) => err.offset(o),
        None => err,
    }
}

/// 409 when a tet scene has no mesh yet (steps need one); nothing for other kinds.
pub fn check_ready(setup: &crate::kind::SceneSetup) -> Result<(), ApiError> {
    match &setup.kind {
        KindSetup::Tets(t) if t.mesh.get().is_none() => Err(ApiError::new(
            StatusCode::CONFLICT,
            "no_mesh",
            "this tet scene has no mesh yet: send it with PUT /api/v1/scenes/{id}/mesh, then its steps",
        )
        .field("mesh")),
        _ => Ok(()),
    }
}

/// A tet step sent as JSON: checked value by value (naming `scalars[i]`), then written like a
/// raw `(V, 1)` array.
pub fn ingest_json_tets(
    step: &JsonTetStep,
    limits: &IngestLimits,
    target: Target,
) -> Result<WrittenStep, IngestError> {
    let rows = step.scalars.len() as u64;
    if let Some(why) = limits.layout.check_rows(rows) {
        return Err(
            IngestError::invalid("bad_shape", format!("scalars: {why}")).at_field("scalars")
        );
    }
    let mut raw = Vec::with_capacity(RAW_STEP_HEADER_LEN + step.scalars.len() * 4);
    raw.extend_from_slice(&RAW_STEP_MAGIC);
    raw.extend_from_slice(&[1, 1]);
    raw.extend_from_slice(&1u16.to_le_bytes());
    raw.extend_from_slice(&rows.to_le_bytes());
    for (i, &v) in step.scalars.iter().enumerate() {
        let f = v as f32;
        if !f.is_finite() {
            return Err(IngestError::invalid(
                "invalid_value",
                format!("scalars[{i}] = {v} is not a finite f32"),
            )
            .at_field(format!("scalars[{i}]")));
        }
        raw.extend_from_slice(&f.to_le_bytes());
    }
    ingest_raw(BodyReader::from_bytes(raw.into()), limits, target)
}

/// Sends a tet scene's mesh: JSON (`TetMeshData`), two `.npy` arrays one after the other
/// (`(V, 3)` float, then `(T, 4)` integer), or two raw `ISRA` arrays. The mesh is checked in
/// full and stored once; the same mesh again is a no-op, a different one a 409.
#[utoipa::path(
    put,
    path = "/api/v1/scenes/{id}/mesh",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id (a tet scene)")),
    request_body(
        description = "The mesh: JSON, or two arrays back to back (.npy, or raw with the ISRA header)",
        content(
            (TetMeshData = "application/json"),
            ("application/x-npy"),
            ("application/octet-stream")
        )
    ),
    security(("bearer" = [])),
    responses(
        (status = 200, description = "The same mesh was already there", body = MeshInfo),
        (status = 201, description = "Stored", body = MeshInfo),
        (status = 400, description = "Invalid mesh; names the field (tet and corner) or byte offset", body = ApiErrorBody),
        (status = 401, description = "Token missing", body = ApiErrorBody), (status = 403, description = "Token wrong", body = ApiErrorBody),
        (status = 404, description = "Not found", body = ApiErrorBody),
        (status = 408, description = "Body too slow", body = ApiErrorBody),
        (status = 409, description = "Not a tet scene, or a different mesh is there", body = ApiErrorBody),
        (status = 413, description = "Body too large", body = ApiErrorBody),
        (status = 415, description = "Unsupported media type", body = ApiErrorBody),
        (status = 429, description = "Too many writes", body = ApiErrorBody)
    )
)]
pub(super) async fn put_mesh(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    path: Result<Path<String>, PathRejection>,
    body: Body,
) -> Result<(StatusCode, Json<MeshInfo>), ApiError> {
    shared.writes.check(client)?;
    let Path(id) = path.map_err(super::path_error)?;
    let entry = scene_of(&app, &id)?;
    let scene = stored_of(&entry)?;
    check_write(&app, &headers, &scene)?;
    let KindSetup::Tets(setup) = &scene.setup.kind else {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "not_a_tet_scene",
            format!(
                "scene `{id}` is of kind `{}`; only tet scenes have a mesh",
                scene.meta.kind.as_str()
            ),
        )
        .field("id"));
    };
    let slot = Arc::clone(&setup.mesh);
    let format = push_format(&headers)?;
    let config = app.config();
    let limits = MeshLimits {
        max_tets: config.max_primitives as u64,
        max_vertices: u64::from(u32::MAX),
    };
    let body_limit = match format {
        PushFormat::Json => config.max_json_bytes,
        PushFormat::Npy | PushFormat::Raw => config.max_push_bytes,
    };
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > body_limit) {
        return Err(too_large(body_limit).field("Content-Length"));
    }
    let mesh = match format {
        PushFormat::Json => {
            let data: TetMeshData = read_json(&app, body).await?;
            let n = data.cells.len() as u64;
            if n > limits.max_tets {
                return Err(too_many_tets(n, limits.max_tets));
            }
            blocking(move || mesh_from_json(&data, "")).await??
        }
        PushFormat::Npy | PushFormat::Raw => {
            let (tx, rx) = tokio::sync::mpsc::channel(BODY_QUEUE);
            let worker = tokio::task::spawn_blocking(move || {
                let mut reader = Counted::new(BodyReader::new(rx));
                read_binary_mesh(&mut reader, format == PushFormat::Npy, &limits)
            });
            let timeout = Duration::from_secs(config.push_timeout_secs);
            let _received = forward_body(body, tx, body_limit, declared, timeout).await;
            worker
                .await
                .map_err(|e| ApiError::internal(format!("mesh reader failed: {e}")))??
        }
    };
    let dir = scene.dir().to_path_buf();
    let (outcome, checksum, mesh) = blocking(move || {
        let _one = slot.upload.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(existing) = slot.get() {
            return if **existing == mesh {
                Ok((
                    "unchanged",
                    crate::store::mesh::checksum(existing),
                    Arc::clone(existing),
                ))
            } else {
                Err(ApiError::new(
                    StatusCode::CONFLICT,
                    "mesh_exists",
                    "this scene already has a different mesh; a tet scene's mesh never changes \
                     (create a new scene for a new mesh)",
                )
                .field("mesh"))
            };
        }
        let checksum = crate::store::mesh::write(&dir, &mesh).map_err(ApiError::internal)?;
        let mesh = Arc::new(mesh);
        slot.set(Arc::clone(&mesh));
        Ok(("created", checksum, mesh))
    })
    .await??;
    tracing::info!(scene = %id, tets = mesh.tets().len(), outcome, "tet mesh stored");
    let status = if outcome == "created" {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((
        status,
        Json(MeshInfo {
            vertices: mesh.vertices().len() as u64,
            tets: mesh.tets().len() as u64,
            checksum: crate::store::format::checksum_hex(checksum),
            outcome: outcome.into(),
        }),
    ))
}

#[derive(Clone, Copy, Debug)]
struct MeshLimits {
    max_tets: u64,
    max_vertices: u64,
}

fn too_many_tets(n: u64, limit: u64) -> ApiError {
    ApiError::bad_request(
        "too_many_primitives",
        format!("{n} tets exceed the limit of {limit} (--max-primitives)"),
    )
    .field("cells")
}

/// A reader that knows how many bytes it has returned.
struct Counted<R> {
    inner: R,
    offset: u64,
}

impl<R: Read> Counted<R> {
    fn new(inner: R) -> Counted<R> {
        Counted { inner, offset: 0 }
    }

    /// Exactly `out.len()` bytes, or an error naming where the body ended.
    fn fill(&mut self, out: &mut [u8], what: &str) -> Result<(), ApiError> {
        let mut got = 0;
        while got < out.len() {
            let n = match self.inner.read(&mut out[got..]) {
                Ok(n) => n,
                Err(e) => {
                    return Err(ApiError::bad_request(
                        "body_read_failed",
                        format!(
                            "reading the body failed at byte offset {}: {e}",
                            self.offset
                        ),
                    )
                    .offset(self.offset))
                }
            };
            if n == 0 {
                return Err(ApiError::bad_request(
                    "truncated",
                    format!(
                        "the body ends at byte offset {} inside {what}; {} more bytes were expected",
                        self.offset,
                        out.len() - got
                    ),
                )
                .offset(self.offset));
            }
            got += n;
            self.offset += n as u64;
        }
        Ok(())
    }

    fn expect_end(&mut self) -> Result<(), ApiError> {
        let mut one = [0u8; 1];
        match self.inner.read(&mut one) {
            Ok(0) => Ok(()),
            Ok(_) => Err(ApiError::bad_request(
                "trailing_bytes",
                format!(
                    "the body continues past the cells at byte offset {}",
                    self.offset
                ),
            )
            .offset(self.offset)),
            Err(e) => Err(ApiError::bad_request("body_read_failed", e.to_string())),
        }
    }
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
fn read_head<R: Read>(r: &mut Counted<R>, npy: bool, which: &str) -> Result<ArrayHead, ApiError> {
    let start = r.offset;
    let bad = |code: &'static str, message: String, at: u64| {
        ApiError::bad_request(code, format!("{which}: {message}"))
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
        let header_at = r.offset;
        let mut text = vec![0u8; len];
        r.fill(&mut text, &format!("the {which} .npy header"))?;
        let text = String::from_utf8_lossy(&text);
        let value = |key: &str| npy_dict_value(&text, key);
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
        let dims = value("shape").and_then(|s| npy_shape(s).ok());
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
        data_offset: r.offset,
    })
}

/// Reads the two arrays of a binary mesh body and checks the mesh, naming the first problem
/// by field and byte offset.
fn read_binary_mesh<R: Read>(
    r: &mut Counted<R>,
    npy: bool,
    limits: &MeshLimits,
) -> Result<TetMesh, ApiError> {
    const BATCH: usize = 1 << 16;
    let head = read_head(r, npy, "vertices")?;
    if head.columns != 3 || !head.element.is_float() {
        return Err(ApiError::bad_request(
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
        return Err(ApiError::bad_request(
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
                return Err(ApiError::bad_request(
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
        return Err(ApiError::bad_request(
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
    r.expect_end()?;
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

    fn read(bytes: Vec<u8>) -> Result<TetMesh, ApiError> {
        read_binary_mesh(&mut Counted::new(&bytes[..]), true, &LIMITS)
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
        let mesh = read_binary_mesh(&mut Counted::new(&out[..]), false, &LIMITS).expect("valid");
        assert_eq!(mesh.tets(), &[[0, 1, 2, 3]]);
    }

    #[test]
    fn json_steps_name_the_bad_scalar() {
        let dir = tempfile::tempdir().expect("temp dir");
        let limits = IngestLimits {
            layout: crate::kind::StepLayout::Tets { vertices: Some(3) },
            max_rows: 100,
            max_step_bytes: 1 << 20,
        };
        let target = |name: &str| Target {
            temp_path: dir.path().join(name),
            index: 0,
            time: 0.0,
        };
        let ok = ingest_json_tets(
            &JsonTetStep {
                scalars: vec![0.0, 1.0, 2.0],
            },
            &limits,
            target("a"),
        )
        .expect("valid");
        assert_eq!((ok.header.rows, ok.header.columns), (3, 1));
        let e = ingest_json_tets(
            &JsonTetStep {
                scalars: vec![0.0, 1e300, 2.0],
            },
            &limits,
            target("b"),
        )
        .expect_err("too big for f32");
        assert_eq!(e.field.as_deref(), Some("scalars[1]"));
        let e = ingest_json_tets(
            &JsonTetStep {
                scalars: vec![0.0, 1.0],
            },
            &limits,
            target("c"),
        )
        .expect_err("one short");
        assert_eq!(e.field.as_deref(), Some("scalars"));
        assert!(e.message.contains("3 vertices"), "{}", e.message);
        assert!(!dir.path().join("b").exists() && !dir.path().join("c").exists());
    }
}
