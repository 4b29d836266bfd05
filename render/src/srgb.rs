//! Linear light to 8-bit sRGB codes, fast and exactly as the formula gives them.
//!
//! The formula (IEC 61966-2-1: `12.92·v` below 0.0031308, else `1.055·v^(1/2.4) − 0.055`,
//! then `⌊255·s + 0.5⌋`) costs a `powf` per channel, three per pixel of every frame. The code
//! it gives never decreases as `v` grows, so it is fixed by the 255 least values at which it
//! steps up (`Tables::steps`, found once by bisection over the `f32` bit patterns with the formula
//! itself); a value's code is the number of steps at or below it, counted from a table
//! indexed by the value's top 16 bits: at most one step lies above a prefix's least value
//! within it, so one comparison finishes the count, without a branch (the data-dependent
//! walk it replaces was mispredicted about every other pixel). The test
//! `the_fast_code_is_the_formulas_for_every_f32_in_0_1` compares the two for every `f32`
//! from 0 to 1 (about 1.07 billion values), so the images do not change by a bit.

use std::sync::OnceLock;

/// The sRGB code of linear `v` by the formula (clamped to `[0, 1]`; NaN gives 0).
#[inline]
pub fn encode8_formula(v: f32) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// The least values, for `k = 1..=255`, whose code is at least `k` (then an infinity, so
/// that the comparison after any prefix's code stays in the array), and the code of the
/// least value with each top-16-bit prefix from `first` (the one below the first step's) to
/// 1.0's. Below `first` every value's code is 0, so the table starts there: 1.6 KB instead
/// of 16 KB, which stays in the first-level cache beside the tracer's data.
struct Tables {
    steps: [f32; 256],
    first: usize,
    by_prefix: Vec<u8>,
}

/// The top 16 bits of a value in `[0, 1]`.
#[inline(always)]
fn prefix(v: f32) -> usize {
    (v.to_bits() >> 16) as usize
}

fn tables() -> &'static Tables {
    static TABLES: OnceLock<Tables> = OnceLock::new();
    TABLES.get_or_init(|| {
        let one = 1.0f32.to_bits();
        let mut steps = [f32::INFINITY; 256];
        for (k, step) in steps[..255].iter_mut().enumerate() {
            let code = k as u8 + 1;
            // The least bit pattern in [0, 1] whose code is at least `code` (1.0's is 255).
            let (mut lo, mut hi) = (0u32, one);
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if encode8_formula(f32::from_bits(mid)) >= code {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            *step = f32::from_bits(lo);
        }
        // One prefix below the first step's: its least value is below that step (code 0).
        let first = prefix(steps[0]) - 1;
        let by_prefix = (first..=prefix(1.0))
            .map(|p| {
                let least = f32::from_bits((p as u32) << 16);
                steps[..255].partition_point(|&s| s <= least) as u8
            })
            .collect();
        Tables {
            steps,
            first,
            by_prefix,
        }
    })
}

/// The sRGB code of linear `v`: [`encode8_formula`]'s, by table.
#[inline]
pub fn encode8(v: f32) -> u8 {
    code_of(tables(), v)
}

/// [`encode8`] of each channel of `rgb`, the tables looked up once.
#[inline]
pub fn encode8_rgb(rgb: [f32; 3]) -> [u8; 3] {
    codes_of(tables(), rgb)
}

/// [`encode8`] of every channel of `colors` into `out` (three bytes a colour).
pub fn encode8_pixels(colors: &[glam::Vec3], out: &mut [u8]) {
    let t = tables();
    for (c, px) in colors.iter().zip(out.chunks_exact_mut(3)) {
        px.copy_from_slice(&codes_of(t, c.to_array()));
    }
}

#[inline(always)]
fn codes_of(t: &Tables, rgb: [f32; 3]) -> [u8; 3] {
    rgb.map(|v| code_of(t, v))
}

#[inline(always)]
fn code_of(t: &Tables, v: f32) -> u8 {
    if !(v > 0.0) {
        return 0; // zero, negative or NaN
    }
    if v >= 1.0 {
        return 255;
    }
    // At most one step above the prefix's least value lies within the prefix (the test
    // checks it), and the step past the 255th is infinite. A value below `first` is below
    // the first step: the clamped index's code (0) and the comparison give its 0.
    let base = t.by_prefix[prefix(v).saturating_sub(t.first)];
    base + u8::from(v >= t.steps[base as usize])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    /// Every `f32` in `[0, 1]`, and the values outside it, get the formula's code.
    #[test]
    fn the_fast_code_is_the_formulas_for_every_f32_in_0_1() {
        let one = 1.0f32.to_bits();
        let chunk = 1u32 << 20;
        let mismatches: u64 = (0..=one / chunk)
            .into_par_iter()
            .map(|c| {
                let (lo, hi) = (c * chunk, (c * chunk).saturating_add(chunk - 1).min(one));
                (lo..=hi)
                    .filter(|&b| {
                        let v = f32::from_bits(b);
                        encode8(v) != encode8_formula(v)
                    })
                    .count() as u64
            })
            .sum();
        assert_eq!(mismatches, 0);
        for v in [
            -0.0,
            -1e-30,
            -1.0,
            f32::NEG_INFINITY,
            1.0 + f32::EPSILON,
            7.5,
            f32::INFINITY,
            f32::NAN,
        ] {
            assert_eq!(encode8(v), encode8_formula(v), "{v}");
        }
        // The steps are real: codes 0 and 255 at the ends, every code met in between.
        let mut seen = [false; 256];
        for &s in &tables().steps[..255] {
            seen[encode8(s) as usize] = true;
        }
        assert!(seen[1..].iter().all(|&s| s));
        // Within a prefix the code rises by at most one step.
        let t = tables();
        assert!(t.by_prefix.len() < 2_000, "{}", t.by_prefix.len());
        assert_eq!(t.by_prefix[0], 0);
        for (i, &least) in t.by_prefix.iter().enumerate().take(t.by_prefix.len() - 1) {
            let p = t.first + i;
            assert_eq!(encode8_formula(f32::from_bits((p as u32) << 16)), least);
            let most = encode8(f32::from_bits(((p as u32) << 16) | 0xFFFF));
            assert!(most - least <= 1, "prefix {p}: codes {least}..={most}");
        }
    }

    #[test]
    fn a_pixels_codes_are_its_channels_codes() {
        let values = [
            -1.0,
            0.0,
            1e-9,
            0.002,
            0.0031308,
            0.2,
            0.5,
            0.999_999_9,
            1.0,
            3.0,
        ];
        let colors: Vec<glam::Vec3> = (0..values.len() * values.len())
            .map(|i| {
                let (a, b) = (values[i % values.len()], values[i / values.len()]);
                glam::Vec3::new(a, b, f32::NAN)
            })
            .collect();
        let mut out = vec![7u8; colors.len() * 3];
        encode8_pixels(&colors, &mut out);
        for (c, px) in colors.iter().zip(out.chunks_exact(3)) {
            let each = [c.x, c.y, c.z].map(encode8_formula);
            assert_eq!(px, each, "{c}");
            assert_eq!(encode8_rgb(c.to_array()), each, "{c}");
        }
    }
}
