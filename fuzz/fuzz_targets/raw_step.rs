//! A pushed step as raw values after the 16-byte `ISRA` header, for both kinds' layouts.
#![no_main]
use isoray_server::store::ingest::ingest_raw;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| isoray_fuzz::fuzz_step(data, ingest_raw));
