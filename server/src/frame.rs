//! The one frame function: a prepared scene state traced by the backend and encoded, and for
//! a stream the message that carries it (header, payload, depth block). Sessions
//! (`session::render`), the one-shot render endpoint (`api::render`) and `isoray render`
//! (`cli/render.rs`) all go through [`render`], so an image of the same state, view, effects
//! and codec is byte for byte the same whichever asked for it.
//!
//! Blocking: call it on the render pool or the job pool, never on the async runtime.

use crate::encode::{self, EncodeError};
use crate::metrics as m;
use crate::refine::{RefineKey, Refinement};
use crate::scenes::prepared::{micros, PreparedState};
use crate::style::Style;
use axum::body::Bytes;
use isoray_protocol::{
    Codec, FrameHeader, InputId, StageTimings, FLAG_DEPTH, FLAG_FINAL, FLAG_KEYFRAME, FLAG_STILL,
    PROTOCOL_VERSION,
};
use isoray_render::{
    Accumulator, Backend, DeviceTimes, Effects, Framebuffer, PreparedScene, SurfaceBuffer, View,
};
use std::time::Instant;

/// The H.264 stream of a session, moved into each H.264 frame and back.
#[cfg(feature = "h264")]
pub type VideoState = Option<encode::H264Stream>;
#[cfg(not(feature = "h264"))]
pub type VideoState = Option<std::convert::Infallible>;

/// How a frame is traced.
#[derive(Clone, Copy)]
pub enum Pass<'a> {
    /// One pass of the effects: interactive frames and one-shot images.
    Single,
    /// The next refinement pass of a still view, accumulated for the view `key`.
    Refine(&'a Refinement, RefineKey),
    /// The mean of this many passes, each from its own sub-pixel position (one-shot images).
    Accumulate(u32),
}

/// What an H.264 frame needs beyond the image.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct H264Plan {
    /// Bit rate for a new stream.
    pub bitrate_bps: u32,
    /// Start the stream over with a keyframe.
    pub restart: bool,
    /// The stream's frame rate.
    pub fps: f64,
}

/// One frame to make.
pub struct FrameRequest<'a> {
    pub view: View,
    pub effects: &'a Effects,
    /// The viewer's own clip box, isosurfaces and colour map (`None`: the scene's look).
    pub style: Option<&'a Style>,
    pub pass: Pass<'a>,
    pub codec: Codec,
    /// JPEG quality, 1–100 (JPEG frames only).
    pub jpeg_quality: u8,
    /// H.264 frames only.
    pub h264: H264Plan,
    /// Add a depth block, subsampled by this factor.
    pub depth_factor: Option<u32>,
}

impl<'a> FrameRequest<'a> {
    /// A one-shot image: one pass of the effects, PNG or JPEG (`codec`), no depth block. The
    /// render endpoint and `isoray render` ask for this.
    pub fn image(
        view: View,
        effects: &'a Effects,
        codec: Codec,
        jpeg_quality: u8,
    ) -> FrameRequest<'a> {
        FrameRequest {
            view,
            effects,
            style: None,
            pass: Pass::Single,
            codec,
            jpeg_quality,
            h264: H264Plan::default(),
            depth_factor: None,
        }
    }
}

/// A traced and encoded frame.
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// The image in the request's codec.
    pub payload: Vec<u8>,
    /// The H.264 stream to keep for the next frame.
    pub video: VideoState,
    pub keyframe: bool,
    pub depth: Option<Vec<u8>>,
    /// Tracing, less the device's upload and readback when a device traced it.
    pub trace_us: u32,
    /// From the end of the trace to the end of encoding (image and depth), plus the device's
    /// readback.
    pub encode_us: u32,
    /// What the device spent on the frame (zero on the CPU).
    pub device: DeviceTimes,
}

/// Traces `state` as `request` asks and encodes the image (and depth block).
pub fn render(
    backend: &Backend,
    state: &PreparedState,
    request: &FrameRequest,
    video: VideoState,
) -> Result<Frame, EncodeError> {
    let t0 = Instant::now();
    // A viewer's style traces the same prepared state under its own lighting.
    let styled = styled(state, request.style);
    let prepared = styled.as_ref().unwrap_or(&state.prepared);
    // Effects hook: a single pass traces one pass of the effects; a still frame adds a
    // refinement pass.
    let (fb, device) = match request.pass {
        Pass::Single => {
            let (fb, rays) = backend.render_effects(prepared, &request.view, request.effects);
            m::capped_searches(rays.kinds.metaballs.capped, rays.kinds.surfels.capped);
            (fb, rays.device)
        }
        Pass::Refine(refinement, key) => {
            refinement.next_pass(backend, prepared, &request.view, request.effects, key)
        }
        Pass::Accumulate(passes) => backend.refine_until_converged(
            prepared,
            &request.view,
            request.effects,
            &mut Accumulator::fixed_passes(passes),
        ),
    };
    m::traced(&device);
    let t1 = Instant::now();
    let (payload, video, keyframe) = encode_image(&fb, request, video)?;
    let depth = match request.depth_factor {
        Some(factor) => Some(encode::depth_block(&fb, &request.view.camera, factor)?),
        None => None,
    };
    Ok(Frame {
        width: fb.width,
        height: fb.height,
        payload,
        video,
        keyframe,
        depth,
        // The device's upload is reported with the build, its readback with the encoding.
        trace_us: micros(t1 - t0).saturating_sub(us32(device.upload_us + device.readback_us)),
        encode_us: micros(t1.elapsed()).saturating_add(us32(device.readback_us)),
        device,
    })
}

