//! Frame encoders: JPEG for interactive frames, lossless PNG for the still frame, H.264 for
//! sustained motion, and the compact depth channel that lets a browser reproject the last
//! frame to a new camera. They run on the render pool, never on the async runtime.
//!
//! JPEG comes from the fastest encoder the build offers: libjpeg-turbo through the
//! `turbojpeg` crate when the `turbojpeg` feature is on (not a default feature: its bundled
//! source needs cmake and nasm to build; `.ci/run` tests it), else the pure-Rust
//! `jpeg-encoder` with its SIMD colour conversion. Both use 4:2:0 chroma below quality 90 and 4:4:4 from 90 up, so their outputs
//! are comparable. H.264 (feature `h264`, OpenH264 built from source) is a stateful stream
//! per session: [`H264Stream`].

use isoray_protocol::Codec;
use isoray_render::{Camera, Framebuffer};

/// Why a frame could not be encoded.
#[derive(Debug, thiserror::Error)]
#[error("encoding failed: {0}")]
pub struct EncodeError(String);

impl EncodeError {
    pub fn from_message(message: impl std::fmt::Display) -> EncodeError {
        EncodeError(message.to_string())
    }
}

/// The codecs this build can stream, in the server's order of preference for interactive
/// frames.
pub fn offered_codecs() -> Vec<Codec> {
    let mut codecs = vec![Codec::Jpeg, Codec::Png];
    if H264_AVAILABLE {
        codecs.push(Codec::H264);
    }
    codecs
}

/// The JPEG encoders a build may offer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JpegEncoder {
    /// libjpeg-turbo (feature `turbojpeg`).
    Turbo,
    /// `jpeg-encoder`, pure Rust.
    Rust,
}

impl JpegEncoder {
    /// Every encoder compiled into this build, fastest first.
    pub fn available() -> Vec<JpegEncoder> {
        let mut all = Vec::new();
        if cfg!(feature = "turbojpeg") {
            all.push(JpegEncoder::Turbo);
        }
        all.push(JpegEncoder::Rust);
        all
    }

    /// The fastest encoder of this build: what the server streams with.
    pub fn fastest() -> JpegEncoder {
        if cfg!(feature = "turbojpeg") {
            JpegEncoder::Turbo
        } else {
            JpegEncoder::Rust
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            JpegEncoder::Turbo => "libjpeg-turbo",
            JpegEncoder::Rust => "jpeg-encoder",
        }
    }
}

/// Baseline JPEG of the frame's colour with the fastest encoder of this build.
pub fn jpeg(fb: &Framebuffer, quality: u8) -> Result<Vec<u8>, EncodeError> {
    jpeg_rgb(
        &fb.rgb,
        fb.width,
        fb.height,
        quality,
        JpegEncoder::fastest(),
    )
}

/// Baseline JPEG of packed RGB pixels with a chosen encoder.
pub fn jpeg_rgb(
    rgb: &[u8],
    width: u32,
    height: u32,
    quality: u8,
    encoder: JpegEncoder,
) -> Result<Vec<u8>, EncodeError> {
    check_rgb(rgb, width, height)?;
    let quality = quality.clamp(1, 100);
    match encoder {
        JpegEncoder::Turbo => turbo_jpeg(rgb, width, height, quality),
        JpegEncoder::Rust => {
            let w =
                u16::try_from(width).map_err(|_| EncodeError::from_message("frame too wide"))?;
            let h =
                u16::try_from(height).map_err(|_| EncodeError::from_message("frame too tall"))?;
            let mut out = Vec::with_capacity(rgb.len() / 8);
            jpeg_encoder::Encoder::new(&mut out, quality)
                .encode(rgb, w, h, jpeg_encoder::ColorType::Rgb)
                .map_err(EncodeError::from_message)?;
            Ok(out)
        }
    }
}

fn check_rgb(rgb: &[u8], width: u32, height: u32) -> Result<(), EncodeError> {
    let want = width as usize * height as usize * 3;
    if rgb.len() != want || width == 0 || height == 0 {
        return Err(EncodeError(format!(
            "{width}×{height} RGB needs {want} bytes, got {}",
            rgb.len()
        )));
    }
    Ok(())
}

