//! Client input: parsing, validation and application to a session's settings.
//!
//! Every message is checked in full before anything changes, so a rejected input leaves the
//! session exactly as it was. Errors name the field and the limit that was broken.

use crate::effects::EffectLimits;
use isoray_protocol::effects::EffectsInput;
use isoray_protocol::{
    CameraInput, ClientMessage, Codec, ErrorMessage, InputId, IsovalueInput, ResizeInput,
    StreamInput, TimeInput, CLIENT_MESSAGE_TYPES, MAX_INPUT_ID,
};
use isoray_render::{Camera, Effects};

/// What a session renders, as the client last set it.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub camera: Camera,
    pub isovalue: f32,
    pub width: u32,
    pub height: u32,
    /// `None`: follow the live animation.
    pub pinned_time: Option<f64>,
    /// The last input applied, echoed in frame headers.
    pub last_input_id: InputId,
    /// Bumped by every applied input, so the renderer knows the view changed.
    pub version: u64,
    /// When the last input was applied (for input-to-frame latency).
    pub last_input_at: Option<std::time::Instant>,
    /// Effect switches and quality.
    pub effects: Effects,
    /// The viewer's own clip box, further isosurfaces and colour map.
    pub style: crate::style::Style,
    /// How frames are sent (`stream` messages).
    pub stream: StreamSettings,
}

/// How a session's frames are made and sent, as the client last set it.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamSettings {
    /// Codecs the client decodes that this server offers, most preferred first.
    pub codecs: Vec<Codec>,
    /// Attach the depth channel to interactive frames.
    pub depth: bool,
    /// `false` while the client's page is hidden: nothing is rendered.
    pub visible: bool,
    /// Frames per second wanted while the view moves or the scene animates.
    pub fps: f64,
}

impl StreamSettings {
    /// What a session starts with: the codecs of protocol v1's first clients (JPEG and PNG;
    /// H.264 only for clients that ask for it), no depth, visible.
    pub fn initial(fps: f64) -> StreamSettings {
        StreamSettings::new(&[Codec::Jpeg, Codec::Png], fps)
    }

    /// Settings accepting `codecs`, no depth, visible.
    pub fn new(codecs: &[Codec], fps: f64) -> StreamSettings {
        StreamSettings {
            codecs: codecs.to_vec(),
            depth: false,
            visible: true,
            fps,
        }
    }

    pub fn accepts(&self, codec: Codec) -> bool {
        self.codecs.contains(&codec)
    }
}

/// The limits inputs are checked against.
#[derive(Clone, Debug)]
pub struct Limits {
    pub max_size: u32,
    /// Open interval of meaningful isovalues for the scene.
    pub isovalue_range: (f32, f32),
    /// The isovalue slider's range (a colour map's default range).
    pub isovalue_slider: (f32, f32),
    /// Whether the scene's surface is an isosurface of a field (not for surfels: they refuse
    /// an isovalue, further isosurfaces and a colour map, which would change nothing).
    pub scalar_field: bool,
    /// How many further isosurfaces the scene has of its own (`surfaces[i].scene_surface`
    /// names one).
    pub scene_surfaces: usize,
    /// Largest effect quality settings.
    pub effects: EffectLimits,
    /// The codecs this server can send.
    pub codecs: Vec<Codec>,
    /// The server's frame rate cap.
    pub max_fps: f64,
}

/// Most codec names a `stream` message may list.
const MAX_CODEC_NAMES: usize = 16;

/// Largest coordinate accepted for a camera: keeps every value exact enough in f32.
const MAX_COORDINATE: f64 = 1.0e6;

fn error(code: &str, message: String, input_id: Option<InputId>) -> ErrorMessage {
    ErrorMessage {
        code: code.to_string(),
        message,
        input_id,
    }
}

