//! Step payloads in, step files out: streaming parsers for `.npy`, raw and JSON bodies that
//! validate every value and write the canonical step file (see `format`) as they read.
//!
//! How it works: the HTTP handler forwards body chunks over a bounded channel to a blocking
//! thread, where [`BodyReader`] turns them back into a `Read`. The parser reads the array
//! header, checks the shape and dtype against the limits, then reads whole rows about a
//! megabyte at a time, converts them to f32, checks that every value is finite and every
//! radius positive, hashes them (XXH3-128) and writes them to a temporary file. Nothing is
//! buffered beyond one chunk, and the temporary file is removed on any error ([`TempFile`]),
//! so a rejected push leaves the store as it was. Every error names the field (`shape`,
//! `descr`, `positions[3][1]`, …) or the byte offset in the body where the input went wrong.

use crate::body::{BodyAbort, BodyError, BodyReader};
use crate::kinds::error::{KindError, KindErrorKind};
use crate::kinds::metaballs::step as ball_step;
use crate::kinds::tets::step::raw_from_json;
use crate::kinds::StepLayout;
use crate::npy;
use crate::store::format::{StepHeader, HEADER_LEN};
use isoray_protocol::api::{JsonStep, JsonTetStep, RAW_STEP_HEADER_LEN, RAW_STEP_MAGIC};
use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use xxhash_rust::xxh3::Xxh3;

/// Bytes of rows converted and written per batch.
const BATCH_BYTES: usize = 1 << 20;

/// What went wrong with a push, and where.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct IngestError {
    pub kind: IngestErrorKind,
    pub code: &'static str,
    pub message: String,
    pub field: Option<String>,
    pub offset: Option<u64>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IngestErrorKind {
    /// The input is wrong (400).
    Invalid,
    /// The input is over a size limit (413).
    TooLarge,
    /// The client took too long (408).
    Timeout,
    /// The server could not write (500).
    Io,
    /// The disk (or the user's quota) is full (507).
    StorageFull,
    /// Values that break a rule between them, or with the scene (422; see
    /// `KindErrorKind::Relational`).
    Relational,
}

impl IngestError {
    pub fn invalid(code: &'static str, message: impl Into<String>) -> IngestError {
        IngestError {
            kind: IngestErrorKind::Invalid,
            code,
            message: message.into(),
            field: None,
            offset: None,
        }
    }

    pub fn at_offset(mut self, offset: u64) -> IngestError {
        self.offset = Some(offset);
        self
    }

    pub fn at_field(mut self, field: impl Into<String>) -> IngestError {
        self.field = Some(field.into());
        self
    }

    fn io(e: std::io::Error) -> IngestError {
        if storage_full(&e) {
            return IngestError {
                kind: IngestErrorKind::StorageFull,
                code: "storage_full",
                message: STORAGE_FULL.into(),
                field: None,
                offset: None,
            };
        }
        IngestError {
            kind: IngestErrorKind::Io,
            code: "store_failed",
            message: format!("could not write the step: {e}"),
            field: None,
            offset: None,
        }
    }
}

/// How a body read failure reads in a push.
impl From<BodyError> for IngestError {
    fn from(e: BodyError) -> IngestError {
        let message = e.to_string();
        match e {
            BodyError::Truncated { offset, .. } => {
                IngestError::invalid("truncated", message).at_offset(offset)
            }
            BodyError::Trailing { offset, .. } => {
                IngestError::invalid("trailing_bytes", message).at_offset(offset)
            }
            BodyError::Read {
                abort: Some(BodyAbort::TooLarge(limit)),
                ..
            } => IngestError {
                kind: IngestErrorKind::TooLarge,
                code: "body_too_large",
                message: format!("the body exceeds the limit of {limit} bytes"),
                field: None,
                offset: Some(limit),
            },
            BodyError::Read {
                abort: Some(BodyAbort::Timeout),
                offset,
                ..
            } => IngestError {
                kind: IngestErrorKind::Timeout,
                code: "timeout",
                message: "the body did not arrive within the time limit (--push-timeout-secs)"
                    .into(),
                field: None,
                offset: Some(offset),
            },
            BodyError::Read { offset, error, .. } => IngestError::invalid(
                "body_read_failed",
                format!("reading the body failed: {error}"),
            )
            .at_offset(offset),
        }
    }
}