#[cfg(feature = "turbojpeg")]
fn turbo_jpeg(rgb: &[u8], width: u32, height: u32, quality: u8) -> Result<Vec<u8>, EncodeError> {
    use std::cell::RefCell;
    thread_local! {
        // One compressor per render thread: creating one allocates libjpeg-turbo's state.
        static COMPRESSOR: RefCell<Option<turbojpeg::Compressor>> = const { RefCell::new(None) };
    }
    COMPRESSOR.with(|cell| {
        let mut slot = cell.borrow_mut();
        let compressor = match &mut *slot {
            Some(c) => c,
            empty => empty.insert(turbojpeg::Compressor::new().map_err(EncodeError::from_message)?),
        };
        compressor
            .set_quality(quality as i32)
            .map_err(EncodeError::from_message)?;
        let subsamp = if quality < 90 {
            turbojpeg::Subsamp::Sub2x2
        } else {
            turbojpeg::Subsamp::None
        };
        compressor
            .set_subsamp(subsamp)
            .map_err(EncodeError::from_message)?;
        let image = turbojpeg::Image {
            pixels: rgb,
            width: width as usize,
            pitch: width as usize * 3,
            height: height as usize,
            format: turbojpeg::PixelFormat::RGB,
        };
        compressor
            .compress_to_vec(image)
            .map_err(EncodeError::from_message)
    })
}

#[cfg(not(feature = "turbojpeg"))]
fn turbo_jpeg(_: &[u8], _: u32, _: u32, _: u8) -> Result<Vec<u8>, EncodeError> {
    Err(EncodeError::from_message(
        "this build has no libjpeg-turbo (feature `turbojpeg`)",
    ))
}

/// Lossless PNG of the frame's colour with fast compression (the default level costs ten
/// times more for a few percent fewer bytes; see shared/CRATES.md).
pub fn png(fb: &Framebuffer) -> Result<Vec<u8>, EncodeError> {
    png_rgb(&fb.rgb, fb.width, fb.height)
}

