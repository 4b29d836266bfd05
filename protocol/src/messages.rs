//! The websocket protocol's JSON messages: what the client sends (camera, isovalue, time,
//! size, effects, frame acknowledgements, stream preferences) and what the server answers
//! (session info, scene lists, errors). The crate root re-exports every item here.

use crate::effects;
use crate::version::InputId;
use serde::{Deserialize, Serialize};

/// A message from the client to the server (a JSON text message, tagged by `type`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ClientMessage {
    Camera(CameraInput),
    Isovalue(IsovalueInput),
    Resize(ResizeInput),
    Time(TimeInput),
    Ack(FrameAck),
    /// Switch effects and set their quality (see [`effects`]).
    Effects(effects::EffectsInput),
    Stream(StreamInput),
}

/// The `type` of every client message, in the order of [`ClientMessage`].
pub const CLIENT_MESSAGE_TYPES: [&str; 7] = [
    "camera", "isovalue", "resize", "time", "ack", "effects", "stream",
];

/// Place the camera. Positions are in world space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraInput {
    pub input_id: InputId,
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    /// Vertical field of view in degrees; 45 when absent.
    #[serde(default)]
    pub fov_y_deg: Option<f64>,
}

/// Set the isovalue of the (first) isosurface.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IsovalueInput {
    pub input_id: InputId,
    pub value: f64,
}

/// Set the render size in pixels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResizeInput {
    pub input_id: InputId,
    pub width: u32,
    pub height: u32,
}

/// Pin the scene time in seconds, or follow the live animation with `null`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeInput {
    pub input_id: InputId,
    pub time: Option<f64>,
}

/// The client has received (and shown) every frame up to `sequence`. The server keeps at
/// most a small window of unacknowledged frames in flight per session, so frames never pile
/// up in network buffers in front of a slow client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameAck {
    pub sequence: u64,
}

/// How the client wants its frames. Every field but `input_id` is optional; an absent field
/// keeps its current value (at first: `jpeg` and `png`, no depth, visible, the server's frame
/// rate).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StreamInput {
    pub input_id: InputId,
    /// The codecs the client decodes, by name (`jpeg`, `png`, `h264`), most preferred first.
    /// Names the server does not know are ignored, so a client may list newer codecs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub codecs: Option<Vec<String>>,
    /// Attach the compact depth channel to interactive frames, for reprojection.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<bool>,
    /// `false` while the page is hidden: the server renders nothing for the session.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visible: Option<bool>,
    /// The frame rate the client wants while the view moves or the scene animates (capped by
    /// the server's maximum).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
}

impl ClientMessage {
    /// The client's identifier for this input; acknowledgements carry none.
    pub fn input_id(&self) -> Option<InputId> {
        match self {
            ClientMessage::Camera(m) => Some(m.input_id),
            ClientMessage::Isovalue(m) => Some(m.input_id),
            ClientMessage::Resize(m) => Some(m.input_id),
            ClientMessage::Time(m) => Some(m.input_id),
            ClientMessage::Stream(m) => Some(m.input_id),
            ClientMessage::Ack(_) => None,
            ClientMessage::Effects(m) => Some(m.input_id),
        }
    }
}

/// A JSON text message from the server to the client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
// `info` is sent once per session; boxing it would only burden every client of this type.
#[allow(clippy::large_enum_variant)]
pub enum ServerMessage {
    /// Sent once after the websocket opens.
    Info(SessionInfo),
    /// An input was rejected; the session goes on with its previous state.
    Error(ErrorMessage),
}

fn field_default() -> bool {
    true
}

