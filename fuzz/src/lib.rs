//! Shared pieces of the fuzz targets: the `isoray push` VTK readers, which live in the
//! server's binary crate and are compiled here from the same source files.

pub mod cli;

use std::io::Write;
use std::path::PathBuf;

/// Writes `data` to one scratch file per process (the VTK readers take a path, as `isoray
/// push` does) and returns its path.
pub fn scratch_file(data: &[u8], suffix: &str) -> PathBuf {
    static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    let dir = DIR.get_or_init(|| tempfile::tempdir().expect("a scratch directory"));
    let path = dir.path().join(format!("input{suffix}"));
    let mut f = std::fs::File::create(&path).expect("scratch file");
    f.write_all(data).expect("scratch write");
    path
}

/// The step ingest functions' signature (`ingest_npy`, `ingest_raw`).
pub type Ingest = fn(
    isoray_server::body::BodyReader,
    &isoray_server::store::ingest::IngestLimits,
    isoray_server::store::ingest::Target,
) -> Result<
    isoray_server::store::ingest::WrittenStep,
    isoray_server::store::ingest::IngestError,
>;

/// Feeds a pushed step to `ingest`: the first byte picks the layout (even: metaballs; odd: a
/// tet scene of `byte >> 1` vertices), the rest is the body.
pub fn fuzz_step(data: &[u8], ingest: Ingest) {
    use isoray_server::kinds::StepLayout;
    use isoray_server::store::ingest::{IngestLimits, Target};
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let layout = if which & 1 == 0 {
        StepLayout::Metaballs
    } else {
        StepLayout::Tets {
            vertices: Some(u64::from(which >> 1)),
        }
    };
    let limits = IngestLimits {
        layout,
        max_rows: 4096,
        max_step_bytes: 1 << 20,
    };
    let target = Target {
        temp_path: scratch_file(&[], ".step"),
        index: 0,
        time: 0.0,
    };
    let body = isoray_server::body::BodyReader::from_bytes(bytes::Bytes::copy_from_slice(body));
    let _ = ingest(body, &limits, target);
}