/// What a kind's step check found, as a push error.
impl From<KindError> for IngestError {
    fn from(e: KindError) -> IngestError {
        let kind = match e.kind {
            KindErrorKind::Relational => IngestErrorKind::Relational,
            KindErrorKind::Invalid | KindErrorKind::Unsupported | KindErrorKind::NotReady => {
                IngestErrorKind::Invalid
            }
        };
        IngestError {
            kind,
            code: e.code,
            message: e.message,
            field: e.field,
            offset: e.offset,
        }
    }
}

/// What a push is checked against: its scene's step layout and the limits.
#[derive(Clone, Copy, Debug)]
pub struct IngestLimits {
    pub layout: StepLayout,
    pub max_rows: u64,
    /// Largest step file, in bytes (the smaller of the per-scene and total budgets).
    pub max_step_bytes: u64,
}

/// Element type of the incoming values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Dtype {
    F32,
    F64,
}

impl Dtype {
    fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F64 => 8,
        }
    }
}

/// A step written to a temporary file, fsynced, not yet in place.
#[derive(Debug)]
pub struct WrittenStep {
    pub temp: TempFile,
    pub header: StepHeader,
}

/// A temporary file removed on drop unless [`TempFile::keep`] was called.
#[derive(Debug)]
pub struct TempFile {
    path: Option<PathBuf>,
}

impl TempFile {
    pub fn path(&self) -> &Path {
        self.path
            .as_deref()
            .expect("path present until keep or drop")
    }

    /// Disarms the removal: the file has been renamed into place.
    pub fn keep(mut self) {
        self.path = None;
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if let Some(path) = self.path.take() {
            if let Err(e) = std::fs::remove_file(&path) {
                if e.kind() != std::io::ErrorKind::NotFound {
                    tracing::warn!(path = %path.display(), error = %e, "cannot remove a temporary step file");
                }
            }
        }
    }
}

/// Writes validated rows to a temporary step file.
struct StepWriter {
    file: File,
    temp: TempFile,
    hasher: Xxh3,
    columns: u32,
    out: Vec<u8>,
}

impl StepWriter {
    fn create(path: PathBuf, columns: u32) -> Result<StepWriter, IngestError> {
        let mut file = File::options()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(IngestError::io)?;
        let temp = TempFile { path: Some(path) };
        file.write_all(&[0u8; HEADER_LEN])
            .map_err(IngestError::io)?;
        Ok(StepWriter {
            file,
            temp,
            hasher: Xxh3::new(),
            columns,
            out: Vec::with_capacity(BATCH_BYTES),
        })
    }

    fn write_rows(&mut self, values: &[f32]) -> Result<(), IngestError> {
        self.out.clear();
        self.out.reserve(values.len() * 4);
        for v in values {
            self.out.extend_from_slice(&v.to_le_bytes());
        }
        self.hasher.update(&self.out);
        self.file.write_all(&self.out).map_err(IngestError::io)
    }

    fn finish(mut self, rows: u64, index: u64, time: f64) -> Result<WrittenStep, IngestError> {
        let header = StepHeader {
            columns: self.columns,
            rows,
            index,
            time,
            checksum: self.hasher.digest128(),
        };
        self.file
            .seek(SeekFrom::Start(0))
            .and_then(|_| self.file.write_all(&header.encode()))
            .and_then(|()| self.file.sync_all())
            .and_then(|()| {
                // Write-once: the store maps step files and never opens them for writing again.
                let mut permissions = self.file.metadata()?.permissions();
                permissions.set_readonly(true);
                self.file.set_permissions(permissions)
            })
            .map_err(IngestError::io)?;
        Ok(WrittenStep {
            temp: self.temp,
            header,
        })
    }
}

