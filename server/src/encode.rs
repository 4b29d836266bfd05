//! Frame encoders. They run on the render pool, never on the async runtime.

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
