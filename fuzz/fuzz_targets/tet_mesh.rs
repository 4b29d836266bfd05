//! A tet mesh body: two `.npy` or raw arrays (vertices, cells), checked for every problem.
#![no_main]
use bytes::Bytes;
use isoray_server::body::BodyReader;
use isoray_server::kinds::tets::mesh_body::{read_binary_mesh, MeshLimits};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let limits = MeshLimits {
        max_tets: 1 << 14,
        max_vertices: 1 << 14,
    };
    let mut r = BodyReader::from_bytes(Bytes::copy_from_slice(body));
    let _ = read_binary_mesh(&mut r, which & 1 == 0, &limits);
});