/// Checks a batch of whole rows. `first_row` numbers the batch's first row; `value_offset`
/// maps a value's position in the batch to its byte offset in the body.
fn check_rows(
    layout: StepLayout,
    values: &[f32],
    columns: usize,
    first_row: u64,
    value_offset: impl Fn(usize) -> u64,
) -> Result<(), IngestError> {
    // A branch-free pass first (it vectorises); the slow search only runs on bad data.
    let all_finite = values.iter().fold(true, |ok, v| ok & v.is_finite());
    if all_finite && layout.rows_valid(values, columns) {
        return Ok(());
    }
    for (i, v) in values.iter().enumerate() {
        let (row, col) = (first_row + (i / columns) as u64, i % columns);
        let bad = if v.is_finite() {
            layout.check_value(col, *v)
        } else {
            Some(format!("is {v}, not a finite number"))
        };
        if let Some(what) = bad {
            return Err(IngestError::invalid(
                "invalid_value",
                format!(
                    "row {row}, column {col} ({}) {what} (byte offset {})",
                    layout.column_name(col),
                    value_offset(i)
                ),
            )
            .at_field(format!("[{row}][{col}]"))
            .at_offset(value_offset(i)));
        }
    }
    Ok(())
}

/// Checks the declared shape against the limits before any data is read.
fn check_shape(rows: u64, columns: u64, limits: &IngestLimits) -> Result<u32, IngestError> {
    let columns = u32::try_from(columns)
        .ok()
        .filter(|c| limits.layout.allowed_columns().contains(c))
        .ok_or_else(|| {
            IngestError::invalid(
                "bad_shape",
                format!(
                    "an array of {columns} columns; {}",
                    limits.layout.columns_help()
                ),
            )
            .at_field("shape")
        })?;
    if let Some(why) = limits.layout.check_rows(rows) {
        return Err(IngestError::invalid("bad_shape", why).at_field("shape"));
    }
    if rows > limits.max_rows {
        return Err(IngestError::invalid(
            "too_many_primitives",
            format!("{rows} rows exceed the limit of {}", limits.max_rows),
        )
        .at_field("shape"));
    }
    let step_bytes = rows
        .saturating_mul(u64::from(columns) * 4)
        .saturating_add(HEADER_LEN as u64);
    if step_bytes > limits.max_step_bytes {
        return Err(IngestError {
            kind: IngestErrorKind::TooLarge,
            code: "step_too_large",
            message: format!(
                "the step would take {step_bytes} bytes on disk, over the store's limit of {}",
                limits.max_step_bytes
            ),
            field: Some("shape".into()),
            offset: None,
        });
    }
    Ok(columns)
}

/// Reads `rows × columns` values of `dtype`, starting at the reader's current offset.
fn copy_values(
    layout: StepLayout,
    body: &mut BodyReader,
    dtype: Dtype,
    rows: u64,
    columns: u32,
    writer: &mut StepWriter,
) -> Result<(), IngestError> {
    let row_bytes = columns as usize * dtype.size();
    let rows_per_batch = (BATCH_BYTES / row_bytes).max(1) as u64;
    let mut raw = vec![0u8; rows_per_batch as usize * row_bytes];
    let mut values: Vec<f32> = Vec::with_capacity(rows_per_batch as usize * columns as usize);
    let mut row = 0u64;
    while row < rows {
        let n = (rows - row).min(rows_per_batch) as usize;
        let batch = &mut raw[..n * row_bytes];
        let batch_offset = body.offset();
        body.fill(batch, "the array data")?;
        values.clear();
        match dtype {
            Dtype::F32 => values.extend(
                batch
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes(b.try_into().expect("4-byte chunk"))),
            ),
            // A finite f64 too large for f32 becomes infinite and is caught below.
            Dtype::F64 => values.extend(
                batch
                    .chunks_exact(8)
                    .map(|b| f64::from_le_bytes(b.try_into().expect("8-byte chunk")) as f32),
            ),
        }
        let size = dtype.size() as u64;
        check_rows(layout, &values, columns as usize, row, |i| {
            batch_offset + i as u64 * size
        })?;
        writer.write_rows(&values)?;
        row += n as u64;
    }
    Ok(())
}

/// Where and under which identity a step is being written.
pub struct Target {
    pub temp_path: PathBuf,
    pub index: u64,
    pub time: f64,
}

