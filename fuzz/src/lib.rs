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
