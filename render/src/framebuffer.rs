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

/// What a primary ray found, per pixel: the distance along the unit-length ray from the eye
/// to the first hit and the outward unit normal there (world space, not turned towards the
/// viewer). A miss is `[∞, 0, 0, 0]`. Row-major from the top-left, four `f32` per pixel: the
/// `(H, W, 4)` array that `format: "npy"` returns.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceBuffer {
    pub width: u32,
    pub height: u32,
    pub values: Vec<f32>,
}

impl SurfaceBuffer {
    /// Values per pixel: hit distance, normal x, y, z.
    pub const CHANNELS: usize = 4;

    /// The pixel's `[t, nx, ny, nz]`.
    pub fn at(&self, x: u32, y: u32) -> [f32; 4] {
        let i = (y as usize * self.width as usize + x as usize) * Self::CHANNELS;
        [
            self.values[i],
            self.values[i + 1],
            self.values[i + 2],
            self.values[i + 3],
        ]
    }
}