/// Reads a NumPy `.npy` body: a C-ordered `<f4` or `<f8` array of shape `(rows, columns)`.
pub fn ingest_npy(
    mut body: BodyReader,
    limits: &IngestLimits,
    target: Target,
) -> Result<WrittenStep, IngestError> {
    let mut preamble = [0u8; 10];
    body.fill(&mut preamble, "the .npy preamble")?;
    if &preamble[..6] != b"\x93NUMPY" {
        return Err(IngestError::invalid(
            "bad_npy",
            "the body does not start with the .npy magic \\x93NUMPY",
        )
        .at_offset(0));
    }
    let header_len = match preamble[6] {
        1 => u16::from_le_bytes([preamble[8], preamble[9]]) as usize,
        2 | 3 => {
            let mut rest = [0u8; 2];
            body.fill(&mut rest, "the .npy header length")?;
            u32::from_le_bytes([preamble[8], preamble[9], rest[0], rest[1]]) as usize
        }
        v => {
            return Err(IngestError::invalid(
                "bad_npy",
                format!(".npy format version {v} is not supported (1, 2 or 3)"),
            )
            .at_offset(6))
        }
    };
    if header_len > 64 * 1024 {
        return Err(IngestError::invalid(
            "bad_npy",
            format!(".npy header of {header_len} bytes is implausibly long"),
        )
        .at_offset(8));
    }
    let header_offset = body.offset();
    let mut header = vec![0u8; header_len];
    body.fill(&mut header, "the .npy header")?;
    let header = String::from_utf8_lossy(&header);
    let (dtype, shape) = parse_npy_header(&header).map_err(|e| e.at_offset(header_offset))?;
    let (rows, columns) = match shape.as_slice() {
        [rows, columns] => (*rows, *columns),
        _ => {
            return Err(IngestError::invalid(
                "bad_shape",
                format!("shape {shape:?}: a step is a 2-D array (rows, columns)"),
            )
            .at_field("shape")
            .at_offset(header_offset))
        }
    };
    let columns = check_shape(rows, columns, limits)?;
    let mut writer = StepWriter::create(target.temp_path, columns)?;
    copy_values(limits.layout, &mut body, dtype, rows, columns, &mut writer)?;
    body.expect_end("the declared array")?;
    writer.finish(rows, target.index, target.time)
}

/// Picks `descr`, `fortran_order` and `shape` out of the header's Python dict literal.
fn parse_npy_header(header: &str) -> Result<(Dtype, Vec<u64>), IngestError> {
    let value_of = |key: &str| -> Result<&str, IngestError> {
        npy::dict_value(header, key).ok_or_else(|| {
            IngestError::invalid("bad_npy", format!(".npy header has no '{key}'")).at_field(key)
        })
    };
    let descr = value_of("descr")?;
    let dtype = if descr.starts_with("'<f4'") || descr.starts_with("'|f4'") {
        Dtype::F32
    } else if descr.starts_with("'<f8'") || descr.starts_with("'|f8'") {
        Dtype::F64
    } else {
        let shown: String = descr.chars().take(12).collect();
        return Err(IngestError::invalid(
            "bad_dtype",
            format!("dtype {shown}…: a step is little-endian float32 ('<f4') or float64 ('<f8')"),
        )
        .at_field("descr"));
    };
    if !value_of("fortran_order")?.starts_with("False") {
        return Err(IngestError::invalid(
            "bad_npy",
            "the array is in Fortran order; send a C-ordered array (numpy.ascontiguousarray)",
        )
        .at_field("fortran_order"));
    }
    let shape = npy::shape(value_of("shape")?)
        .map_err(|why| IngestError::invalid("bad_npy", why).at_field("shape"))?;
    Ok((dtype, shape))
}

