//! The GPU backend against the CPU backend on lavapipe (Vulkan; CI installs Mesa's software
//! driver). A missing driver fails these tests: wgpu is built with its Vulkan backend only,
//! and every test asserts that each frame it compares really was traced on the GPU.
//!
//! Agreement (issue 12, Must show 1): every demo scene at 160×120, prepared as the server
//! prepares it (the CPU's default finder: Bézier clipping for metaballs, which the GPU kernel
//! uses too; finder_tests.rs checks the others), with four effect sets — ray casting, hard
//! shadows, the scene's own defaults, and every effect on (each distinct plan once) — the
//! first refinement pass of each (the same random streams on both sides). Stated tolerance: the same hit or miss on at
//! least 99.9% of pixels; over pixels that agree on it, at least 99% of channels within 3
//! sRGB codes and a mean difference under 0.5 codes. The figures of every pair are printed.

use crate::backend::accumulator::{self, DeviceTimes, TracePasses};
use crate::backend::cpu::CpuBackend;
use crate::backend::dispatch::Backend;
use crate::backend::gpu::backend::{GpuBackend, DEFAULT_MEMORY_BUDGET};
use crate::backend::gpu::buffers::{Budget, FrameBuffers};
use crate::backend::gpu::device::{AdapterChoice, GpuDevice};
use crate::backend::gpu::layout::flags;
use crate::backend::gpu::retrace::{retrace_cut, CUT_DEPTH};
use crate::backend::gpu::upload;
use crate::effects::toggles::Effects;
use crate::framebuffer::Framebuffer;
use crate::kinds::dispatch::Geometry;
use crate::scene::PreparedScene;
use crate::scenes::DemoScene;
use crate::shade::linear_to_srgb8;
use crate::view::View;
use std::sync::Arc;

const WIDTH: u32 = 160;
const HEIGHT: u32 = 120;

pub(super) fn gpu() -> GpuBackend {
    let gpu = GpuBackend::new(2, AdapterChoice::Any, DEFAULT_MEMORY_BUDGET)
        .unwrap_or_else(|e| panic!("a Vulkan adapter (lavapipe in CI): {e}"));
    assert!(
        gpu.adapter().contains("Vulkan"),
        "the adapter is a Vulkan one: {}",
        gpu.adapter()
    );
    gpu
}

/// `demo` at 160×120, prepared as the server does.
pub(super) fn setup(demo: DemoScene) -> (PreparedScene, View) {
    let state = Arc::new(demo.state_at(1.0));
    let scene = state.prepare();
    let view = demo.default_view(WIDTH, HEIGHT);
    (scene, view)
}

/// Whether the GPU kernel traces `geometry`'s kind (the others go to the CPU, and the
/// agreement test checks that they do, with the CPU's image).
fn on_gpu(geometry: &Geometry) -> bool {
    match geometry {
        Geometry::Metaballs(_) => true,
        Geometry::Tets(_) => true,
        Geometry::Surfels(_) => true,
    }
}

/// How two frames differ.
#[derive(Debug)]
struct Agreement {
    /// Pixels compared.
    pixels: usize,
    hits: usize,
    /// Pixels one frame hits and the other misses.
    hit_mismatch: usize,
    /// Over pixels with the same hit/miss: channels more than 3 codes apart, the largest
    /// difference, and the mean difference.
    far_channels: usize,
    max_diff: u8,
    mean_diff: f64,
}

fn agreement(a: &Framebuffer, b: &Framebuffer) -> Agreement {
    agreement_where(a, b, |_| true)
}

