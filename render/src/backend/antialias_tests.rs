//! Antialiasing of a resting view ([`Accumulator::antialias`]): the mean of passes seen from
//! sub-pixel offsets against each pixel's area sampled on a fine grid, by brute force.

use super::accumulator::{subpixel_offset, Accumulator};
use super::cpu::CpuBackend;
use crate::effects::toggles::Effects;
use crate::framebuffer::Framebuffer;
use crate::scenes::DemoScene;
use crate::shade::srgb8_to_linear;
use crate::srgb::encode8_rgb;
use crate::View;
use glam::Vec3;
use std::sync::Arc;

/// Pixel `i`'s colour in linear light.
fn linear(fb: &Framebuffer, i: usize) -> Vec3 {
    let c = &fb.rgb[i * 3..i * 3 + 3];
    Vec3::new(
        srgb8_to_linear(c[0]),
        srgb8_to_linear(c[1]),
        srgb8_to_linear(c[2]),
    )
}

#[test]
fn subpixel_offsets_cover_the_pixel_from_its_centre() {
    assert_eq!(subpixel_offset(0), (0.0, 0.0));
    let offsets: Vec<(f32, f32)> = (1..16).map(subpixel_offset).collect();
    for &(x, y) in &offsets {
        assert!(
            (-0.5..0.5).contains(&x) && (-0.5..0.5).contains(&y),
            "({x}, {y})"
        );
    }
    // Every quarter of the pixel gets three of the first fifteen (Halton's stratification).
    for (qx, qy) in [(false, false), (false, true), (true, false), (true, true)] {
        let n = offsets
            .iter()
            .filter(|&&(x, y)| (x >= 0.0) == qx && (y >= 0.0) == qy)
            .count();
        assert!((3..=5).contains(&n), "quarter ({qx}, {qy}): {n} offsets");
    }
}

/// A ray-cast view of Blobs refined with sixteen sub-pixel positions, against the same view
/// rendered 8× larger and averaged over each pixel's 64 centres in linear light: on the
/// pixels one sample gets wrong (the blobs' edges) the antialiased image is several times
/// nearer that reference (measured: 11.1 codes summed over the channels against 59.3); it
/// keeps the first pass's depths, and it is deterministic. (A floor's checker is filtered
/// over each pass's footprint already, so there the passes blur it a little more than a
/// pixel's area: not a scene for this comparison.)
#[test]
fn a_resting_view_averages_its_pixels() {
    let backend = CpuBackend::new(2).expect("pool");
    let demo = DemoScene::Blobs;
    let scene = Arc::new(demo.state_at(1.0)).prepare();
    let view = demo.default_view(64, 48);
    let refined = || {
        let mut acc = Accumulator::new(64);
        acc.antialias = 16;
        let fb = backend.refine_until_converged(&scene, &view, &Effects::OFF, &mut acc);
        assert_eq!(acc.passes(), 16, "every position once, then final");
        fb
    };
    let aa = refined();
    assert!(aa == refined(), "the same settings give the same image");
    let (single, _) = backend.render_effects(&scene, &view, &Effects::OFF);
    assert_eq!(
        aa.depth, single.depth,
        "the depths are the pixels' centres'"
    );

    const K: u32 = 8;
    let fine_view = View {
        width: view.width * K,
        height: view.height * K,
        ..view
    };
    let (fine, _) = backend.render_effects(&scene, &fine_view, &Effects::OFF);
    let (mut err_aa, mut err_single, mut edges) = (0.0f64, 0.0f64, 0);
    for y in 0..view.height {
        for x in 0..view.width {
            let mut sum = Vec3::ZERO;
            for fy in 0..K {
                for fx in 0..K {
                    sum += linear(
                        &fine,
                        ((y * K + fy) * fine_view.width + x * K + fx) as usize,
                    );
                }
            }
            let reference = encode8_rgb((sum / (K * K) as f32).to_array());
            let i = (y * view.width + x) as usize;
            let diff = |fb: &Framebuffer| {
                (0..3)
                    .map(|c| fb.rgb[i * 3 + c].abs_diff(reference[c]) as f64)
                    .sum::<f64>()
            };
            // Pixels whose one sample is off by more than 8 codes in a channel: edges.
            if (0..3).any(|c| single.rgb[i * 3 + c].abs_diff(reference[c]) > 8) {
                edges += 1;
                err_aa += diff(&aa);
                err_single += diff(&single);
            }
        }
    }
    let (err_aa, err_single) = (err_aa / edges as f64, err_single / edges as f64);
    eprintln!(
        "{edges} edge pixels: mean error {err_aa:.1} codes antialiased, {err_single:.1} one sample"
    );
    assert!(edges > 50, "{edges} edge pixels");
    assert!(
        err_aa < 0.3 * err_single,
        "edge pixels' mean error: antialiased {err_aa:.1}, one sample {err_single:.1}"
    );
}

/// With antialiasing a plan with nothing random is refined over every position, and a
/// stochastic one converges no earlier than that.
#[test]
fn antialiasing_sets_the_fewest_passes() {
    let backend = CpuBackend::new(2).expect("pool");
    let demo = DemoScene::Glass;
    let scene = Arc::new(demo.state_at(1.0)).prepare();
    let view = demo.default_view(32, 24);
    let soft = Effects {
        shadows: true,
        soft_shadows: true,
        light_samples: 2,
        ..Effects::OFF
    };
    for (effects, antialias) in [(Effects::OFF, 1), (Effects::OFF, 6), (soft, 6)] {
        let mut acc = Accumulator::new(64);
        acc.antialias = antialias;
        acc.threshold = 1.0;
        backend.refine_until_converged(&scene, &view, &effects, &mut acc);
        let least = if antialias > 1 { antialias } else { 1 };
        assert_eq!(acc.passes(), least, "{effects:?}, antialias {antialias}");
    }
}
