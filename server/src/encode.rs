//! Frame encoders: JPEG for interactive frames, lossless PNG for the still frame. They run on
//! the render pool, never on the async runtime.

use isoray_render::Framebuffer;

/// Why a frame could not be encoded.
#[derive(Debug, thiserror::Error)]
#[error("encoding failed: {0}")]
pub struct EncodeError(String);

/// Baseline JPEG of the frame's colour, with `jpeg-encoder`'s SIMD colour conversion.
pub fn jpeg(fb: &Framebuffer, quality: u8) -> Result<Vec<u8>, EncodeError> {
    let width = u16::try_from(fb.width).map_err(|_| EncodeError("frame too wide".into()))?;
    let height = u16::try_from(fb.height).map_err(|_| EncodeError("frame too tall".into()))?;
    let mut out = Vec::with_capacity(fb.rgb.len() / 8);
    jpeg_encoder::Encoder::new(&mut out, quality)
        .encode(&fb.rgb, width, height, jpeg_encoder::ColorType::Rgb)
        .map_err(|e| EncodeError(e.to_string()))?;
    Ok(out)
}

/// Lossless PNG of the frame's colour with fast compression (the default level costs ten
/// times more for a few percent fewer bytes; see shared/CRATES.md).
pub fn png(fb: &Framebuffer) -> Result<Vec<u8>, EncodeError> {
    let mut out = Vec::with_capacity(fb.rgb.len() / 2);
    let mut encoder = png::Encoder::new(&mut out, fb.width, fb.height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder
        .write_header()
        .map_err(|e| EncodeError(e.to_string()))?;
    writer
        .write_image_data(&fb.rgb)
        .map_err(|e| EncodeError(e.to_string()))?;
    writer.finish().map_err(|e| EncodeError(e.to_string()))?;
    Ok(out)
}