/// [`agreement`] over the pixels `i` for which `compared(i)`.
fn agreement_where(
    a: &Framebuffer,
    b: &Framebuffer,
    compared: impl Fn(usize) -> bool,
) -> Agreement {
    let (mut hits, mut hit_mismatch, mut far, mut max, mut sum, mut n) = (0, 0, 0, 0u8, 0u64, 0u64);
    let mut pixels = 0;
    for i in (0..a.depth.len()).filter(|&i| compared(i)) {
        pixels += 1;
        let (ha, hb) = (a.depth[i].is_finite(), b.depth[i].is_finite());
        hits += ha as usize;
        if ha != hb {
            hit_mismatch += 1;
            continue;
        }
        for c in 0..3 {
            let d = a.rgb[i * 3 + c].abs_diff(b.rgb[i * 3 + c]);
            far += (d > 3) as usize;
            max = max.max(d);
            sum += d as u64;
            n += 1;
        }
    }
    Agreement {
        pixels,
        hits,
        hit_mismatch,
        far_channels: far,
        max_diff: max,
        mean_diff: sum as f64 / n.max(1) as f64,
    }
}

fn assert_agree(what: &str, cpu: &Framebuffer, gpu: &Framebuffer) -> Agreement {
    assert_agreement(what, agreement(cpu, gpu))
}

/// The stated tolerance on `a`.
fn assert_agreement(what: &str, a: Agreement) -> Agreement {
    let pixels = a.pixels;
    eprintln!("{what}: {a:?}, largest difference {} codes", a.max_diff);
    assert!(
        a.hits > pixels / 50,
        "{what}: the view sees the surface ({a:?})"
    );
    assert!(
        a.hit_mismatch * 1000 <= pixels,
        "{what}: hit/miss differs on more than 0.1% of pixels ({a:?})"
    );
    let channels = 3 * (pixels - a.hit_mismatch);
    assert!(
        a.far_channels * 100 <= channels,
        "{what}: more than 1% of channels over 3 codes apart ({a:?})"
    );
    assert!(a.mean_diff < 0.5, "{what}: mean difference ({a:?})");
    a
}

/// The effect sets every demo is rendered with.
fn effect_sets(scene: &PreparedScene) -> [(&'static str, Effects); 4] {
    [
        ("ray casting", Effects::OFF),
        (
            "hard shadows",
            Effects {
                shadows: true,
                ..Effects::OFF
            },
        ),
        ("its defaults", scene.lighting().effects),
        ("every effect", Effects::ALL),
    ]
}

/// Renders `demo` with every effect set on both backends; checks that the GPU traced each
/// frame its kind is traced by (the CPU the others) and that the images agree.
fn check(gpu: &GpuBackend, cpu: &CpuBackend, demo: DemoScene) {
    let (scene, view) = setup(demo);
    let traced_by_gpu = on_gpu(&scene.scene().geometry);
    let mut plans = Vec::new();
    for (name, effects) in effect_sets(&scene) {
        // A set whose plan an earlier set already had renders the same frame again.
        let plan = accumulator::plan_for(&scene, &effects);
        if plans.contains(&plan) {
            continue;
        }
        plans.push(plan);
        let (gpu_before, cpu_before) = gpu.frames();
        let (g, _) = accumulator::render_effects(gpu, &scene, &view, &effects);
        let what = format!("{} with {name}", demo.name());
        let (c, _) = accumulator::render_effects(cpu, &scene, &view, &effects);
        let refused = (!plan.is_primary_only())
            .then(|| upload::check_plan(&plan).err())
            .flatten();
        // Issue 12, Must show 1: every demo with every effect set is the GPU's.
        assert_eq!(refused, None, "{what}: the GPU refuses the plan");
        if traced_by_gpu {
            assert_eq!(
                gpu.frames(),
                (gpu_before + 1, cpu_before),
                "{what}: the GPU traced the frame"
            );
            assert_agree(&what, &c, &g);
        } else {
            assert_eq!(
                gpu.frames(),
                (gpu_before, cpu_before + 1),
                "{what}: the CPU traced the frame"
            );
            assert!(g == c, "{what}: the fallback is the CPU's image");
        }
    }
}

#[test]
fn gpu_and_cpu_agree_on_every_demo_with_every_effect() {
    let (gpu, cpu) = (gpu(), CpuBackend::new(2).expect("pool"));
    for demo in DemoScene::ALL {
        check(&gpu, &cpu, demo);
    }
    assert!(!gpu.has_failed());
}

#[test]
fn mirror_rays_from_outside_surfels_leave_the_surface_on_both_backends() {
    // The ball pit just after the landing with every ball a perfect mirror: asked as camera
    // rays, hundreds of its mirror rays meet a neighbouring leaf's sheet of their own surface
    // at their start (stability::surfel_shadows); both backends ask them as rays leaving the
    // surface (`first_hit_leaving`; the kernel's task `leaving`).
    let (gpu, cpu) = (gpu(), CpuBackend::new(2).expect("pool"));
    let mut state = DemoScene::SurfelBalls.state_at(0.61);
    state.lighting.materials[0].reflectivity = 1.0;
    let scene = Arc::new(state).prepare();
    let view = DemoScene::SurfelBalls.default_view(320, 240);
    let effects = Effects {
        reflections: true,
        depth: 1,
        ..scene.lighting().effects
    };
    let (g, _) = accumulator::render_effects(&gpu, &scene, &view, &effects);
    let (c, _) = accumulator::render_effects(&cpu, &scene, &view, &effects);
    // Measured on lavapipe: 795 channels over 3 codes apart (mirrors magnify the backends'
    // rounding of the MLS normals), mean 0.28 codes; with the kernel asking mirror rays as
    // camera rays, 2,573 and 0.64 (over the agreement's 1% and 0.5).
    let a = assert_agree("the mirror ball pit", &c, &g);
    assert!(a.far_channels <= 1500, "{a:?}");
}

/// Pixels of `fb` whose hit lies more than `gap` behind the hits of all four neighbours: the
/// object's back seen through a crack in its front.
fn specks(fb: &Framebuffer, gap: f32) -> usize {
    let (w, h) = (fb.width as usize, fb.height as usize);
    let depth = |x: usize, y: usize| fb.depth[y * w + x];
    (1..h - 1)
        .flat_map(|y| (1..w - 1).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let t = depth(x, y);
            let around = [(x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)];
            t.is_finite() && around.iter().all(|&(i, j)| t > depth(i, j) + gap)
        })
        .count()
}