/// Reads a raw body: the 16-byte header of [`RAW_STEP_MAGIC`], then the values.
pub fn ingest_raw(
    mut body: BodyReader,
    limits: &IngestLimits,
    target: Target,
) -> Result<WrittenStep, IngestError> {
    let mut h = [0u8; RAW_STEP_HEADER_LEN];
    body.fill(&mut h, "the 16-byte raw header")?;
    if h[0..4] != RAW_STEP_MAGIC {
        return Err(IngestError::invalid(
            "bad_raw_header",
            "the body does not start with the raw step magic `ISRA`",
        )
        .at_offset(0));
    }
    if h[4] != 1 {
        return Err(IngestError::invalid(
            "bad_raw_header",
            format!("raw header version {} is not supported (1)", h[4]),
        )
        .at_field("version")
        .at_offset(4));
    }
    let dtype = match h[5] {
        1 => Dtype::F32,
        2 => Dtype::F64,
        d => {
            return Err(IngestError::invalid(
                "bad_dtype",
                format!("dtype code {d}: 1 (f32) or 2 (f64)"),
            )
            .at_field("dtype")
            .at_offset(5))
        }
    };
    let columns = u64::from(u16::from_le_bytes([h[6], h[7]]));
    let rows = u64::from_le_bytes(h[8..16].try_into().expect("8 bytes"));
    let columns = check_shape(rows, columns, limits).map_err(|e| e.at_offset(6))?;
    let mut writer = StepWriter::create(target.temp_path, columns)?;
    copy_values(limits.layout, &mut body, dtype, rows, columns, &mut writer)?;
    body.expect_end("the declared array")?;
    writer.finish(rows, target.index, target.time)
}

/// Converts a parsed JSON metaball step to rows (the kind's checks name the JSON field) and
/// writes it.
pub fn ingest_json(
    step: &JsonStep,
    limits: &IngestLimits,
    target: Target,
) -> Result<WrittenStep, IngestError> {
    let columns = ball_step::json_columns(step)?;
    let rows = step.positions.len();
    // A surfel step's rows against the scene's nodes: a rule between the body and the scene
    // (422), as a tet step's scalars against its vertices.
    if let Some(why) = limits.layout.check_rows(rows as u64) {
        return Err(IngestError {
            kind: IngestErrorKind::Relational,
            ..IngestError::invalid("bad_shape", format!("positions: {why}")).at_field("positions")
        });
    }
    let columns_u32 = check_shape(rows as u64, columns as u64, limits)?;
    let values = ball_step::json_rows(step, columns);
    check_rows(limits.layout, &values, columns, 0, |_| 0).map_err(|mut e| {
        // Name the JSON field rather than a row/column pair.
        if let Some(field) = e.field.take() {
            let nums: Vec<usize> = field
                .trim_matches(|c| c == '[' || c == ']')
                .split("][")
                .filter_map(|s| s.parse().ok())
                .collect();
            if let [row, col] = nums[..] {
                e.field = Some(ball_step::json_field(row, col));
                e.message = format!(
                    "{} {}",
                    e.field.as_deref().unwrap_or_default(),
                    e.message.split_once(") ").map_or("", |(_, rest)| rest)
                );
                e.message = e
                    .message
                    .split(" (byte offset")
                    .next()
                    .unwrap_or_default()
                    .to_string();
            }
        }
        e.offset = None;
        e
    })?;
    let mut writer = StepWriter::create(target.temp_path, columns_u32)?;
    for chunk in values.chunks(BATCH_BYTES / 4) {
        writer.write_rows(chunk)?;
    }
    writer.finish(rows as u64, target.index, target.time)
}

/// A tet step sent as JSON: checked value by value by its kind (naming `scalars[i]`), then
/// written like a raw `(V, 1)` array.
pub fn ingest_json_tets(
    step: &JsonTetStep,
    limits: &IngestLimits,
    target: Target,
) -> Result<WrittenStep, IngestError> {
    let vertices = match limits.layout {
        StepLayout::Tets { vertices } => vertices,
        StepLayout::Metaballs => {
            return Err(IngestError {
                kind: IngestErrorKind::Relational,
                ..IngestError::invalid(
                    "bad_shape",
                    "scalars: a metaball step is rows of balls, not scalars",
                )
                .at_field("scalars")
            })
        }
        StepLayout::Surfels { .. } => {
            return Err(IngestError {
                kind: IngestErrorKind::Relational,
                ..IngestError::invalid(
                    "bad_shape",
                    "scalars: a surfel step is the simulation nodes' positions, not scalars",
                )
                .at_field("scalars")
            })
        }
    };
    let raw = raw_from_json(step, vertices)?;
    ingest_raw(BodyReader::from_bytes(raw.into()), limits, target)
}