/// Parses one text message. Distinguishes broken JSON, unknown types and bad fields, and
/// names the field (`eye[1]`) that is wrong.
pub fn parse(text: &str) -> Result<ClientMessage, ErrorMessage> {
    let value: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| error("bad_json", format!("message is not valid JSON: {e}"), None))?;
    let serde_json::Value::Object(mut fields) = value else {
        return Err(error(
            "invalid_message",
            "message must be a JSON object".into(),
            None,
        ));
    };
    let input_id = fields.get("input_id").and_then(|v| v.as_u64());
    let kind = match fields.remove("type") {
        Some(serde_json::Value::String(kind)) => kind,
        Some(_) => {
            return Err(error(
                "invalid_message",
                "`type` must be a string".into(),
                input_id,
            ))
        }
        None => {
            return Err(error(
                "invalid_message",
                "message has no `type` field".into(),
                input_id,
            ))
        }
    };
    let body = serde_json::Value::Object(fields);
    fn typed<T: serde::de::DeserializeOwned>(
        kind: &str,
        body: serde_json::Value,
        input_id: Option<InputId>,
    ) -> Result<T, ErrorMessage> {
        serde_path_to_error::deserialize(body).map_err(|e| {
            let path = e.path().to_string();
            let field = if path == "." {
                String::new()
            } else {
                format!(", field `{path}`")
            };
            error(
                "invalid_message",
                format!(
                    "`{kind}` message{field}: {}",
                    crate::error::plain_words(&e.into_inner().to_string())
                ),
                input_id,
            )
        })
    }
    Ok(match kind.as_str() {
        "camera" => ClientMessage::Camera(typed(&kind, body, input_id)?),
        "isovalue" => ClientMessage::Isovalue(typed(&kind, body, input_id)?),
        "resize" => ClientMessage::Resize(typed(&kind, body, input_id)?),
        "time" => ClientMessage::Time(typed(&kind, body, input_id)?),
        "ack" => ClientMessage::Ack(typed(&kind, body, input_id)?),
        "effects" => ClientMessage::Effects(typed(&kind, body, input_id)?),
        "stream" => ClientMessage::Stream(typed(&kind, body, input_id)?),
        _ => {
            return Err(error(
                "unknown_type",
                format!(
                    "unknown message type `{kind}`; expected one of {}",
                    CLIENT_MESSAGE_TYPES.join(", ")
                ),
                input_id,
            ))
        }
    })
}

/// Checks a view input against `limits` and, if it is valid, applies it to `settings`.
/// Acknowledgements are not view inputs; the session handles them.
pub fn apply(
    message: &ClientMessage,
    settings: &mut Settings,
    limits: &Limits,
) -> Result<(), ErrorMessage> {
    let Some(input_id) = message.input_id() else {
        return Ok(());
    };
    let fail = |message: String| Err(error("invalid_value", message, Some(input_id)));
    if input_id > MAX_INPUT_ID {
        return fail(format!("input_id {input_id} exceeds 2^53 - 1"));
    }
    match message {
        ClientMessage::Camera(CameraInput {
            eye,
            target,
            up,
            fov_y_deg,
            ..
        }) => {
            for (name, v) in [("eye", eye), ("target", target), ("up", up)] {
                for (i, c) in v.iter().enumerate() {
                    if !c.is_finite() || c.abs() > MAX_COORDINATE {
                        return fail(format!(
                            "camera.{name}[{i}] = {c} must be finite and within ±{MAX_COORDINATE}"
                        ));
                    }
                }
            }
            let fov = fov_y_deg.unwrap_or(45.0);
            if !(1.0..=170.0).contains(&fov) {
                return fail(format!("camera.fov_y_deg = {fov} must be in [1, 170]"));
            }
            let to_vec = |v: &[f64; 3]| glam::DVec3::from_array(*v);
            let (eye, target, up) = (to_vec(eye), to_vec(target), to_vec(up));
            let forward = target - eye;
            if forward.length() < 1e-6 {
                return fail("camera: eye and target coincide".into());
            }
            if up.length() < 1e-9 || forward.normalize().cross(up.normalize()).length() < 1e-6 {
                return fail("camera: up is zero or parallel to the view direction".into());
            }
            settings.camera = Camera {
                eye: eye.as_vec3(),
                target: target.as_vec3(),
                up: up.as_vec3(),
                fov_y_deg: fov as f32,
            };
        }
        ClientMessage::Isovalue(IsovalueInput { value, .. }) => {
            let range = limits.isovalue_range;
            match crate::kinds::convert::isovalue(*value, range, limits.scalar_field, "isovalue") {
                Ok(v) => settings.isovalue = v,
                Err(e) => return fail(e.message),
            }
        }
        ClientMessage::Resize(ResizeInput { width, height, .. }) => {
            let (width, height, max) = (*width, *height, limits.max_size);
            if width == 0 || height == 0 {
                return fail(format!(
                    "resize {width}×{height}: width and height must be at least 1"
                ));
            }
            if width > max || height > max {
                return fail(format!(
                    "resize {width}×{height} exceeds the maximum {max}×{max}"
                ));
            }
            settings.width = width;
            settings.height = height;
        }
        ClientMessage::Time(TimeInput { time, .. }) => match *time {
            None => settings.pinned_time = None,
            Some(t) if t.is_finite() && (0.0..=crate::kinds::convert::MAX_TIME).contains(&t) => {
                settings.pinned_time = Some(t)
            }
            Some(t) => {
                return fail(format!(
                    "time {t} must be a number in [0, 1e9] seconds, or null to follow the animation"
                ))
            }
        },
        ClientMessage::Stream(stream) => {
            settings.stream = checked_stream(stream, settings, limits)?
        }
        ClientMessage::Ack(_) => return Ok(()),
        ClientMessage::Effects(EffectsInput { effects, .. }) => {
            // Both checked in full before either changes.
            let field = match limits.scalar_field {
                true => Ok(()),
                false => crate::style::refuse_without_field(effects),
            };
            let applied = field
                .and_then(|()| crate::effects::apply(&settings.effects, effects, &limits.effects))
                .and_then(|e| {
                    crate::style::apply(
                        &settings.style,
                        effects,
                        limits.isovalue_range,
                        limits.isovalue_slider,
                        limits.scene_surfaces,
                    )
                    .map(|s| (e, s))
                });
            match applied {
                Ok((e, s)) => {
                    settings.effects = e;
                    settings.style = s;
                }
                Err(e) => return fail(format!("effects.{}", e.message)),
            }
        }
    }
    settings.last_input_id = input_id;
    settings.version += 1;
    Ok(())
}

