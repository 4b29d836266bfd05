//! The GPU's metaball root finders against the CPU's, on lavapipe (issue 12: "Bézier clipping,
//! with the secant method as the alternative"): demo states prepared with each finder, traced
//! by both backends at 96×72 (the secant method also at the paper's infinite step, whose
//! grazing misses both sides must share), with ray casting and with the clip box and shadows
//! (rays that start inside the solid at the box's face, and shadow rays' any-hit queries).
//! Each frame must be the GPU's, hit or miss the same on every pixel, and each depth within
//! [`depth_tolerance`] of the CPU's. Sphere tracing, which the kernel does not have, is
//! marched on the GPU and held to marching's tolerance. The tet kernel's isopolygon test is
//! checked here too, on a sliver that rounding once let rays through.

use crate::backend::accumulator;
use crate::backend::cpu::CpuBackend;
use crate::backend::gpu::agreement_tests::gpu;
use crate::backend::gpu::backend::GpuBackend;
use crate::effects::toggles::Effects;
use crate::framebuffer::Framebuffer;
use crate::kinds::metaballs::engine::PrepareOptions;
use crate::kinds::metaballs::roots::RootFinder;
use crate::scene::PreparedScene;
use crate::scenes::DemoScene;
use crate::view::View;
use std::sync::Arc;

/// Largest depth difference allowed, world units: each side stops within the states' root
/// tolerance (1e-4, `PrepareOptions::fitted`) of the same root, so twice that; Bézier clipping
/// on both sides clips the same polynomial to the same stopping point, so a fifth of the
/// tolerance covers the rounding (a GPU that marched instead would be off by up to 1e-4).
fn depth_tolerance(finder: RootFinder) -> f32 {
    match finder {
        RootFinder::BezierClipping => 2e-5,
        RootFinder::March | RootFinder::Secant | RootFinder::SphereTracing => 2e-4,
    }
}

/// Pixels whose hit differs, and the largest depth difference over the others.
fn depth_difference(cpu: &Framebuffer, gpu: &Framebuffer) -> (usize, usize, f32) {
    let (mut hits, mut mismatch, mut largest) = (0, 0, 0.0f32);
    for (c, g) in cpu.depth.iter().zip(&gpu.depth) {
        match (c.is_finite(), g.is_finite()) {
            (true, true) => {
                hits += 1;
                largest = largest.max((c - g).abs());
            }
            (false, false) => {}
            (true, false) | (false, true) => mismatch += 1,
        }
    }
    (hits, mismatch, largest)
}

#[test]
fn each_gpu_finder_finds_the_cpu_finders_depths() {
    let gpu = gpu();
    let cpu = CpuBackend::new(2).expect("pool");
    let clipped = Effects {
        clip_box: true,
        shadows: true,
        ..Effects::OFF
    };
    for demo in [DemoScene::Blobs, DemoScene::Shells] {
        let state = Arc::new(demo.state_at(1.0));
        let view = demo.default_view(96, 72);
        // Every finder at its default step, and the secant method at the paper's (centre
        // projections only: an infinite step, which the kernel gets as 0).
        let steps = RootFinder::ALL
            .map(|f| (f, f.default_step()))
            .into_iter()
            .chain([(RootFinder::Secant, f32::INFINITY)]);
        for (finder, step) in steps {
            let options = PrepareOptions {
                step,
                ..state
                    .geometry
                    .default_metaball_options()
                    .with_finder(finder)
            };
            let scene = Arc::clone(&state).prepare_with(options);
            for (name, effects) in [("ray casting", Effects::OFF), ("clip box", clipped)] {
                let what = format!(
                    "{} by {} (step {step}) with {name}",
                    demo.name(),
                    finder.name()
                );
                let before = gpu.frames();
                let (g, _) = accumulator::render_effects(&gpu, &scene, &view, &effects);
                assert_eq!(
                    gpu.frames(),
                    (before.0 + 1, before.1),
                    "{what}: the GPU traced the frame"
                );
                let (c, _) = accumulator::render_effects(&cpu, &scene, &view, &effects);
                let (hits, mismatch, largest) = depth_difference(&c, &g);
                eprintln!(
                    "{what}: {hits} hits, {mismatch} differ in hit/miss, depth within {largest:e}"
                );
                assert!(hits > 96 * 72 / 50, "{what}: the view sees the surface");
                assert_eq!(mismatch, 0, "{what}: the same hit or miss on every pixel");
                assert!(
                    largest <= depth_tolerance(finder),
                    "{what}: depths differ by {largest:e}"
                );
            }
        }
    }
    assert!(!gpu.has_failed());
}