/// What a client is told when the disk is full.
pub const STORAGE_FULL: &str =
    "the server's disk (or quota) is full: nothing was stored, and what is stored is unchanged; retry once space is freed";

/// Whether `e` says the disk or the quota is full (ENOSPC, EDQUOT).
pub fn storage_full(e: &std::io::Error) -> bool {
    matches!(e.raw_os_error(), Some(28 | 122))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> IngestLimits {
        IngestLimits {
            layout: StepLayout::Metaballs,
            max_rows: 1000,
            max_step_bytes: 1 << 20,
        }
    }

    fn npy(descr: &str, shape: &str, data: &[u8]) -> Vec<u8> {
        let mut header =
            format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(data);
        out
    }

    fn target(dir: &Path) -> Target {
        Target {
            temp_path: dir.join(".tmp-test"),
            index: 0,
            time: 0.0,
        }
    }

    #[test]
    fn npy_f64_is_converted_and_nan_is_located() {
        let dir = tempfile::tempdir().expect("temp dir");
        let values: Vec<u8> = [1.0f64, 2.0, 3.0, 0.5, 4.0, 5.0, 6.0, 0.25]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let body = npy("<f8", "(2, 4)", &values);
        let step = ingest_npy(
            BodyReader::from_bytes(body.clone().into()),
            &limits(),
            target(dir.path()),
        )
        .expect("valid array");
        assert_eq!((step.header.rows, step.header.columns), (2, 4));
        drop(step);
        assert!(
            !dir.path().join(".tmp-test").exists(),
            "temp removed on drop"
        );

        let mut bad = body.clone();
        let nan_at = bad.len() - 8 * 3; // row 1, column 1
        bad[nan_at..nan_at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        let e = ingest_npy(
            BodyReader::from_bytes(bad.into()),
            &limits(),
            target(dir.path()),
        )
        .expect_err("NaN rejected");
        assert_eq!(e.code, "invalid_value");
        assert_eq!(e.offset, Some(nan_at as u64));
        assert_eq!(e.field.as_deref(), Some("[1][1]"));
        assert!(!dir.path().join(".tmp-test").exists());

        let e = ingest_npy(
            BodyReader::from_bytes(body[..body.len() - 3].to_vec().into()),
            &limits(),
            target(dir.path()),
        )
        .expect_err("truncated");
        assert_eq!(e.code, "truncated");
        assert_eq!(e.offset, Some(body.len() as u64 - 3));
    }

    #[test]
    fn npy_wrong_dtype_and_shape_name_the_field() {
        let dir = tempfile::tempdir().expect("temp dir");
        let e = ingest_npy(
            BodyReader::from_bytes(npy("<i4", "(2, 3)", &[0; 24]).into()),
            &limits(),
            target(dir.path()),
        )
        .expect_err("int array");
        assert_eq!(e.field.as_deref(), Some("descr"));
        let e = ingest_npy(
            BodyReader::from_bytes(npy("<f4", "(2, 6)", &[0; 48]).into()),
            &limits(),
            target(dir.path()),
        )
        .expect_err("six columns");
        assert_eq!(e.field.as_deref(), Some("shape"));
    }

    #[test]
    fn json_steps_name_the_bad_scalar() {
        let dir = tempfile::tempdir().expect("temp dir");
        let limits = IngestLimits {
            layout: StepLayout::Tets { vertices: Some(3) },
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
                positions: None,
            },
            &limits,
            target("a"),
        )
        .expect("valid");
        assert_eq!((ok.header.rows, ok.header.columns), (3, 1));
        let e = ingest_json_tets(
            &JsonTetStep {
                scalars: vec![0.0, 1e300, 2.0],
                positions: None,
            },
            &limits,
            target("b"),
        )
        .expect_err("too big for f32");
        assert_eq!(e.field.as_deref(), Some("scalars[1]"));
        let e = ingest_json_tets(
            &JsonTetStep {
                scalars: vec![0.0, 1.0],
                positions: None,
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
