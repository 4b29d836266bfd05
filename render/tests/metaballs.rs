//! The metaball engine against its `f64` reference and against itself.
//!
//! - `root_finders_agree_with_the_f64_reference`: every root finder (marching + bisection,
//!   projections + secant, Bézier clipping, sphere tracing), under brute force and under the
//!   sorted active list, and Bézier clipping under the BVH and the Fitted BVH, on seeded random
//!   rays through random scenes of every kernel, with negative strengths and rotated
//!   ellipsoids, compared with `f64` Bézier clipping at a `1e-9` tolerance.
//! - `accelerations_render_the_same_image_on_every_paper_scene`: brute force, active list,
//!   BVH with split metaballs and Fitted BVH give the same hit/miss per pixel and the same
//!   depth (within tolerance) on every scene of fitted-bvh-metaballs.txt's Table 1.
//!
//! How "agree" is decided, per ray (`T` the isovalue, `ε` the rounding budget of the `f32`
//! field, below). The `f64` reference gives `lo = t(T - ε)`, the first point where the field
//! reaches `T - ε`, and `u1 = t(T + ε)` with the end `u2` of that first stretch at or above
//! `T + ε`. Wherever the `f32` field is within `ε` of the exact one, a point where the `f32`
//! field reaches `T` lies at or after `lo`, and every point of `[u1, u2]` is one. So:
//! - if the field never reaches `T - ε`, the finder must miss;
//! - if the stretch `[u1, u2]` exists and the finder can resolve it, the finder must hit, at
//!   a distance in `[lo - tol, u1 + tol]` (`tol` its stated tolerance);
//! - otherwise the ray is *grazing*: it only touches the surface within the rounding budget,
//!   or it crosses a stretch inside the surface that the finder is documented to skip. A
//!   grazing ray may hit or miss, but a hit must still lie at or after `lo - tol`.
//!
//! What a finder can resolve: Bézier clipping any stretch; marching a stretch at least as long
//! as its largest step (a quarter of the largest smallest semi-axis); sphere tracing a stretch
//! at least as long as its tolerance; the secant method a stretch that holds a centre
//! projection where the exact field is at least `T + 2ε`.
//!
//! The rounding budget `ε`: the `f32` quadratic `s(t)` of a ball at distance `D` and smallest
//! semi-axis `r` is off by about `6·10⁻⁷ D / r` (a few ulps of `D`), and the kernel turns that
//! into at most `max|df/ds|` times as much field, so `ε = 10⁻⁶ max|df/ds| Σ |q_i| (D_i / r_i
//! + 1)` over the balls the ray crosses.
//!
//! Both tests print their figures with `eprintln!` (shown on failure, or with
//! `--nocapture`), and assert.

use glam::{Quat, Vec3};
use isoray_render::kinds::metaballs::reference::ReferenceRay;
use isoray_render::kinds::metaballs::{
    AccelKind, BuildOptions, Kernel, Metaball, MetaballScene, PrepareOptions, PreparedMetaballs,
    RootFinder, Shape,
};
use isoray_render::scenes::SplitMix64;
use isoray_render::Ray;
use std::collections::BTreeMap;

/// The tolerance every finder is run with, world units.
const TOLERANCE: f32 = 1e-4;
/// Far end of every ray.
const T_MAX: f32 = 1.0e4;

/// Balls of `kernel` in a 6-unit cube: a quarter carve (negative strength), a third are
/// rotated ellipsoids. Returns the scene and its isovalue.
fn random_scene(kernel: Kernel, seed: u64) -> (MetaballScene, f32) {
    let mut rng = SplitMix64(seed);
    let balls = (0..48)
        .map(|_| {
            let center = Vec3::new(
                rng.range(-3.0, 3.0),
                rng.range(-3.0, 3.0),
                rng.range(-3.0, 3.0),
            );
            let radius = rng.range(0.8, 1.6);
            let strength = if rng.next_f32() < 0.25 {
                rng.range(-1.0, -0.3)
            } else {
                rng.range(0.6, 1.4)
            };
            let shape = if rng.next_f32() < 0.35 {
                let axis = rng.in_unit_ball().normalize_or(Vec3::X);
                Shape::Ellipsoid {
                    axes: Vec3::new(1.0, rng.range(0.35, 1.0), rng.range(0.35, 1.0)),
                    rotation: Quat::from_axis_angle(axis, rng.range(0.0, std::f32::consts::TAU)),
                }
            } else {
                Shape::Sphere
            };
            let color = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            Metaball {
                center,
                radius,
                strength,
                color,
                shape,
            }
        })
        .collect();
    let isovalue = 0.35 * kernel.peak();
    let scene = MetaballScene {
        kernel,
        balls,
        min_isovalue: isovalue,
    };
    scene.validate(usize::MAX).expect("a valid random scene");
    (scene, isovalue)
}

