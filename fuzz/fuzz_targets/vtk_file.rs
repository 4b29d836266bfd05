//! `isoray push` of a VTK file: XML `.vtu` (raw, base64, appended, zlib/lz4/lzma blocks) and
//! legacy `.vtk`, chosen by the first byte.
#![no_main]
use isoray_fuzz::cli::{vtk_legacy, vtk_xml};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    if which & 1 == 0 {
        let path = isoray_fuzz::scratch_file(body, ".vtu");
        if let Ok(grid) = vtk_xml::read(&path, None) {
            let _ = grid.into_tets();
        }
    } else {
        let path = isoray_fuzz::scratch_file(body, ".vtk");
        if let Ok(grid) = vtk_legacy::read(&path, None) {
            let _ = grid.into_tets();
        }
    }
});
