//! A tet scene's mesh on disk: `scenes/<id>/mesh.bin`, written once, crash-safely, and
//! checked in full when the store loads (header and payload checksums, then every tet again
//! by the engine's mesh checks).
//!
//! | offset | size | field |
//! | --- | --- | --- |
//! | 0 | 8 | magic `ISORAYMS` |
//! | 8 | 4 | format version (1) |
//! | 12 | 4 | reserved, 0 |
//! | 16 | 8 | vertices `V` |
//! | 24 | 8 | tets `T` |
//! | 32 | 16 | XXH3-128 of the payload |
//! | 48 | 8 | XXH3-64 of bytes 0..48 |
//! | 56 | 8 | reserved, 0 |
//!
//! then `V × 3` little-endian f32 positions and `T × 4` little-endian u32 vertex indices.
//! Written as `.tmp-mesh.bin`, fsynced, renamed to `mesh.bin`, directory fsynced: after a
//! crash the mesh is wholly there or absent (a leftover temporary file is removed on load).

use crate::kinds::SceneSetup;
use glam::Vec3;
use isoray_render::kinds::tets::TetMesh;
use std::io::Write;
use std::path::Path;
use std::sync::Arc;
use xxhash_rust::xxh3::{xxh3_64, Xxh3};

const MAGIC: [u8; 8] = *b"ISORAYMS";
const VERSION: u32 = 1;
const HEADER_LEN: usize = 64;
const FILE: &str = "mesh.bin";
const TEMP: &str = ".tmp-mesh.bin";

fn payload(mesh: &TetMesh) -> Vec<u8> {
    let mut out = Vec::with_capacity(mesh.vertices().len() * 12 + mesh.tets().len() * 16);
    for v in mesh.vertices() {
        for x in v.to_array() {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    for t in mesh.tets() {
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    out
}

/// The mesh's content identity: XXH3-128 of its payload.
pub fn checksum(mesh: &TetMesh) -> u128 {
    let mut h = Xxh3::new();
    h.update(&payload(mesh));
    h.digest128()
}

fn header(mesh: &TetMesh, checksum: u128) -> [u8; HEADER_LEN] {
    let mut h = [0u8; HEADER_LEN];
    h[0..8].copy_from_slice(&MAGIC);
    h[8..12].copy_from_slice(&VERSION.to_le_bytes());
    h[16..24].copy_from_slice(&(mesh.vertices().len() as u64).to_le_bytes());
    h[24..32].copy_from_slice(&(mesh.tets().len() as u64).to_le_bytes());
    h[32..48].copy_from_slice(&checksum.to_le_bytes());
    let own = xxh3_64(&h[..48]);
    h[48..56].copy_from_slice(&own.to_le_bytes());
    h
}

/// Writes `dir/mesh.bin` crash-safely; returns the payload checksum.
pub fn write(dir: &Path, mesh: &TetMesh) -> std::io::Result<u128> {
    let body = payload(mesh);
    let mut h = Xxh3::new();
    h.update(&body);
    let sum = h.digest128();
    let temp = dir.join(TEMP);
    let mut file = std::fs::File::create(&temp)?;
    let written = file
        .write_all(&header(mesh, sum))
        .and_then(|()| file.write_all(&body))
        .and_then(|()| file.sync_all());
    if let Err(e) = written {
        let _ = std::fs::remove_file(&temp);
        return Err(e);
    }
    drop(file);
    std::fs::rename(&temp, dir.join(FILE))?;
    std::fs::File::open(dir)?.sync_all()?;
    Ok(sum)
}

/// Reads and checks `dir/mesh.bin`: `None` when there is none.
pub fn read(dir: &Path) -> Result<Option<TetMesh>, String> {
    let temp = dir.join(TEMP);
    if temp.exists() {
        tracing::info!(path = %temp.display(), "removing a mesh whose upload was interrupted");
        std::fs::remove_file(&temp).map_err(|e| format!("{TEMP}: {e}"))?;
    }
    let bytes = match std::fs::read(dir.join(FILE)) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("{FILE}: {e}")),
    };
    if bytes.len() < HEADER_LEN || bytes[0..8] != MAGIC {
        return Err(format!("{FILE}: not a mesh file"));
    }
    let u64_at = |at: usize| {
        u64::from_le_bytes(
            bytes[at..at + 8]
                .try_into()
                .expect("8 bytes inside the header"),
        )
    };
    if u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes")) != VERSION {
        return Err(format!("{FILE}: unknown version"));
    }
    if xxh3_64(&bytes[..48]) != u64_at(48) {
        return Err(format!("{FILE}: header checksum mismatch"));
    }
    let (vertices, tets) = (u64_at(16), u64_at(24));
    let expected = vertices
        .checked_mul(12)
        .and_then(|v| tets.checked_mul(16).and_then(|t| v.checked_add(t)));
    let body = &bytes[HEADER_LEN..];
    if expected != Some(body.len() as u64) {
        return Err(format!("{FILE}: payload length does not match the header"));
    }
    let mut h = Xxh3::new();
    h.update(body);
    let sum = u128::from_le_bytes(bytes[32..48].try_into().expect("16 bytes"));
    if h.digest128() != sum {
        return Err(format!("{FILE}: payload checksum mismatch"));
    }
    let (positions, cells) = body.split_at(vertices as usize * 12);
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let positions = positions
        .chunks_exact(12)
        .map(|b| Vec3::new(f(&b[0..]), f(&b[4..]), f(&b[8..])))
        .collect();
    let u = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let cells = cells
        .chunks_exact(16)
        .map(|b| [u(&b[0..]), u(&b[4..]), u(&b[8..]), u(&b[12..])])
        .collect();
    TetMesh::new(positions, cells)
        .map(Some)
        .map_err(|e| format!("{FILE}: {e}"))
}