/// Seeded rays: from a 14-unit sphere towards the cube, from inside the cube in any
/// direction, and from 150 units away (where `f32` distances lose digits).
fn random_rays(seed: u64, count: usize) -> Vec<Ray> {
    let mut rng = SplitMix64(seed);
    (0..count)
        .map(|i| {
            let target = Vec3::new(
                rng.range(-3.0, 3.0),
                rng.range(-3.0, 3.0),
                rng.range(-3.0, 3.0),
            );
            let unit = rng.in_unit_ball().normalize_or(Vec3::Y);
            match i % 4 {
                0 | 1 => Ray::new(14.0 * unit, target - 14.0 * unit),
                2 => Ray::new(
                    Vec3::new(
                        rng.range(-3.5, 3.5),
                        rng.range(-3.5, 3.5),
                        rng.range(-3.5, 3.5),
                    ),
                    rng.in_unit_ball().normalize_or(Vec3::Z),
                ),
                _ => Ray::new(150.0 * unit, target - 150.0 * unit),
            }
        })
        .collect()
}

/// Largest `|df/ds|` of the kernel on `[0, 1]`.
fn max_ds_slope(kernel: Kernel) -> f64 {
    (0..=1000)
        .map(|i| kernel.derivative(i as f32 / 1000.0).abs() as f64)
        .fold(0.0, f64::max)
}

/// What one variant may miss, besides rays within the rounding budget.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Resolves {
    Everything,
    /// Stretches at least this long.
    Longer(f64),
    /// Stretches holding a centre projection with the field at least `T + 2ε`.
    Projection,
}

struct Variant {
    name: String,
    options: PrepareOptions,
    resolves: Resolves,
}

fn variants(scene: &MetaballScene, isovalue: f32) -> Vec<Variant> {
    let largest_step = 0.25
        * scene
            .balls
            .iter()
            .map(|b| b.min_semi_axis())
            .fold(0.0f32, f32::max) as f64;
    let base = PrepareOptions {
        tolerance: TOLERANCE,
        ..PrepareOptions::fitted(isovalue)
    };
    let mut out = Vec::new();
    for (mode, accel) in [
        ("brute force", AccelKind::BruteForce),
        ("active list", AccelKind::ActiveList),
    ] {
        for finder in RootFinder::ALL {
            let resolves = match finder {
                RootFinder::BezierClipping => Resolves::Everything,
                RootFinder::March => Resolves::Longer(largest_step),
                RootFinder::SphereTracing => Resolves::Longer(TOLERANCE as f64),
                RootFinder::Secant => Resolves::Projection,
            };
            out.push(Variant {
                name: format!("{mode} / {}", finder.name()),
                options: base.with_accel(accel).with_finder(finder),
                resolves,
            });
        }
    }
    for (mode, opts) in [
        ("BVH", BuildOptions::bvh()),
        ("FBVH", BuildOptions::fitted(isovalue)),
        // Built for a higher isovalue than the query: the engine must fall back to a tree
        // without the isovalue-dependent §5.3 optimisations.
        ("FBVH for 2T", BuildOptions::fitted(2.0 * isovalue)),
    ] {
        out.push(Variant {
            name: format!("{mode} / {}", RootFinder::BezierClipping.name()),
            options: base
                .with_accel(AccelKind::Tree(opts))
                .with_finder(RootFinder::BezierClipping),
            resolves: Resolves::Everything,
        });
    }
    out
}

