//! `isoray push` of a point cloud or mesh for a surfel scene: `.xyz`, `.ply` (ascii or
//! binary, through ply-rs-bw), `.obj` (tobj) and `.off`, chosen by the first byte's low two
//! bits; what reads is made into the scene `isoray push` would create, which the server then
//! checks, builds and traces (rest shape and one step; the other bits of the first byte pick
//! how far the nodes move).
#![no_main]
use isoray_fuzz::cli::surfel_files;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let ext = [".xyz", ".ply", ".obj", ".off"][usize::from(which & 3)];
    let path = isoray_fuzz::scratch_file(body, ext);
    if let Ok(input) = surfel_files::read(&path) {
        let scale = [0.0, 0.05, 1.0, 1000.0][usize::from((which >> 2) & 3)];
        isoray_fuzz::exercise_surfels(&isoray_fuzz::surfel_spec_of(input), scale, u64::from(which));
    }
});