/// What the client needs to know to drive a session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionInfo {
    pub protocol_version: u16,
    pub scene: SceneSummary,
    /// Largest width and height the server renders.
    pub max_width: u32,
    pub max_height: u32,
    /// The size frames have until the client sends `resize`.
    pub width: u32,
    pub height: u32,
    /// The current isovalue and the open interval it must stay in.
    pub isovalue: f64,
    pub isovalue_range: [f64; 2],
    /// A slider range inside `isovalue_range` where the surface changes visibly.
    pub isovalue_slider: [f64; 2],
    /// Whether the scene's surface is an isosurface of a scalar field (metaballs, tets):
    /// `false` for surfels, whose surface no isovalue, further isosurface or colour map of
    /// the isovalue changes, so a client offers none. Absent from older servers: `true`.
    #[serde(default = "field_default")]
    pub scalar_field: bool,
    /// A camera that frames the whole scene.
    pub camera: CameraPose,
    /// Frames the server sends ahead of the client's `ack`s.
    pub frame_window: u32,
    /// The effects the scene can use, the session's effects, and their limits.
    pub effects: effects::EffectsInfo,
    /// The codecs this server can send, by name (see [`crate::frame::Codec::name`]).
    #[serde(default)]
    pub codecs: Vec<String>,
    /// The frame rate cap of the server.
    #[serde(default)]
    pub max_fps: f64,
}

/// A camera as the server reports it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraPose {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    pub fov_y_deg: f64,
}

/// One scene in `GET /api/v1/scenes`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneSummary {
    pub id: String,
    pub name: String,
    /// `metaballs`, `surfels` or `tets`.
    pub kind: String,
    /// Number of primitives (balls, surfels, tetrahedra) in the current state.
    pub primitives: u64,
    /// Whether the scene changes over time by itself.
    pub animated: bool,
    pub description: String,
}

/// The body of `GET /api/v1/scenes`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneList {
    pub scenes: Vec<SceneSummary>,
}

/// An error, on the socket and as the JSON body of HTTP errors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorMessage {
    /// A stable, machine-readable code such as `bad_json` or `invalid_value`.
    pub code: String,
    /// What was wrong, for a person.
    pub message: String,
    /// The input this error answers, when the server could read one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_id: Option<InputId>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn client_messages_have_the_documented_json_shape() {
        let camera: ClientMessage = serde_json::from_str(
            r#"{"type":"camera","input_id":7,"eye":[0,0,5],"target":[0,0,0],"up":[0,1,0]}"#,
        )
        .expect("documented camera message parses");
        assert_eq!(
            camera,
            ClientMessage::Camera(CameraInput {
                input_id: 7,
                eye: [0.0, 0.0, 5.0],
                target: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: None
            })
        );
        let time: ClientMessage =
            serde_json::from_str(r#"{"type":"time","input_id":1,"time":null}"#).expect("parses");
        assert_eq!(time.input_id(), Some(1));
        let ack: ClientMessage =
            serde_json::from_str(r#"{"type":"ack","sequence":3}"#).expect("parses");
        assert_eq!(ack, ClientMessage::Ack(FrameAck { sequence: 3 }));
        let stream: ClientMessage = serde_json::from_str(
            r#"{"type":"stream","input_id":2,"codecs":["h264","jpeg","png"],"depth":true}"#,
        )
        .expect("documented stream message parses");
        assert_eq!(
            stream,
            ClientMessage::Stream(StreamInput {
                input_id: 2,
                codecs: Some(vec!["h264".into(), "jpeg".into(), "png".into()]),
                depth: Some(true),
                visible: None,
                fps: None,
            })
        );
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"zoom","input_id":1}"#).is_err());
        assert!(serde_json::from_str::<ClientMessage>(
            r#"{"type":"isovalue","input_id":1,"value":0.5,"extra":1}"#
        )
        .is_err());
    }

    #[test]
    fn server_error_serializes_with_type_tag() {
        let msg = ServerMessage::Error(ErrorMessage {
            code: "bad_json".into(),
            message: "expected value".into(),
            input_id: None,
        });
        let json = serde_json::to_string(&msg).expect("serializes");
        assert_eq!(
            json,
            r#"{"type":"error","code":"bad_json","message":"expected value"}"#
        );
    }
}
