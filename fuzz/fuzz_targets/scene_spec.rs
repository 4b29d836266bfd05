//! A scene's description as a client posts it (`POST /v1/scenes`, any kind: camera, isovalue
//! and slider, lights, materials, floor, volume, extra isosurfaces, clip box, effects and the
//! kind's own settings), validated by the server's own code with the engine's effect limits,
//! then traced once as the server would show it (`isoray_fuzz::render_setup`). A surfel mesh
//! is sampled into at most 256 surfels so that an execution stays short.
#![no_main]
use isoray_protocol::api::CreateScene;
use isoray_server::effects::EffectLimits;
use isoray_server::kinds::SceneSetup;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(mut spec) = serde_json::from_slice::<CreateScene>(data) else {
        return;
    };
    if let Some(mesh) = spec.surfels.as_mut().and_then(|s| s.mesh.as_mut()) {
        mesh.count = Some(mesh.count.unwrap_or(256).min(256));
    }
    if let Ok(setup) = SceneSetup::from_spec(&spec, &EffectLimits::ENGINE) {
        isoray_fuzz::render_setup(&setup);
    }
});