/// Bézier clipping took a hull meeting the axis on a stretch narrower than the tolerance for a
/// root, on both backends: three pixels of the `blobs` demo at 10.24 s (its camera, 1148×812)
/// showed a surface 0.6–2.7 units in front of the true one, where the field peaks at 0.46–0.49
/// against 0.5. Each ray is a one-pixel view along it here; both backends must find the `f64`
/// reference's first crossing (an exact polynomial per section, an interval search).
#[test]
fn no_backend_takes_a_sliver_of_the_hull_for_a_root() {
    use crate::kinds::dispatch::Geometry;
    use crate::kinds::metaballs::reference::reference_hit;
    let gpu = gpu();
    let cpu = CpuBackend::new(1).expect("pool");
    let state = Arc::new(DemoScene::Blobs.state_at(10.24));
    let Geometry::Metaballs(balls) = &state.geometry else {
        panic!("blobs is a metaball scene");
    };
    let scene = Arc::clone(&state).prepare();
    let mut view = DemoScene::Blobs.default_view(1, 1);
    let isovalue = view.isovalue as f64;
    let eye = glam::Vec3::new(0.0, 1.5, 7.5);
    for dir in [
        glam::Vec3::new(0.038046964, -0.0990249, -0.99435735),
        glam::Vec3::new(-0.12998717, -0.19593987, -0.97196233),
        glam::Vec3::new(-0.03210617, -0.22541009, -0.97373486),
    ] {
        view.camera.eye = eye;
        view.camera.target = eye + dir * 7.0;
        let truth = reference_hit(balls, eye.as_dvec3(), dir.as_dvec3(), 0.0, 100.0, isovalue)
            .expect("the ray meets the surface");
        for (name, depth) in one_pixel_depths(&gpu, &cpu, &scene, &view) {
            assert!(
                (depth - truth).abs() < 1e-3,
                "{name} along {dir}: depth {depth}, the reference's crossing {truth}"
            );
        }
    }
}

/// The depth of a one-pixel view (ray casting) on each backend, named.
fn one_pixel_depths(
    gpu: &GpuBackend,
    cpu: &CpuBackend,
    scene: &PreparedScene,
    view: &View,
) -> [(&'static str, f64); 2] {
    let depth = |frame: Framebuffer| frame.depth[0] as f64;
    [
        (
            "GPU",
            depth(accumulator::render_effects(gpu, scene, view, &Effects::OFF).0),
        ),
        (
            "CPU",
            depth(accumulator::render_effects(cpu, scene, view, &Effects::OFF).0),
        ),
    ]
}

/// The tet kernel's isopolygon test on a sliver: a triangle 5·10⁻⁵ across (a corner 2·10⁻⁴
/// below the isovalue) 5.5 from the eye. Edge planes formed from the points' offsets from the
/// eye carried the rounding of those offsets, turned about the line of sight by about 1%,
/// and two of them let through a ray passing 0.035 off the triangle: the gyroid demo at 23.3 s
/// showed it at pixel (171, 85) of 320×240, 0.019 in front of the surface (march.rs
/// `edge_plane`). A one-pixel view along that ray on both backends must find the brute-force
/// `f64` reference's hit.
#[test]
fn no_backend_hits_a_tet_sliver_the_ray_passes_by() {
    use crate::kinds::dispatch::Geometry;
    use crate::kinds::tets::reference::reference_hit;
    let gpu = gpu();
    let cpu = CpuBackend::new(1).expect("pool");
    let demo = DemoScene::TetGyroid;
    let state = Arc::new(demo.state_at(23.3));
    let Geometry::Tets(step) = &state.geometry else {
        panic!("the gyroid is a tet scene");
    };
    let scene = Arc::clone(&state).prepare();
    let mut view = demo.default_view(1, 1);
    let eye = glam::Vec3::new(3.0, 2.2, 5.2);
    let dir = glam::Vec3::new(-0.4542334, -0.24435239, -0.8567168);
    view.camera.eye = eye;
    view.camera.target = eye + dir * 5.0;
    let (truth, _) = reference_hit(
        step.positions(),
        step.scalars(),
        step.mesh().tets(),
        eye.as_dvec3(),
        dir.as_dvec3(),
        0.0,
        100.0,
        view.isovalue as f64,
    )
    .expect("the ray meets the surface");
    for (name, depth) in one_pixel_depths(&gpu, &cpu, &scene, &view) {
        assert!(
            (depth - truth).abs() < 1e-4,
            "{name}: depth {depth}, the reference's hit {truth}"
        );
    }
}