/// The stream settings a `stream` message asks for, or the error naming what is wrong.
fn checked_stream(
    message: &StreamInput,
    settings: &Settings,
    limits: &Limits,
) -> Result<StreamSettings, ErrorMessage> {
    let fail = |text: String| Err(error("invalid_value", text, Some(message.input_id)));
    let mut next = settings.stream.clone();
    if let Some(names) = &message.codecs {
        if names.len() > MAX_CODEC_NAMES {
            return fail(format!(
                "stream.codecs lists {} names; at most {MAX_CODEC_NAMES}",
                names.len()
            ));
        }
        let mut codecs = Vec::new();
        for name in names {
            // Unknown names are skipped: a client may list codecs of later versions.
            if let Some(codec) = Codec::from_name(name) {
                if limits.codecs.contains(&codec) && !codecs.contains(&codec) {
                    codecs.push(codec);
                }
            }
        }
        if !codecs.iter().any(|c| matches!(c, Codec::Jpeg | Codec::Png)) {
            let offered: Vec<&str> = limits.codecs.iter().map(|c| c.name()).collect();
            return fail(format!(
                "stream.codecs {names:?} has no image codec this server sends (it offers {}); \
                 `jpeg` or `png` is needed for still frames",
                offered.join(", ")
            ));
        }
        next.codecs = codecs;
    }
    if let Some(depth) = message.depth {
        next.depth = depth;
    }
    if let Some(visible) = message.visible {
        next.visible = visible;
    }
    if let Some(fps) = message.fps {
        if !(fps.is_finite() && (1.0..=1000.0).contains(&fps)) {
            return fail(format!("stream.fps = {fps} must be in [1, 1000]"));
        }
        next.fps = fps.min(limits.max_fps);
    }
    Ok(next)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn settings() -> Settings {
        Settings {
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
        }
    }

    fn limits() -> Limits {
        Limits {
            max_size: 4096,
            isovalue_range: (0.0, 2.0),
            isovalue_slider: (0.2, 1.8),
            scalar_field: true,
            scene_surfaces: 0,
            effects: EffectLimits {
                max_depth: 8,
                max_samples: 64,
                max_passes: 64,
            },
            codecs: vec![Codec::Jpeg, Codec::Png],
            max_fps: 30.0,
        }
    }

    #[test]
    fn errors_name_the_field() {
        let e = parse(
            r#"{"type":"camera","input_id":3,"eye":[0,null,1],"target":[0,0,0],"up":[0,1,0]}"#,
        )
        .expect_err("null coordinate");
        assert_eq!(e.code, "invalid_message");
        assert!(e.message.contains("eye[1]"), "{}", e.message);
        assert_eq!(e.input_id, Some(3));
        assert_eq!(parse("{").expect_err("broken").code, "bad_json");
        assert_eq!(
            parse(r#"{"type":"fly","input_id":1}"#)
                .expect_err("unknown")
                .code,
            "unknown_type"
        );
        assert_eq!(parse("[1,2]").expect_err("array").code, "invalid_message");
        // A nested object of the wrong type, in a client's words, not the server's type names.
        let e = parse(r#"{"type":"effects","input_id":4,"effects":7}"#).expect_err("number");
        assert!(
            e.message.contains("field `effects`") && e.message.contains("expected a JSON object"),
            "{}",
            e.message
        );
        assert!(!e.message.contains("struct"), "{}", e.message);
    }

    #[test]
    fn rejected_input_changes_nothing() {
        let mut s = settings();
        let before = s.clone();
        for text in [
            r#"{"type":"resize","input_id":1,"width":0,"height":10}"#,
            r#"{"type":"resize","input_id":1,"width":5000,"height":10}"#,
            r#"{"type":"isovalue","input_id":1,"value":2.5}"#,
            r#"{"type":"isovalue","input_id":1,"value":0}"#,
            r#"{"type":"camera","input_id":1,"eye":[0,0,0],"target":[0,0,0],"up":[0,1,0]}"#,
            r#"{"type":"camera","input_id":1,"eye":[0,5,0],"target":[0,0,0],"up":[0,1,0]}"#,
            r#"{"type":"time","input_id":1,"time":-1}"#,
            r#"{"type":"effects","input_id":1,"effects":{"shadows":true,"depth":9}}"#,
            r#"{"type":"effects","input_id":1,"effects":{"ao_samples":0}}"#,
            r#"{"type":"stream","input_id":1,"codecs":["h264","vp9"]}"#,
            r#"{"type":"stream","input_id":1,"codecs":[]}"#,
            r#"{"type":"stream","input_id":1,"depth":true,"fps":0}"#,
        ] {
            let msg = parse(text).expect("well-formed");
            let e = apply(&msg, &mut s, &limits()).expect_err(text);
            assert_eq!(e.code, "invalid_value", "{text}");
            assert_eq!(s, before, "{text} changed the settings");
        }
        let ok = parse(r#"{"type":"isovalue","input_id":9,"value":1.25}"#).expect("parses");
        apply(&ok, &mut s, &limits()).expect("valid");
        assert_eq!((s.isovalue, s.last_input_id, s.version), (1.25, 9, 1));
        let ok =
            parse(r#"{"type":"effects","input_id":10,"effects":{"reflections":true,"depth":8}}"#)
                .expect("parses");
        apply(&ok, &mut s, &limits()).expect("valid");
        assert!(s.effects.reflections && s.effects.depth == 8 && s.version == 2);
        let e = parse(r#"{"type":"effects","input_id":11,"effects":{"reflection":true}}"#)
            .expect_err("unknown field");
        assert!(e.message.contains("reflection"), "{}", e.message);
    }

    #[test]
    fn a_surfel_session_refuses_the_look_of_a_field() {
        let surfels = Limits {
            scalar_field: false,
            ..limits()
        };
        let mut s = settings();
        let before = s.clone();
        for (text, field) in [
            (
                r#"{"type":"isovalue","input_id":1,"value":1.25}"#,
                "isovalue",
            ),
            (
                r#"{"type":"effects","input_id":1,"effects":{"shadows":true,"surfaces":[{"isovalue":1}]}}"#,
                "surfaces",
            ),
            (
                r#"{"type":"effects","input_id":1,"effects":{"color_map":{"name":"grey"}}}"#,
                "color_map",
            ),
        ] {
            let msg = parse(text).expect("well-formed");
            let e = apply(&msg, &mut s, &surfels).expect_err(text);
            assert!(
                e.code == "invalid_value"
                    && e.message.contains(field)
                    && e.message.contains("surfel"),
                "{text}: {e:?}"
            );
            assert_eq!(s, before, "{text} changed the settings");
        }
        // The effects that apply to surfels, and the look's resets, pass.
        let ok = parse(
            r#"{"type":"effects","input_id":2,"effects":{"shadows":true,"surfaces":[],"color_map":{"name":"none"}}}"#,
        )
        .expect("parses");
        apply(&ok, &mut s, &surfels).expect("valid");
        assert!(s.effects.shadows);
    }

    #[test]
    fn stream_settings_keep_offered_codecs_in_the_clients_order() {
        let mut s = settings();
        let msg = parse(
            r#"{"type":"stream","input_id":2,"codecs":["av1","h264","png","jpeg"],"depth":true,"fps":144}"#,
        )
        .expect("parses");
        apply(&msg, &mut s, &limits()).expect("valid");
        // h264 is not offered by this (test) server and av1 is unknown: both are skipped.
        assert_eq!(s.stream.codecs, vec![Codec::Png, Codec::Jpeg]);
        assert!(s.stream.depth && s.stream.visible);
        assert_eq!(s.stream.fps, 30.0, "capped at the server's maximum");
        let hide = parse(r#"{"type":"stream","input_id":3,"visible":false}"#).expect("parses");
        apply(&hide, &mut s, &limits()).expect("valid");
        assert!(
            !s.stream.visible && s.stream.depth,
            "absent fields keep their value"
        );
        let e = parse(r#"{"type":"stream","input_id":4,"codecs":"jpeg"}"#).expect_err("string");
        assert!(e.message.contains("codecs"), "{}", e.message);
    }
}