#[test]
fn the_strikes_cracks_close_on_both_backends() {
    // `surfel-impact` as the cannonball dents the blob (step 6): where the start gate turns
    // away every leaf of the front a camera ray's nearest hit is the blob's back, facing away
    // from it; both backends search such a ray again for a crossing in before it (the CPU's
    // `camera_nearest`, the kernel's `kind_first_hit` from 0).
    let (gpu, cpu) = (gpu(), CpuBackend::new(2).expect("pool"));
    let scene = Arc::new(DemoScene::SurfelImpact.state_at(0.2)).prepare();
    let view = DemoScene::SurfelImpact.default_view(320, 240);
    let effects = scene.lighting().effects;
    let (g, _) = accumulator::render_effects(&gpu, &scene, &view, &effects);
    let (c, _) = accumulator::render_effects(&cpu, &scene, &view, &effects);
    // Measured on lavapipe: no channel over 3 codes apart and no speck on either backend;
    // with the kernel's second search left out, 105 channels and 6 specks on the GPU (within
    // the agreement's 1%, so counted here).
    let a = assert_agree("the strike", &c, &g);
    let (sc, sg) = (specks(&c, 0.1), specks(&g, 0.1));
    eprintln!("the strike: specks CPU {sc}, GPU {sg}");
    assert!(a.far_channels <= 30, "{a:?}");
    assert!(sc <= 2 && sg <= 2, "specks: CPU {sc}, GPU {sg}");
}

/// The kernel's output as the backend turns it into a frame (a negative depth: a miss).
fn framebuffer(pixels: &[[f32; 4]]) -> Framebuffer {
    let mut fb = Framebuffer::new(WIDTH, HEIGHT);
    for (i, p) in pixels.iter().enumerate() {
        fb.rgb[i * 3..i * 3 + 3].copy_from_slice(&[p[0], p[1], p[2]].map(linear_to_srgb8));
        fb.depth[i] = if p[3] < 0.0 { f32::INFINITY } else { p[3] };
    }
    fb
}

