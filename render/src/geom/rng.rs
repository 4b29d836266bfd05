//! The engine's two deterministic random generators: [`SplitMix64`] for generated scenes
//! (fixed seeds, so every run sees the same states) and [`PixelRng`], one stream per pixel
//! and refinement pass for the effects' samples (an image is the same whatever the thread
//! count or tile order, and a test can reproduce any pass).

use glam::Vec3;

/// A small fixed-seed generator (SplitMix64) so scenes never depend on a platform RNG.
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }

    /// Uniform in the unit ball.
    pub fn in_unit_ball(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            if v.length_squared() <= 1.0 {
                return v;
            }
        }
    }
}

/// The random stream of one pixel in one pass (SplitMix64 over a hashed seed).
#[derive(Clone, Debug)]
pub struct PixelRng(u64);

#[inline]
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl PixelRng {
    /// The stream of pixel (`x`, `y`) in pass `pass`.
    #[inline]
    pub fn new(x: u32, y: u32, pass: u32) -> PixelRng {
        let key = ((y as u64) << 32 | x as u64) ^ mix((pass as u64).wrapping_add(0x1503_A7E5));
        PixelRng(mix(key.wrapping_mul(0x9E37_79B9_7F4A_7C15)))
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix(self.0)
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }
}