#[derive(Default)]
struct Tally {
    rays: usize,
    hits: usize,
    grazing: usize,
    /// Largest `|t - t_ref|` over rays that are not grazing.
    worst_error: f64,
    /// The same over well-conditioned rays (`t(T+ε) - t(T-ε) ≤ tol / 10`).
    worst_error_well_conditioned: f64,
    failures: Vec<String>,
}

#[test]
fn root_finders_agree_with_the_f64_reference() {
    let mut table: BTreeMap<(String, String), Tally> = BTreeMap::new();
    let tol = TOLERANCE as f64;
    for (k, kernel) in Kernel::ALL.into_iter().enumerate() {
        let (scene, isovalue) = random_scene(kernel, 0xB1_0B5 + k as u64);
        let t = isovalue as f64;
        let slope = max_ds_slope(kernel);
        let prepared: Vec<(Variant, PreparedMetaballs)> = variants(&scene, isovalue)
            .into_iter()
            .map(|v| {
                let p = PreparedMetaballs::new(scene.clone(), v.options);
                (v, p)
            })
            .collect();
        for ray in random_rays(0x5EED + k as u64, 400) {
            let origin = ray.origin.as_dvec3();
            let reference =
                ReferenceRay::new(&scene, origin, ray.dir.as_dvec3(), 0.0, T_MAX as f64);
            let eps = 1e-6
                * slope
                * reference
                    .crossed()
                    .map(|i| {
                        let b = &scene.balls[i as usize];
                        let d = (b.center.as_dvec3() - origin).length();
                        b.strength.abs() as f64 * (d / b.min_semi_axis() as f64 + 1.0)
                    })
                    .sum::<f64>();
            // The f32 ray's direction is renormalised in f64: a relative change of 1e-7.
            let slack = 1e-6;
            let t_ref = reference.first_at_least(t, 0.0);
            let lo = reference.first_at_least(t - eps, 0.0);
            let robust = reference.first_at_least(t + eps, 0.0).map(|u1| {
                let u2 = reference.first_below(t + eps, u1 + 1e-7);
                (u1, u2)
            });
            for (variant, engine) in &prepared {
                let tally = table
                    .entry((kernel_name(kernel), variant.name.clone()))
                    .or_default();
                tally.rays += 1;
                let got = engine
                    .first_hit(&ray, 0.0, T_MAX, isovalue)
                    .map(|h| h.t as f64);
                tally.hits += got.is_some() as usize;
                let resolvable = robust.is_some_and(|(u1, u2)| match variant.resolves {
                    Resolves::Everything => true,
                    Resolves::Longer(len) => u2 - u1 >= len + 1e-6,
                    Resolves::Projection => reference
                        .projections()
                        .any(|p| u1 <= p && p <= u2 && reference.field(p) >= t + 2.0 * eps),
                });
                let describe = || {
                    format!(
                        "{} {}: ray {:?} → {:?}; reference t(T)={t_ref:?} t(T-ε)={lo:?} \
                         stretch at T+ε {robust:?}, ε={eps:.2e}",
                        kernel_name(kernel),
                        variant.name,
                        ray,
                        got
                    )
                };
                match (lo, got) {
                    (None, None) => {}
                    (None, Some(_)) => tally.failures.push(format!("false hit: {}", describe())),
                    (Some(lo), got) => {
                        if let Some(g) = got {
                            if g < lo - tol - slack {
                                tally
                                    .failures
                                    .push(format!("hit before the surface: {}", describe()));
                            }
                        }
                        match (resolvable, robust, got) {
                            (true, Some((u1, _)), Some(g)) => {
                                if g > u1 + tol + slack {
                                    tally.failures.push(format!("hit too far: {}", describe()));
                                }
                                let err = (g - t_ref.unwrap_or(lo)).abs();
                                tally.worst_error = tally.worst_error.max(err);
                                if u1 - lo <= tol / 10.0 {
                                    tally.worst_error_well_conditioned =
                                        tally.worst_error_well_conditioned.max(err);
                                }
                            }
                            (true, _, None) => {
                                tally.failures.push(format!("missed: {}", describe()))
                            }
                            _ => tally.grazing += 1,
                        }
                    }
                }
            }
        }
    }
    eprintln!("Root finders against the f64 reference (tolerance {TOLERANCE:e}):");
    eprintln!(
        "{:<10} {:<36} {:>5} {:>5} {:>7} {:>12} {:>12} {:>8}",
        "kernel", "variant", "rays", "hits", "grazing", "worst |Δt|", "well-cond.", "failures"
    );
    let mut failures = Vec::new();
    for ((kernel, variant), t) in &table {
        eprintln!(
            "{kernel:<10} {variant:<36} {:>5} {:>5} {:>7} {:>12.3e} {:>12.3e} {:>8}",
            t.rays,
            t.hits,
            t.grazing,
            t.worst_error,
            t.worst_error_well_conditioned,
            t.failures.len()
        );
        failures.extend(t.failures.iter().take(3).cloned());
        assert!(t.hits > 0, "{kernel} {variant}: no ray hit anything");
        assert!(
            t.grazing * 10 < t.rays,
            "{kernel} {variant}: {} of {} rays grazing",
            t.grazing,
            t.rays
        );
    }
    assert!(
        failures.is_empty(),
        "disagreements:\n{}",
        failures.join("\n")
    );
}