/// Issue 12's two disagreements through transparent layers (Glass with its defaults, the tet
/// gyroid's occlusion through further isosurfaces with every effect) were lavapipe
/// cutting the loops of 8-pixel groups short once their shared budget of 65,535 iterations
/// was spent (retrace.rs). Traced past check_plan's refusal and asked to (MARK_CUT), on
/// lavapipe the kernel marks such pixels (on a hardware GPU it has none to mark); every
/// pixel it leaves unmarked agrees with the CPU within the stated tolerance, and with the
/// marked ones traced again on the CPU the whole frame does.
#[test]
fn pixels_the_driver_cuts_short_are_marked_and_traced_again_on_the_cpu() {
    let device = GpuDevice::new(AdapterChoice::Any).expect("a Vulkan adapter");
    let lavapipe = device.info.name.contains("llvmpipe");
    let cpu = CpuBackend::new(2).expect("pool");
    let mut buffers = FrameBuffers::default();
    for (demo, effects) in [
        (DemoScene::Glass, None),
        (DemoScene::TetGyroid, Some(Effects::ALL)),
    ] {
        let (scene, view) = setup(demo);
        let effects = effects.unwrap_or(scene.lighting().effects);
        let plan = accumulator::plan_for(&scene, &effects);
        assert!(
            plan.layers > 0 && plan.shadows,
            "{}: layers and shadows",
            demo.id()
        );
        let kind = upload::kind_upload(&scene, &view, Some(&plan)).expect("the kernel holds it");
        let mut frame = upload::frame(&scene, &view, Some(&plan), 0);
        frame.flags |= flags::MARK_CUT;
        let arrays = upload::lighting(scene.lighting_in_frame());
        let budget = Budget {
            bytes: DEFAULT_MEMORY_BUDGET,
            max_binding: device.device.limits().max_storage_buffer_binding_size,
        };
        let mut pixels = buffers
            .run(
                &device,
                &frame,
                kind,
                &arrays,
                &budget,
                &mut DeviceTimes::default(),
            )
            .expect("traced on the GPU");
        let (c, _) = accumulator::render_effects(&cpu, &scene, &view, &effects);
        let marked: Vec<bool> = pixels.iter().map(|p| p[3] == CUT_DEPTH).collect();
        let n = marked.iter().filter(|&&m| m).count();
        eprintln!(
            "{}: {n} pixels cut short on {}",
            demo.id(),
            device.info.name
        );
        if lavapipe {
            assert!(
                n > 0,
                "{}: lavapipe's loop budget still cuts this frame",
                demo.id()
            );
        }
        assert!(
            n * 5 < pixels.len(),
            "{}: most pixels finish ({n})",
            demo.id()
        );
        let unmarked = framebuffer(&pixels);
        let what = format!("{} unmarked pixels", demo.id());
        assert_agreement(&what, agreement_where(&c, &unmarked, |i| !marked[i]));
        assert_eq!(retrace_cut(&mut pixels, &scene, &view, &plan, 0), n);
        let what = format!("{} with the cut pixels traced on the CPU", demo.id());
        assert_agree(&what, &c, &framebuffer(&pixels));
    }
}

#[test]
fn buffers_are_reused_while_sizes_do_not_grow() {
    let gpu = gpu();
    let (scene, view) = setup(DemoScene::Blobs);
    gpu.render_primary(&scene, &view);
    let first = gpu.allocations();
    assert!(first >= 9, "every buffer made once ({first})");
    gpu.render_primary(&scene, &view);
    let small = View {
        width: 40,
        height: 30,
        ..view
    };
    gpu.render_primary(&scene, &small);
    assert_eq!(
        gpu.allocations(),
        first,
        "same or smaller frames allocate nothing"
    );
    let big = View {
        width: 320,
        height: 240,
        ..view
    };
    gpu.render_primary(&scene, &big);
    assert_eq!(
        gpu.allocations(),
        first + 2,
        "a larger frame grows the output and readback buffers only"
    );
    assert_eq!(gpu.frames(), (4, 0));
}

