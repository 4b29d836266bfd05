//! A pushed surfel step: the simulation nodes' positions as `.npy` or raw rows, for a scene of
//! as many nodes as the first byte says (see `isoray_fuzz::fuzz_surfel_step`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| isoray_fuzz::fuzz_surfel_step(data));