/// Lossless PNG of packed RGB pixels.
pub fn png_rgb(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>, EncodeError> {
    check_rgb(rgb, width, height)?;
    let mut out = Vec::with_capacity(rgb.len() / 2);
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header().map_err(EncodeError::from_message)?;
    writer
        .write_image_data(rgb)
        .map_err(EncodeError::from_message)?;
    writer.finish().map_err(EncodeError::from_message)?;
    Ok(out)
}

/// Bytes of the depth block's fixed part, before its PNG.
pub const DEPTH_BLOCK_HEADER_LEN: usize = 48;

/// The compact depth channel of an interactive frame (layout in `protocol/PROTOCOL.md`):
/// the camera the frame was traced with, and inverse depth `q = near / depth` (0 where the
/// ray missed, so the background reprojects as a direction) quantised to 16 bits, at
/// `1/factor` of the frame's size in each direction, as an RGB PNG (R high byte, G low byte)
/// that the browser's image decoder unpacks losslessly. Each depth texel takes the nearest
/// depth of its block, so silhouettes keep their foreground.
pub fn depth_block(fb: &Framebuffer, camera: &Camera, factor: u32) -> Result<Vec<u8>, EncodeError> {
    let factor = factor.max(1);
    let (w, h) = (fb.width.div_ceil(factor), fb.height.div_ceil(factor));
    let mut nearest = vec![f32::INFINITY; w as usize * h as usize];
    for y in 0..fb.height {
        let row = &fb.depth[(y * fb.width) as usize..((y + 1) * fb.width) as usize];
        let out_row = (y / factor * w) as usize;
        for (x, &d) in row.iter().enumerate() {
            let cell = &mut nearest[out_row + x / factor as usize];
            if d < *cell {
                *cell = d;
            }
        }
    }
    let near = nearest
        .iter()
        .copied()
        .filter(|d| d.is_finite() && *d > 0.0)
        .fold(f32::INFINITY, f32::min);
    let near = if near.is_finite() { near } else { 1.0 };
    let mut rgb = Vec::with_capacity(nearest.len() * 3);
    for d in nearest {
        let q = if d.is_finite() && d > 0.0 {
            ((near / d).clamp(0.0, 1.0) * 65535.0).round() as u16
        } else {
            0
        };
        let [hi, lo] = q.to_be_bytes();
        rgb.extend([hi, lo, 0]);
    }
    let png = png_rgb(&rgb, w, h)?;
    let mut out = Vec::with_capacity(DEPTH_BLOCK_HEADER_LEN + png.len());
    out.extend_from_slice(&(w as u16).to_le_bytes());
    out.extend_from_slice(&(h as u16).to_le_bytes());
    out.extend_from_slice(&near.to_le_bytes());
    for v in [camera.eye, camera.target, camera.up] {
        for c in v.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    out.extend_from_slice(&camera.fov_y_deg.to_le_bytes());
    debug_assert_eq!(out.len(), DEPTH_BLOCK_HEADER_LEN);
    out.extend_from_slice(&png);
    Ok(out)
}

/// One session's H.264 stream: an OpenH264 encoder kept between frames, so each frame is
/// predicted from the last. A new size or bit rate starts a new stream with a keyframe
/// (IDR with SPS and PPS in front), as does [`H264Stream::force_keyframe`].
#[cfg(feature = "h264")]
pub struct H264Stream {
    encoder: openh264::encoder::Encoder,
    width: u32,
    height: u32,
    bitrate_bps: u32,
    yuv: openh264::formats::YUVBuffer,
}

/// One encoded H.264 access unit (Annex B, start codes included).
#[derive(Debug)]
pub struct H264Frame {
    pub bytes: Vec<u8>,
    /// Whether the unit is an IDR picture with its SPS and PPS, decodable on its own.
    pub keyframe: bool,
}

/// Whether this build can encode H.264.
pub const H264_AVAILABLE: bool = cfg!(feature = "h264");

#[cfg(feature = "h264")]
impl H264Stream {
    /// A stream of `width` × `height` frames (both even) at about `bitrate_bps`.
    pub fn new(
        width: u32,
        height: u32,
        bitrate_bps: u32,
        fps: f32,
    ) -> Result<H264Stream, EncodeError> {
        use openh264::encoder::{
            BitRate, Complexity, EncoderConfig, FrameRate, IntraFramePeriod, Profile,
            RateControlMode, UsageType,
        };
        if width % 2 != 0 || height % 2 != 0 || width < 16 || height < 16 {
            return Err(EncodeError(format!(
                "H.264 frames must be even-sized and at least 16×16, not {width}×{height}"
            )));
        }
        let config = EncoderConfig::new()
            .bitrate(BitRate::from_bps(bitrate_bps))
            .max_frame_rate(FrameRate::from_hz(fps))
            .rate_control_mode(RateControlMode::Bitrate)
            .usage_type(UsageType::CameraVideoRealTime)
            .profile(Profile::Baseline)
            .complexity(Complexity::Low)
            // Every frame the session renders is sent: a skipped frame would be an empty one.
            .skip_frames(false)
            // Keyframes only when asked for (a new stream, a new size).
            .intra_frame_period(IntraFramePeriod::from_num_frames(0))
            .num_threads(1)
            .debug(false);
        let encoder = openh264::encoder::Encoder::with_api_config(
            openh264::OpenH264API::from_source(),
            config,
        )
        .map_err(EncodeError::from_message)?;
        Ok(H264Stream {
            encoder,
            width,
            height,
            bitrate_bps,
            yuv: openh264::formats::YUVBuffer::new(width as usize, height as usize),
        })
    }

    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    pub fn bitrate_bps(&self) -> u32 {
        self.bitrate_bps
    }

    /// The next frame is a keyframe.
    pub fn force_keyframe(&mut self) {
        self.encoder.force_intra_frame();
    }

    /// Encodes packed RGB pixels of the stream's size.
    pub fn encode(&mut self, rgb: &[u8]) -> Result<H264Frame, EncodeError> {
        check_rgb(rgb, self.width, self.height)?;
        let source =
            openh264::formats::RgbSliceU8::new(rgb, (self.width as usize, self.height as usize));
        self.yuv.read_rgb8(source);
        let stream = self
            .encoder
            .encode(&self.yuv)
            .map_err(EncodeError::from_message)?;
        let bytes = stream.to_vec();
        let keyframe = matches!(
            stream.frame_type(),
            openh264::encoder::FrameType::IDR | openh264::encoder::FrameType::I
        );
        if bytes.is_empty() {
            return Err(EncodeError::from_message(
                "the H.264 encoder produced no picture",
            ));
        }
        Ok(H264Frame { bytes, keyframe })
    }
}

/// Peak signal-to-noise ratio of `decoded` against `reference`, dB (infinite when equal).
pub fn psnr(reference: &[u8], decoded: &[u8]) -> f64 {
    let n = reference.len().min(decoded.len()).max(1);
    let sse: f64 = reference
        .iter()
        .zip(decoded)
        .map(|(a, b)| {
            let d = *a as f64 - *b as f64;
            d * d
        })
        .sum();
    if sse == 0.0 {
        return f64::INFINITY;
    }
    10.0 * (255.0f64 * 255.0 / (sse / n as f64)).log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(width: u32, height: u32) -> Vec<u8> {
        (0..height)
            .flat_map(|y| {
                (0..width).flat_map(move |x| {
                    [
                        (x * 255 / width) as u8,
                        (y * 255 / height) as u8,
                        ((x + y) % 256) as u8,
                    ]
                })
            })
            .collect()
    }

    #[test]
    fn every_jpeg_encoder_of_the_build_makes_a_decodable_image() {
        let rgb = gradient(64, 48);
        for encoder in JpegEncoder::available() {
            let bytes = jpeg_rgb(&rgb, 64, 48, 80, encoder).expect("encodes");
            assert_eq!(
                &bytes[..2],
                &[0xFF, 0xD8],
                "{encoder:?} writes a JPEG SOI marker"
            );
            assert!(bytes.len() < rgb.len(), "{encoder:?} compresses");
        }
        assert!(
            jpeg_rgb(&rgb, 65, 48, 80, JpegEncoder::Rust).is_err(),
            "size mismatch"
        );
    }

    #[test]
    fn depth_block_quantises_inverse_depth_with_misses_at_zero() {
        let mut fb = Framebuffer::new(4, 2);
        fb.depth = vec![2.0, 4.0, f32::INFINITY, 8.0, 2.0, 2.0, 2.0, 2.0];
        let camera = Camera {
            eye: glam::Vec3::new(0.0, 0.0, 5.0),
            target: glam::Vec3::ZERO,
            up: glam::Vec3::Y,
            fov_y_deg: 45.0,
        };
        let block = depth_block(&fb, &camera, 1).expect("encodes");
        assert_eq!(u16::from_le_bytes([block[0], block[1]]), 4);
        assert_eq!(u16::from_le_bytes([block[2], block[3]]), 2);
        let near = f32::from_le_bytes([block[4], block[5], block[6], block[7]]);
        assert_eq!(near, 2.0, "near is the smallest depth");
        let eye_z = f32::from_le_bytes([block[16], block[17], block[18], block[19]]);
        assert_eq!(eye_z, 5.0);
        // Decode the PNG and check q = near / depth for a few texels.
        let decoder = png::Decoder::new(std::io::Cursor::new(&block[DEPTH_BLOCK_HEADER_LEN..]));
        let mut reader = decoder.read_info().expect("png");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        reader.next_frame(&mut buf).expect("frame");
        let q = |i: usize| u16::from_be_bytes([buf[i * 3], buf[i * 3 + 1]]);
        assert_eq!(q(0), 65535, "depth 2 = near");
        assert_eq!(q(1), 32768, "depth 4 = near / 2");
        assert_eq!(q(2), 0, "a miss is at infinity");
        assert_eq!(q(3), 16384, "depth 8 = near / 4");
    }

    #[test]
    fn psnr_is_infinite_for_equal_images_and_finite_otherwise() {
        assert!(psnr(&[1, 2, 3], &[1, 2, 3]).is_infinite());
        let p = psnr(&[0, 0, 0, 0], &[0, 0, 0, 255]);
        assert!((p - 6.02).abs() < 0.01, "{p}");
    }

    #[cfg(feature = "h264")]
    #[test]
    fn h264_stream_starts_with_a_keyframe_and_then_predicts() {
        let rgb = gradient(64, 48);
        let mut stream = H264Stream::new(64, 48, 500_000, 30.0).expect("encoder");
        let first = stream.encode(&rgb).expect("first");
        assert!(first.keyframe, "a stream starts with a keyframe");
        assert_eq!(&first.bytes[..4], &[0, 0, 0, 1], "Annex B start code");
        let second = stream.encode(&rgb).expect("second");
        assert!(!second.keyframe);
        assert!(second.bytes.len() < first.bytes.len());
        stream.force_keyframe();
        assert!(stream.encode(&rgb).expect("third").keyframe);
        assert!(H264Stream::new(63, 48, 500_000, 30.0).is_err(), "odd width");
    }
}