#[test]
fn what_the_kernel_cannot_hold_goes_to_the_cpu_with_the_same_image() {
    let (gpu, cpu) = (gpu(), CpuBackend::new(2).expect("pool"));
    let (scene, view) = setup(DemoScene::Glass);
    // 16 bounces and 16 layers can leave more rays waiting than the kernel's stack.
    let deep = Effects {
        depth: 16,
        layers: 16,
        ..Effects::ALL
    };
    let (g, _) = accumulator::render_effects(&gpu, &scene, &view, &deep);
    let (c, _) = accumulator::render_effects(&cpu, &scene, &view, &deep);
    assert_eq!(gpu.frames(), (0, 1), "traced on the CPU");
    assert!(g == c, "with the CPU's image");
    assert!(!gpu.has_failed());
}

#[test]
fn a_lost_device_moves_the_backend_to_the_cpu() {
    let (gpu, cpu) = (gpu(), CpuBackend::new(2).expect("pool"));
    let (scene, view) = setup(DemoScene::Blobs);
    gpu.render_primary(&scene, &view);
    assert_eq!(gpu.frames(), (1, 0));
    gpu.lose_device();
    let after = gpu.render_primary(&scene, &view);
    assert!(gpu.has_failed(), "the backend noticed the lost device");
    assert_eq!(
        after,
        cpu.render_primary(&scene, &view),
        "the CPU traced it"
    );
    gpu.render_primary(&scene, &view);
    assert_eq!(gpu.frames(), (1, 2), "and every frame after it");
}

#[test]
fn auto_takes_a_hardware_gpu_only() {
    let (backend, why) = Backend::auto(1, DEFAULT_MEMORY_BUDGET).expect("pool");
    match &backend {
        Backend::Cpu(_) => {
            let why = why.expect("a reason");
            assert!(
                why.contains("no hardware GPU") || why.contains("no GPU adapter"),
                "{why}"
            );
        }
        Backend::Gpu(gpu) => assert!(!gpu.adapter().contains("Cpu"), "{}", gpu.adapter()),
    }
}

/// Mean absolute difference of two passes' linear colours, per channel.
fn mean_difference(a: &[glam::Vec3], b: &[glam::Vec3]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).abs().element_sum() as f64)
        .sum();
    sum / (3 * a.len().max(1)) as f64
}

/// Soft shadows and occlusion draw the same sample points on both sides in every pass, not
/// only the first: stratified points carry the pass number (`PixelRng::points` in rng.rs,
/// `points_begin`/`points_next` in common.wgsl), independent ones the pass's stream. Glass
/// with soft shadows and occlusion, pass 5 on both backends: the GPU's pass is far nearer the
/// CPU's pass 5 than the CPU's pass 4 is (a kernel that drew pass 0's points, or the other
/// way's, would be as far as another pass).
#[test]
fn later_passes_draw_the_same_sample_points_on_both_backends() {
    use crate::geom::rng::Sampling;
    let (gpu, cpu) = (gpu(), CpuBackend::new(2).expect("pool"));
    let (scene, view) = setup(DemoScene::Glass);
    let effects = Effects {
        shadows: true,
        soft_shadows: true,
        ambient_occlusion: true,
        ..Effects::OFF
    };
    let plan = accumulator::plan_for(&scene, &effects);
    assert!(plan.soft_shadows && plan.ao_samples > 0, "{plan:?}");
    assert_eq!(plan.sampling, Sampling::Stratified, "the default");
    for sampling in [Sampling::Stratified, Sampling::Independent] {
        let plan = crate::EffectsPlan { sampling, ..plan };
        let g = gpu.trace_pass(&scene, &view, &plan, 5);
        assert_eq!(g.rays.device.passes, 1, "{sampling:?}: traced on the GPU");
        let c = cpu.trace_pass(&scene, &view, &plan, 5);
        let earlier = cpu.trace_pass(&scene, &view, &plan, 4);
        let same = mean_difference(&g.color, &c.color);
        let other = mean_difference(&earlier.color, &c.color);
        eprintln!("{sampling:?}: GPU against CPU pass 5 {same:.2e}, CPU pass 4 {other:.2e}");
        assert!(
            same * 8.0 < other,
            "{sampling:?}: the GPU's pass 5 is {same:.2e} from the CPU's, another pass {other:.2e}"
        );
    }
    assert!(!gpu.has_failed());
}
