//! A surfel scene's description as a client posts it (`surfels` of `POST /v1/scenes`:
//! surfels, a point cloud or a mesh to sample, nodes, masses, clipping relations), checked,
//! built and traced by the server's own code, rest shape and one step whose nodes move by the
//! scale the first byte picks. A mesh is sampled into at most 256 surfels so that an
//! execution stays short.
#![no_main]
use isoray_protocol::api::SurfelSpec;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let Ok(mut spec) = serde_json::from_slice::<SurfelSpec>(body) else {
        return;
    };
    if let Some(mesh) = &mut spec.mesh {
        mesh.count = Some(mesh.count.unwrap_or(256).min(256));
    }
    let scale = [0.0, 0.05, 1.0, 1000.0][usize::from(which & 3)];
    isoray_fuzz::exercise_surfels(&spec, scale, u64::from(which));
});
