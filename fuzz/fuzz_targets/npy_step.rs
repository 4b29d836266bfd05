//! A pushed step as `.npy` (`Content-Type: application/x-npy`), for both kinds' layouts.
#![no_main]
use isoray_server::store::ingest::ingest_npy;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| isoray_fuzz::fuzz_step(data, ingest_npy));