fn kernel_name(kernel: Kernel) -> String {
    match kernel {
        Kernel::Wyvill => "wyvill".into(),
        Kernel::Quartic => "quartic".into(),
        Kernel::Power { alpha } => format!("power-{alpha}"),
        Kernel::Tutorial => "tutorial".into(),
    }
}

/// Whether a disagreement between two answers on one ray is explained by the ray grazing the
/// surface: both answers lie where the `f32` field may round either way (see the module doc).
fn explained_by_grazing(
    scene: &MetaballScene,
    ray: &Ray,
    isovalue: f32,
    answers: [Option<f32>; 2],
) -> bool {
    let origin = ray.origin.as_dvec3();
    let reference = ReferenceRay::new(scene, origin, ray.dir.as_dvec3(), 0.0, T_MAX as f64);
    let eps = 1e-6
        * max_ds_slope(scene.kernel)
        * reference
            .crossed()
            .map(|i| {
                let b = &scene.balls[i as usize];
                let d = (b.center.as_dvec3() - origin).length();
                b.strength.abs() as f64 * (d / b.min_semi_axis() as f64 + 1.0)
            })
            .sum::<f64>();
    let t = isovalue as f64;
    let tol = TOLERANCE as f64 + 1e-6;
    let lo = reference.first_at_least(t - eps, 0.0);
    let hi = reference.first_at_least(t + eps, 0.0);
    answers.iter().all(|a| match (a, lo, hi) {
        (None, _, None) => true,
        (Some(a), Some(lo), hi) => {
            let a = *a as f64;
            a >= lo - tol && hi.is_none_or(|hi| a <= hi + tol)
        }
        _ => false,
    })
}