/// Gives a loaded tet scene its stored mesh, if it has one; a damaged mesh file is renamed
/// to `.corrupt` and logged, and the scene stays without a mesh (its steps show nothing).
pub fn attach(dir: &Path, setup: &SceneSetup) {
    // Only kinds with a static mesh (tets) have one on disk.
    let Some(slot) = setup.mesh_slot() else {
        return;
    };
    match read(dir) {
        Ok(Some(mesh)) => slot.set(Arc::new(mesh)),
        Ok(None) => {}
        Err(e) => {
            tracing::error!(dir = %dir.display(), error = %e, "tet mesh failed verification; renamed to .corrupt and not served");
            let path = dir.join(FILE);
            if let Err(e) = std::fs::rename(&path, path.with_extension("corrupt")) {
                tracing::error!(path = %path.display(), error = %e, "cannot rename a damaged mesh");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mesh() -> TetMesh {
        TetMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE],
            vec![[0, 1, 2, 3], [1, 4, 2, 3]],
        )
        .expect("valid")
    }

    #[test]
    fn meshes_round_trip_and_damage_is_caught() {
        let dir = tempfile::tempdir().expect("temp dir");
        assert_eq!(read(dir.path()), Ok(None));
        let sum = write(dir.path(), &mesh()).expect("written");
        assert_eq!(sum, checksum(&mesh()));
        assert_eq!(read(dir.path()), Ok(Some(mesh())));
        assert!(!dir.path().join(TEMP).exists());
        // A flipped payload byte fails the checksum.
        let path = dir.path().join(FILE);
        let mut bytes = std::fs::read(&path).expect("file");
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(&path, &bytes).expect("write");
        assert!(read(dir.path()).expect_err("damaged").contains("checksum"));
        // A leftover temporary file from a crash is removed.
        std::fs::write(dir.path().join(TEMP), b"half").expect("write");
        std::fs::remove_file(&path).expect("remove");
        assert_eq!(read(dir.path()), Ok(None));
        assert!(!dir.path().join(TEMP).exists());
    }
}
