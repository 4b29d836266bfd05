//! `isoray push` of a particle file for a metaball scene: `.csv` (the csv crate), `.xyz`
//! frames and `.npz` archives (zip and npyz), chosen by the first byte's low two bits. What
//! reads must be whole rows of finite values, as the push would send them.
#![no_main]
use isoray_fuzz::cli::points_files;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let ext = [".csv", ".xyz", ".npz", ".npz"][usize::from(which & 3)];
    let path = isoray_fuzz::scratch_file(body, ext);
    if let Ok(steps) = points_files::read_steps(&path) {
        for step in steps {
            assert!((3..=8).contains(&step.columns), "{} columns", step.columns);
            assert_eq!(step.values.len() % step.columns as usize, 0);
            assert!(step.values.iter().all(|v| v.is_finite()));
        }
    }
});
