//! A pushed step as raw values after the 16-byte `ISRA` header, for both kinds' layouts.
#![no_main]
use bytes::Bytes;
use isoray_server::body::BodyReader;
use isoray_server::kinds::StepLayout;
use isoray_server::store::ingest::{ingest_raw, IngestLimits, Target};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
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
        temp_path: isoray_fuzz::scratch_file(&[], ".step"),
        index: 0,
        time: 0.0,
    };
    let _ = ingest_raw(
        BodyReader::from_bytes(Bytes::copy_from_slice(body)),
        &limits,
        target,
    );
});
