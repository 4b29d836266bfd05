//! The websocket client-message parser and the checks that apply a message to a session's
//! settings (camera, isovalue, size, time, effects, look, stream): whatever a client sends
//! gets an error or leaves a valid session, never a panic.
#![no_main]
use glam::Vec3;
use isoray_protocol::Codec;
use isoray_render::{Camera, Effects};
use isoray_server::effects::EffectLimits;
use isoray_server::input::{apply, parse, Limits, Settings, StreamSettings};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(message) = parse(text) else {
        return;
    };
    let limits = Limits {
        max_size: 4096,
        isovalue_range: (0.0, 2.0),
        isovalue_slider: (0.2, 1.8),
        scalar_field: true,
        scene_surfaces: 2,
        effects: EffectLimits {
            max_depth: 8,
            max_samples: 64,
            max_passes: 64,
        },
        codecs: vec![Codec::Jpeg, Codec::Png],
        max_fps: 30.0,
    };
    let mut settings = Settings {
        camera: Camera {
            eye: Vec3::Z,
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 45.0,
        },
        isovalue: 0.5,
        width: 64,
        height: 64,
        pinned_time: None,
        last_input_id: 0,
        version: 0,
        last_input_at: None,
        effects: Effects::OFF,
        style: Default::default(),
        stream: StreamSettings::new(&Codec::ALL, 30.0),
    };
    // A scene with a field, and a surfel scene (which refuses the look of one).
    let surfels = Limits {
        scalar_field: false,
        ..limits.clone()
    };
    for limits in [&limits, &surfels] {
        let mut settings = settings.clone();
        let before = settings.clone();
        match apply(&message, &mut settings, limits) {
            Ok(()) => {
                // An accepted camera must give a usable view basis.
                let v = settings.camera;
                assert!(v.eye.is_finite() && v.target.is_finite() && v.up.is_finite());
            }
            // A refused message changes nothing.
            Err(_) => assert!(settings == before),
        }
    }
});