#[test]
fn accelerations_render_the_same_image_on_every_paper_scene() {
    use isoray_render::scene::Geometry;
    use isoray_render::scenes::DemoScene;
    let (width, height) = (48u32, 36u32);
    eprintln!("Acceleration modes against the FBVH, {width}×{height}, Bézier clipping:");
    let mut problems = Vec::new();
    for demo in DemoScene::PAPER {
        let Geometry::Metaballs(scene) = demo.state_at(1.0).geometry else {
            panic!("{demo:?} is a metaball scene");
        };
        let isovalue = demo.default_isovalue();
        let floor = demo.isovalue_slider().0;
        let rays = demo.default_camera().rays(width, height);
        let pixels: Vec<(u32, u32)> = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .collect();
        // O(N)-per-ray modes see every pixel on the small scenes, a quarter on the big ones.
        let stride = if scene.balls.len() > 20_000 { 4 } else { 1 };
        let base = PrepareOptions {
            tolerance: TOLERANCE,
            ..PrepareOptions::fitted(floor)
        };
        let fbvh = PreparedMetaballs::new(scene.clone(), base);
        let depth = |engine: &PreparedMetaballs, step: usize| -> Vec<Option<f32>> {
            pixels
                .iter()
                .step_by(step)
                .map(|&(x, y)| {
                    let ray = rays.through_pixel(x, y);
                    engine.first_hit(&ray, 0.0, T_MAX, isovalue).map(|h| h.t)
                })
                .collect()
        };
        let reference = depth(&fbvh, 1);
        let hits = reference.iter().filter(|d| d.is_some()).count();
        assert!(
            hits > pixels.len() / 20 && hits < pixels.len(),
            "{}: the default camera sees the surface and some background ({hits} hits)",
            demo.id()
        );
        for (name, accel, step) in [
            ("BVH", AccelKind::Tree(BuildOptions::bvh()), 1),
            ("active list", AccelKind::ActiveList, stride),
            ("brute force", AccelKind::BruteForce, stride),
        ] {
            let engine = PreparedMetaballs::new(scene.clone(), base.with_accel(accel));
            let got = depth(&engine, step);
            let (mut same, mut grazing, mut worst) = (0usize, 0usize, 0.0f32);
            for (k, (&a, &b)) in got.iter().zip(reference.iter().step_by(step)).enumerate() {
                let agree = match (a, b) {
                    (None, None) => true,
                    (Some(a), Some(b)) => {
                        worst = worst.max((a - b).abs());
                        (a - b).abs() <= 2.0 * TOLERANCE
                    }
                    _ => false,
                };
                if agree {
                    same += 1;
                    continue;
                }
                let (x, y) = pixels[k * step];
                let ray = rays.through_pixel(x, y);
                if explained_by_grazing(&scene, &ray, isovalue, [a, b]) {
                    grazing += 1;
                } else {
                    problems.push(format!(
                        "{} {name}: pixel ({x}, {y}) gives {a:?}, the FBVH {b:?}",
                        demo.id()
                    ));
                }
            }
            eprintln!(
                "{:>15} {name:<12} {:>5} pixels: {same} agree, {grazing} grazing, worst |Δt| {worst:.2e}",
                demo.id(),
                got.len()
            );
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn extreme_but_finite_balls_render_without_panicking() {
    // Values validation lets through (finite, positive radius) but that push f32 to its
    // limits: every mode and finder must answer without panicking or hanging.
    let extremes = [
        Metaball::sphere(Vec3::splat(1e30), 1.0, 1.0, Vec3::ONE),
        Metaball::sphere(Vec3::ZERO, 1e-30, 1.0, Vec3::ONE),
        Metaball::sphere(Vec3::new(0.5, 0.0, 0.0), 1e30, 1e-30, Vec3::ONE),
        Metaball::sphere(Vec3::new(-1e-7, 0.0, 0.0), 0.7, 1e30, Vec3::ONE),
        Metaball::sphere(Vec3::new(0.0, 1e-7, 0.0), 0.7, -1e30, Vec3::ONE),
        Metaball::sphere(Vec3::new(0.2, 0.1, 0.0), 1.0, 1.0, Vec3::ONE),
        Metaball::sphere(Vec3::new(0.2, 0.1, 0.0), 1.0, 1.0, Vec3::ONE),
    ];
    let scene = MetaballScene::new(Kernel::Wyvill, extremes.to_vec());
    scene.validate(100).expect("finite and positive: valid");
    for accel in [
        AccelKind::BruteForce,
        AccelKind::ActiveList,
        AccelKind::Tree(BuildOptions::bvh()),
        AccelKind::Tree(BuildOptions::fitted(0.5)),
    ] {
        for finder in RootFinder::ALL {
            let options = PrepareOptions::fitted(0.5)
                .with_accel(accel)
                .with_finder(finder);
            let engine = PreparedMetaballs::new(scene.clone(), options);
            for ray in random_rays(7, 64) {
                let _ = engine.first_hit(&ray, 0.0, T_MAX, 0.5);
            }
        }
    }
}

/// A search that stops at its iteration cap is counted (issue 13: a capped search is a
/// possible wrong pixel, reported rather than silent); an ordinary one is not.
#[test]
fn searches_that_hit_the_iteration_cap_are_counted() {
    let scene = MetaballScene::new(
        Kernel::Wyvill,
        vec![Metaball::sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE)],
    );
    let ray = Ray::new(Vec3::new(0.0, 0.0, 3.0), Vec3::new(0.0, 0.0, -1.0));
    let run = |step: f32| {
        let options = PrepareOptions {
            step,
            ..PrepareOptions::fitted(0.5)
                .with_accel(AccelKind::BruteForce)
                .with_finder(RootFinder::March)
        };
        let engine = PreparedMetaballs::new(scene.clone(), options);
        let mut counters = isoray_render::kinds::metaballs::RayCounters::default();
        let hit = engine.first_hit_counted(&ray, 0.0, T_MAX, 0.5, &mut counters);
        (hit.map(|h| h.t), counters.capped)
    };
    // Steps of 1e-6 radii: 1.3 million steps to the surface, past the cap of 20,000.
    let (hit, capped) = run(1e-6);
    assert_eq!((hit, capped), (None, 1), "a capped march is a counted miss");
    // The default step reaches the surface uncapped, where the reference does.
    let (hit, capped) = run(RootFinder::March.default_step());
    assert_eq!(capped, 0);
    let t = hit.expect("the default step hits");
    let exact = ReferenceRay::new(
        &scene,
        glam::DVec3::new(0.0, 0.0, 3.0),
        glam::DVec3::new(0.0, 0.0, -1.0),
        0.0,
        10.0,
    )
    .first_at_least(0.5, 0.0)
    .expect("the reference hits");
    assert!((t as f64 - exact).abs() < 1e-3, "t {t} against {exact}");
}

/// `refine_f64` turns a coarse `f32` hit (tolerance 1e-2) into one within `f32` rounding of
/// the reference, for every finder.
#[test]
fn f64_refinement_narrows_a_coarse_hit_to_rounding() {
    let (scene, isovalue) = random_scene(Kernel::Wyvill, 11);
    let mut worst = [0.0f64; 2];
    for finder in RootFinder::ALL {
        for (slot, refine_f64) in [false, true].into_iter().enumerate() {
            let options = PrepareOptions {
                tolerance: 1e-2,
                refine_f64,
                ..PrepareOptions::fitted(isovalue)
                    .with_accel(AccelKind::BruteForce)
                    .with_finder(finder)
            };
            let engine = PreparedMetaballs::new(scene.clone(), options);
            for ray in random_rays(5, 200) {
                let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
                let reference = ReferenceRay::new(&scene, o, d, 0.0, T_MAX as f64);
                let (Some(hit), Some(t)) = (
                    engine.first_hit(&ray, 0.0, T_MAX, isovalue),
                    reference.first_at_least(isovalue as f64, 0.0),
                ) else {
                    continue;
                };
                // Only rays whose first root is simple and the same one both find.
                if (hit.t as f64 - t).abs() < 0.05 {
                    worst[slot] = worst[slot].max((hit.t as f64 - t).abs());
                }
            }
        }
    }
    eprintln!(
        "worst |Δt| at tolerance 1e-2: f32 {:.1e}, refined in f64 {:.1e}",
        worst[0], worst[1]
    );
    assert!(worst[0] > 1e-3, "the coarse tolerance shows: {worst:?}");
    assert!(
        worst[1] < 1e-4,
        "refined hits are within rounding: {worst:?}"
    );
}

/// Where Debian's `pymol-data` keeps its PDB files (`bash .ci/run` installs the package).
const PYMOL_DATA: &str = "/usr/share/pymol/data";

#[test]
fn real_molecules_from_pymol_data_load_and_render_like_brute_force() {
    use isoray_render::kinds::metaballs::pdb::{
        molecule_scene, read_models, Element, MoleculeOptions,
    };
    use isoray_render::Camera;
    // HIV-1 protease with an inhibitor (old format: serial numbers where newer files keep the
    // element), and a larger complex with element columns.
    for file in ["tut/1hpv.pdb", "demo/1tii.pdb"] {
        let path = std::path::Path::new(PYMOL_DATA).join(file);
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
            panic!(
                "{}: {e}; install Debian's pymol-data (bash .ci/run does)",
                path.display()
            )
        });
        // The atom records that are not water (these files carry no hydrogens), counted
        // from the text's columns.
        let records = text
            .lines()
            .take_while(|l| !l.starts_with("ENDMDL"))
            .filter(|l| l.starts_with("ATOM") || l.starts_with("HETATM"))
            .filter(|l| l.get(17..20) != Some("HOH"))
            .count();
        let models = read_models(&path, MoleculeOptions::default()).expect("a real PDB file reads");
        let atoms = &models[0];
        assert_eq!(atoms.len(), records, "{file}: one ball per atom record");
        if file == "demo/1tii.pdb" {
            // The Molecule demo shows this structure when pymol-data is installed.
            let demo = isoray_render::scenes::DemoScene::Molecule;
            assert_eq!(demo.ball_count(), records, "the Molecule demo is 1TII");
        }
        assert!(atoms.len() > 1000, "{file}: {} atoms", atoms.len());
        // Proteins are carbon, nitrogen, oxygen and sulphur, told apart by their colours.
        let is = |r: &[f32; 8], e: Element| {
            let c = e.cpk_color();
            r[5..8] == [c.x, c.y, c.z] && (r[3] - 2.0 * e.van_der_waals_radius()).abs() < 1e-6
        };
        let organic = atoms
            .iter()
            .filter(|r| {
                [Element::C, Element::N, Element::O, Element::S]
                    .iter()
                    .any(|&e| is(r, e))
            })
            .count();
        let carbon = atoms.iter().filter(|r| is(r, Element::C)).count();
        assert!(
            organic * 100 >= atoms.len() * 98,
            "{file}: {organic} of {}",
            atoms.len()
        );
        assert!(
            carbon * 2 > atoms.len(),
            "{file}: carbon is the majority ({carbon})"
        );
        let scene = molecule_scene(atoms);
        scene.validate(usize::MAX).expect("valid balls");
        let (lo, hi) = scene.bounds().expect("atoms");
        let center = 0.5 * (lo + hi);
        let radius = 0.5 * (hi - lo).length();
        let camera = Camera {
            eye: center + Vec3::new(0.3, 0.4, 1.7) * radius,
            target: center,
            up: Vec3::Y,
            fov_y_deg: 40.0,
        };
        let rays = camera.rays(40, 30);
        let isovalue = 0.5;
        let fbvh = PreparedMetaballs::new(
            scene.clone(),
            PrepareOptions {
                tolerance: TOLERANCE,
                ..PrepareOptions::fitted(0.25)
            },
        );
        let brute = PreparedMetaballs::new(
            scene.clone(),
            PrepareOptions {
                tolerance: TOLERANCE,
                ..PrepareOptions::fitted(0.25)
            }
            .with_accel(AccelKind::BruteForce),
        );
        let mut hits = 0;
        for y in 0..30 {
            for x in 0..40 {
                let ray = rays.through_pixel(x, y);
                let a = fbvh.first_hit(&ray, 0.0, T_MAX, isovalue).map(|h| h.t);
                let b = brute.first_hit(&ray, 0.0, T_MAX, isovalue).map(|h| h.t);
                hits += a.is_some() as usize;
                let agree = match (a, b) {
                    (Some(a), Some(b)) => (a - b).abs() <= 2.0 * TOLERANCE,
                    (None, None) => true,
                    _ => false,
                };
                assert!(
                    agree || explained_by_grazing(&scene, &ray, isovalue, [a, b]),
                    "{file} pixel ({x}, {y}): FBVH {a:?}, brute force {b:?}"
                );
            }
        }
        eprintln!("{file}: {} atoms, {hits} of 1200 pixels hit", atoms.len());
        assert!(
            hits > 200 && hits < 1200,
            "{file}: the molecule fills part of the view ({hits})"
        );
    }
}

#[test]
fn a_frame_below_the_isovalue_floor_builds_the_fallback_tree_while_tiles_wait() {
    // The first query under the FBVH's floor builds the relaxed tree inside a `OnceLock` the
    // other tile threads wait on; the build must not fork onto those threads (a forked thread
    // could pick up a waiting tile and wait on itself). Tornado 4k is big enough that a
    // forking build would fork.
    use isoray_render::scenes::DemoScene;
    use isoray_render::{CpuBackend, View};
    use std::sync::Arc;
    let demo = DemoScene::Tornado4k;
    let view = View {
        width: 64,
        height: 48,
        camera: demo.default_camera(),
        isovalue: 0.6 * demo.isovalue_slider().0,
    };
    let backend = CpuBackend::new(2).expect("pool");
    for time in [1.0, 2.0, 3.0] {
        let prepared = Arc::new(demo.state_at(time)).prepare();
        let frame = backend.render(&prepared, &view);
        assert!(frame.hit_count() > 0, "the surface below the floor is seen");
    }
}