/// `state` under a viewer's `style`, where the style changes its lighting (clip box,
/// isosurfaces, colour map): the same prepared geometry, traced with the style's lighting.
fn styled(state: &PreparedState, style: Option<&Style>) -> Option<PreparedScene> {
    style
        .and_then(|s| s.lighting(state.prepared.lighting()))
        .map(|l| state.prepared.with_lighting(l))
}

fn us32(us: u64) -> u32 {
    u32::try_from(us).unwrap_or(u32::MAX)
}

/// The primary hits of `view` as a `.npy` file: an `(H, W, 4)` `f32` array of the hit
/// distance along the ray and the outward normal (`[∞, 0, 0, 0]` for a miss); the
/// `format: "npy"` output of the render endpoint and `isoray render`. The isosurface only (no
/// floor, no further isosurfaces), cut by the clip box where `effects` (and the viewer's
/// `style`) have one on, as the image with those effects is: the one effect that changes
/// which surface a pixel sees.
pub fn surface_npy(
    backend: &Backend,
    state: &PreparedState,
    view: &View,
    effects: &Effects,
    style: Option<&Style>,
) -> Vec<u8> {
    let styled = styled(state, style);
    let prepared = styled.as_ref().unwrap_or(&state.prepared);
    let surface = backend.render_surface_effects(prepared, view, effects);
    crate::npy::write_f32(
        &[
            surface.height as usize,
            surface.width as usize,
            SurfaceBuffer::CHANNELS,
        ],
        &surface.values,
    )
}

/// What a stream message says about its frame besides the frame itself.
pub struct StreamMeta {
    pub sequence: u64,
    pub input_id: InputId,
    pub still: bool,
    /// The last frame of a resting view's refinement: nothing follows until something
    /// changes.
    pub last: bool,
    pub codec: Codec,
    pub jpeg_quality: u8,
    /// The time the session asked for (a state's own time, when it has one, wins).
    pub time: f64,
}

/// The frame as one stream message: the frame header, the payload, the depth block. Records
/// the stage timings and depth bytes in the metrics.
pub fn stream_message(
    frame: Frame,
    state: &PreparedState,
    meta: &StreamMeta,
) -> Result<Bytes, EncodeError> {
    let mut flags = if meta.still { FLAG_STILL } else { 0 };
    if frame.keyframe {
        flags |= FLAG_KEYFRAME;
    }
    if frame.depth.is_some() {
        flags |= FLAG_DEPTH;
    }
    if meta.still && meta.last {
        flags |= FLAG_FINAL;
    }
    let payload_len = u32::try_from(frame.payload.len())
        .map_err(|_| EncodeError::from_message("frame payload over 4 GiB"))?;
    let header = FrameHeader {
        version: PROTOCOL_VERSION,
        sequence: meta.sequence,
        input_id: meta.input_id,
        width: frame.width,
        height: frame.height,
        codec: meta.codec,
        flags,
        quality: if meta.codec == Codec::Jpeg {
            meta.jpeg_quality
        } else {
            0
        },
        payload_len,
        timings: StageTimings {
            update_us: state.update_us,
            // A GPU frame's build includes getting the state onto the device.
            build_us: state.build_us.saturating_add(us32(frame.device.upload_us)),
            trace_us: frame.trace_us,
            encode_us: frame.encode_us,
        },
        // A stored scene's frame shows its step's time, a live demo's the state it shows.
        scene_time: state.step_time.unwrap_or(meta.time),
    };
    m::stage("update", header.timings.update_us);
    m::stage("build", header.timings.build_us);
    m::stage("trace", header.timings.trace_us);
    m::stage("encode", header.timings.encode_us);
    let depth_len = frame.depth.as_ref().map_or(0, Vec::len);
    let mut bytes =
        Vec::with_capacity(isoray_protocol::FRAME_HEADER_LEN + frame.payload.len() + depth_len);
    bytes.extend_from_slice(&header.encode());
    bytes.extend_from_slice(&frame.payload);
    if let Some(depth) = frame.depth {
        metrics::counter!(m::DEPTH_BYTES).increment(depth.len() as u64);
        bytes.extend_from_slice(&depth);
    }
    Ok(Bytes::from(bytes))
}

/// The frame's image in the request's codec: (payload, the H.264 stream to keep, keyframe).
fn encode_image(
    fb: &Framebuffer,
    request: &FrameRequest,
    video: VideoState,
) -> Result<(Vec<u8>, VideoState, bool), EncodeError> {
    match request.codec {
        Codec::Jpeg => Ok((encode::jpeg(fb, request.jpeg_quality)?, video, false)),
        Codec::Png => Ok((encode::png(fb)?, video, false)),
        Codec::H264 => encode_h264(fb, &request.h264, video),
    }
}

#[cfg(feature = "h264")]
fn encode_h264(
    fb: &Framebuffer,
    plan: &H264Plan,
    video: VideoState,
) -> Result<(Vec<u8>, VideoState, bool), EncodeError> {
    let mut stream = match video {
        Some(stream) if stream.size() == (fb.width, fb.height) && !plan.restart => stream,
        Some(mut stream)
            if stream.size() == (fb.width, fb.height)
                && stream.bitrate_bps() == plan.bitrate_bps =>
        {
            stream.force_keyframe();
            stream
        }
        _ => encode::H264Stream::new(fb.width, fb.height, plan.bitrate_bps, plan.fps as f32)?,
    };
    let frame = stream.encode(&fb.rgb)?;
    Ok((frame.bytes, Some(stream), frame.keyframe))
}

#[cfg(not(feature = "h264"))]
fn encode_h264(
    _: &Framebuffer,
    _: &H264Plan,
    _: VideoState,
) -> Result<(Vec<u8>, VideoState, bool), EncodeError> {
    Err(EncodeError::from_message("this build has no H.264 encoder"))
}
