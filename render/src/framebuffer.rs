//! The image a render produces: 8-bit sRGB colour and linear depth.

/// Pixels in row-major order from the top-left corner.
#[derive(Clone, Debug, PartialEq)]
pub struct Framebuffer {
    pub width: u32,
    pub height: u32,
    /// sRGB, three bytes per pixel.
    pub rgb: Vec<u8>,
    /// Distance along the view axis to the first hit, `f32::INFINITY` where the ray missed.
    pub depth: Vec<f32>,
}

impl Framebuffer {
    pub fn new(width: u32, height: u32) -> Framebuffer {
        let n = width as usize * height as usize;
        Framebuffer {
            width,
            height,
            rgb: vec![0; n * 3],
            depth: vec![f32::INFINITY; n],
        }
    }

    /// Number of pixels whose ray hit a surface.
    pub fn hit_count(&self) -> usize {
        self.depth.iter().filter(|d| d.is_finite()).count()
    }
}
