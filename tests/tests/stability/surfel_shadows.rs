//! Shadow rays on the surfel demos as a viewer sees them (320×240): every shadow ray the
//! renderer casts from a hit facing the light ([`shadow_rays`]: the surfels' surface and the
//! floor), answered as the renderer answers it (`integrator::trace_shadows`: packets towards
//! one light) and by the `f64` MLS reference over every surfel of each body
//! ([`surface_trace`]), not the engine's tree, neighbourhoods or iteration. Mirror rays,
//! which start the same way, are checked against the same answers.

use super::shadow_rays;
use super::surfel_demos::{demo_case, demo_surfels, surface_trace, MlsGroups, Surfaces};
use super::surfels::coherence;
use glam::DVec3;
use isoray_render::effects::{Effects, EffectsPlan};
use isoray_render::geom::rng::PixelRng;
use isoray_render::integrator::trace_shadows;
use isoray_render::integrator::{reflect, Tracer, T_MAX};
use isoray_render::kinds::counters::SceneCounters;
use isoray_render::kinds::surfels::demo::{self, SurfelDemo, SurfelDemoKind};
use isoray_render::kinds::surfels::reference::MlsSurfel;
use isoray_render::ray::surface_offset;
use isoray_render::scenes::DemoScene;
use isoray_render::{Camera, PreparedScene, Ray};
use std::sync::Arc;

const SIZE: (u32, u32) = (320, 240);

/// How one shadow ray came out.
#[derive(Default, Debug)]
struct Tally {
    /// Rays the reference blocks robustly, and those of them the engine let through.
    must_block: usize,
    leaks: Vec<String>,
    /// Rays the reference lets through by a margin, and those of them the engine blocked.
    must_pass: usize,
    blocked: Vec<String>,
    /// How many of the rays start on the floor.
    from_floor: usize,
}

/// What the reference says of a shadow ray from `o` along `d` (unit), beyond `from`: `Some
/// (true)` where it crosses a surface robustly (not grazing, the normals there agreeing),
/// `Some(false)` where it never runs within `near` of a surface on a disc, else `None`.
fn shadow_answer(
    groups: &MlsGroups,
    surfaces: &Surfaces,
    (o, d): (DVec3, DVec3),
    from: f64,
    (near, margin): (f64, f64),
) -> Option<bool> {
    let ids = groups.crossing_ids(o, d);
    let (best, near_from, own) = surface_trace(
        &groups.surfels,
        &ids,
        surfaces,
        ((o, d), (from, 1e4)),
        (near, margin),
    );
    let all: Vec<MlsSurfel> = ids.iter().map(|&k| groups.surfels[k as usize]).collect();
    match best {
        Some((t, normal, surface))
            if normal.dot(d) < -0.3
                && coherence(&own[&surface], o + t * d) >= 0.9
                && coherence(&all, o + t * d) >= 0.9 =>
        {
            Some(true)
        }
        None if near_from.is_none() => Some(false),
        Some(_) | None => None,
    }
}

/// The shadow rays of step `step` of `demo` (surfaces as `surfaces`, `near` as in
/// `surfel_demos::demo_answer`) against the reference.
fn check_step(
    kind: SurfelDemoKind,
    demo: &SurfelDemo,
    step: usize,
    surfaces: &Surfaces,
    (near, margin): (f64, f64),
) -> Tally {
    let mut case = demo_case(kind, demo, step, (0.0, 0.0));
    // Lit as served: the ball pit and the cubes stand on a floor.
    let served = DemoScene::SURFELS
        .into_iter()
        .find(|d| d.surfel_kind() == Some(kind));
    case.scene.lighting = served.expect("a surfel demo").lighting();
    let prepared = Arc::new(case.scene.clone()).prepare();
    let frame = *prepared.frame();
    let (u, g) = &demo.steps[step];
    let groups = MlsGroups::new(demo_surfels(&demo.model, u, g));
    let shadows = shadow_rays(&prepared, &case.camera, SIZE, 0.0);
    let queries: Vec<_> = shadows.iter().map(|s| s.query).collect();
    let mut c = SceneCounters::default();
    let blocked = trace_shadows(&prepared, 0.0, &queries, &mut c);
    let mut tally = Tally::default();
    for (shadow, &got) in shadows.iter().zip(&blocked) {
        let (ray, cos) = (shadow.query.ray, shadow.cos);
        // The engine's surface lies within `near` of the reference's: beyond `from`, a ray
        // leaving it at `cos` is clear of both. The floor is the same plane for both.
        let from = match shadow.on_floor {
            true => 0.0,
            false => 4.0 * near / (cos as f64).max(0.1),
        };
        let (o, d) = (frame.world_from_local(ray.origin), ray.dir.as_dvec3());
        tally.from_floor += shadow.on_floor as usize;
        // Where the engine's any-hit query stops, and the body of the surfel nearest its start
        // and that point (with the distance in its support radii): for the failure message.
        let what = || {
            let at = prepared.any_hit_counted(&ray, 0.0, shadow.query.t_max, 0.0, &mut c.clone());
            let body_at = |x: DVec3| {
                let near_by = |k: &usize| groups.surfels[*k].centre.distance(x);
                let k = (0..groups.surfels.len())
                    .min_by(|a, b| near_by(a).total_cmp(&near_by(b)))
                    .unwrap_or(0);
                (surfaces.of[k], near_by(&k) / groups.surfels[k].support)
            };
            let x = at.map(|t| body_at(o + t as f64 * d));
            format!(
                "pixel {:?} (floor: {}) cos {cos:.3} from {from:.3} start {:?}: blocked {got}, \
                 any hit {at:?} at {x:?}",
                shadow.pixel,
                shadow.on_floor,
                body_at(o)
            )
        };
        match shadow_answer(&groups, surfaces, (o, d), from, (near, margin)) {
            Some(true) => {
                tally.must_block += 1;
                if !got {
                    tally.leaks.push(what());
                }
            }
            Some(false) => {
                tally.must_pass += 1;
                if got {
                    tally.blocked.push(what());
                }
            }
            None => {}
        }
    }
    eprintln!(
        "{} step {step}: {} shadow rays ({} from the floor), {} must block, {} leak; {} must \
         pass, {} blocked",
        kind.name(),
        shadows.len(),
        tally.from_floor,
        tally.must_block,
        tally.leaks.len(),
        tally.must_pass,
        tally.blocked.len(),
    );
    tally
}

#[test]
fn the_surfel_demos_shadow_and_mirror_rays() {
    // Per demo: its detail as served, `near` as the camera suite's, and steps with the most
    // shadow rays the reference lets through (by a margin) that the engine may block, and
    // the most mirror rays (from camera hits met from outside) the reference clears that the
    // engine may bring to a surface. None in the frames the camera suite checks; a few in the
    // strike's and the landing's frames, where bodies press together and the two definitions
    // of the surface part (see `surfel_demos`). Shadow rays: measured 1 at the impact's step
    // 6, 16 and 1 at the ball pit's steps 18 and 42 (one of the 16 from the floor; 315 and 91
    // before `OUTWARD`, and 34 at step 60, 12 at the impact's step 6). Mirror rays: 1 at the
    // impact's step 6, 10, 1 and 1 at the ball pit's steps 18, 60 and 120 (asked as camera
    // rays, with `first_hit`: 23 at the impact's step 6, 484, 67 and 9 at the ball pit's 18,
    // 42 and 60).
    // The clipped cubes are traced face by face, cut as the camera suite cuts them. No
    // shadow ray the reference blocks may get through, and no mirror ray it sends into a
    // surface may miss. About 480,000 shadow rays, 400,000 of them from the floors of the
    // ball pit and the cubes.
    let mut must_hit = 0;
    for (kind, detail, near, steps) in [
        (
            SurfelDemoKind::Impact,
            1.0f32,
            2e-3,
            &[(6usize, 3usize, 3usize), (60, 0, 0), (210, 0, 0)][..],
        ),
        (
            SurfelDemoKind::Balls,
            0.1,
            5e-3,
            &[(0, 0, 0), (18, 20, 12), (42, 4, 2), (60, 0, 2), (120, 0, 2)],
        ),
        (
            SurfelDemoKind::Heads,
            0.05,
            2e-3,
            &[(90, 0, 0), (150, 0, 0)],
        ),
    ] {
        let last = steps.iter().map(|s| s.0).max().unwrap_or(0);
        let demo = demo::build(kind, detail, last + 1).expect("a demo");
        let (surfaces, margin) = match kind {
            SurfelDemoKind::Heads => {
                let mut supports = demo.model.support.clone();
                supports.sort_by(f32::total_cmp);
                let margin = 0.5 * supports[supports.len() / 2] as f64;
                (Surfaces::groups(&demo.model), margin)
            }
            SurfelDemoKind::Impact | SurfelDemoKind::Balls => (Surfaces::bodies(&demo.model), 0.0),
        };
        let name = kind.name();
        let mut must_block = 0;
        for &(step, most, most_mirrors) in steps {
            let t = check_step(kind, &demo, step, &surfaces, (near, margin));
            assert!(
                t.leaks.is_empty(),
                "{name} step {step} leaks: {:#?}",
                t.leaks
            );
            assert!(
                t.blocked.len() <= most,
                "{name} step {step}: {} blocked (at most {most}): {:#?}",
                t.blocked.len(),
                t.blocked
            );
            assert!(t.must_pass > 5000, "{name} step {step}: {t:?}");
            must_block += t.must_block;
            let (n, hit, missed, clear, wrong) =
                check_mirrors(kind, &demo, step, &surfaces, (near, margin));
            eprintln!(
                "{name} step {step}: {n} mirror rays, {hit} must hit, {} missed; {clear} must \
                 miss, {} hit",
                missed.len(),
                wrong.len()
            );
            assert!(missed.is_empty(), "{name} step {step} missed: {missed:#?}");
            assert!(
                wrong.len() <= most_mirrors,
                "{name} step {step}: {} mirror rays hit (at most {most_mirrors}): {wrong:#?}",
                wrong.len()
            );
            must_hit += hit;
        }
        assert!(must_block > 40, "{name}: {must_block} rays to block");
    }
    assert!(must_hit > 5000, "{must_hit} mirror rays to hit");
}

/// The mirror rays of `camera`'s hits on the surfels met from outside, as
/// `integrator::shade_hit` casts them (from the hit lifted by `surface_offset`): each with its
/// pixel, the camera ray, and the cosine between the mirror ray and the normal.
fn mirror_rays(prepared: &PreparedScene, camera: &Camera) -> Vec<((u32, u32), Ray, Ray, f64)> {
    let rays = prepared.primary_rays(camera, SIZE.0, SIZE.1);
    let mut c = SceneCounters::default();
    let hits = prepared.primary_hits(&rays, (0, 0, SIZE.0, SIZE.1), 0.0, T_MAX, &mut c);
    let mut out = Vec::new();
    for (k, (ray, hit)) in hits.iter().enumerate() {
        let Some(h) = hit.filter(|h| h.normal.dot(ray.dir) < 0.0) else {
            continue;
        };
        let mirror = Ray {
            origin: h.position + h.normal * surface_offset(h.position),
            dir: reflect(ray.dir, h.normal),
        };
        let pixel = (k as u32 % SIZE.0, k as u32 / SIZE.0);
        out.push((pixel, *ray, mirror, h.normal.dot(mirror.dir) as f64));
    }
    out
}

/// The mirror rays of step `step` of `demo` from its camera hits on the surfels (met from
/// outside, lifted by `surface_offset` as `integrator::shade_hit` casts them), through the
/// kind's query for a ray leaving the surface (`first_hit_leaving`), against the reference as
/// [`shadow_answer`] gives it (`near` as in `surfel_demos::demo_answer`): `(rays, must hit,
/// missed, must miss, hit)`.
fn check_mirrors(
    kind: SurfelDemoKind,
    demo: &SurfelDemo,
    step: usize,
    surfaces: &Surfaces,
    (near, margin): (f64, f64),
) -> (usize, usize, Vec<String>, usize, Vec<String>) {
    let case = demo_case(kind, demo, step, (0.0, 0.0));
    let prepared = Arc::new(case.scene.clone()).prepare();
    let frame = *prepared.frame();
    let (u, g) = &demo.steps[step];
    let groups = MlsGroups::new(demo_surfels(&demo.model, u, g));
    let mirrors = mirror_rays(&prepared, &case.camera);
    let mut c = SceneCounters::default();
    let (n, mut must_hit, mut must_miss) = (mirrors.len(), 0, 0);
    let (mut missed, mut wrong) = (Vec::new(), Vec::new());
    for &(pixel, _, mirror, cos) in &mirrors {
        let got = prepared.first_hit_leaving_counted(&mirror, 0.0, T_MAX, 0.0, &mut c);
        let from = 4.0 * near / cos.max(0.1);
        let (o, d) = (frame.world_from_local(mirror.origin), mirror.dir.as_dvec3());
        let what = || format!("pixel {pixel:?} cos {cos:.3}: {got:?}");
        match shadow_answer(&groups, surfaces, (o, d), from, (near, margin)) {
            Some(true) => {
                must_hit += 1;
                if got.is_none() {
                    missed.push(what());
                }
            }
            Some(false) => {
                must_miss += 1;
                if got.is_some() {
                    wrong.push(what());
                }
            }
            None => {}
        }
    }
    (n, must_hit, missed, must_miss, wrong)
}

#[test]
fn the_renderer_traces_mirror_rays_as_leaving_the_surface() {
    // Every surfel of the ball pit's step 18 a perfect mirror: a pixel whose mirror ray the
    // reference clears shows exactly the sky in the mirror direction (the shade is the
    // mirror's alone). Asked as a camera ray, 484 such mirror rays hit a sheet at their start
    // (`the_surfel_demos_shadow_and_mirror_rays`); the renderer asks it as a ray leaving the surface.
    let kind = SurfelDemoKind::Balls;
    let step = 18;
    let demo = demo::build(kind, 0.1, step + 1).expect("a demo");
    let surfaces = Surfaces::bodies(&demo.model);
    let mut case = demo_case(kind, &demo, step, (0.0, 0.0));
    for m in &mut case.scene.lighting.materials {
        m.reflectivity = 1.0;
    }
    let effects = Effects {
        reflections: true,
        depth: 1,
        ..Effects::OFF
    };
    let prepared = Arc::new(case.scene.clone()).prepare();
    let frame = *prepared.frame();
    let lighting = prepared.lighting_in_frame();
    let plan = EffectsPlan::new(lighting, case.scene.primitive_count(), &effects);
    assert_eq!(plan.reflection_depth, 1);
    let mut tracer = Tracer::new(&prepared, &plan, 0.0, 0.0);
    let (u, g) = &demo.steps[step];
    let groups = MlsGroups::new(demo_surfels(&demo.model, u, g));
    let (mut sky, mut wrong) = (0, Vec::new());
    for (pixel, ray, mirror, cos) in mirror_rays(&prepared, &case.camera) {
        let from = 4.0 * 5e-3 / cos.max(0.1);
        let (o, d) = (frame.world_from_local(mirror.origin), mirror.dir.as_dvec3());
        if shadow_answer(&groups, &surfaces, (o, d), from, (5e-3, 0.0)) != Some(false) {
            continue;
        }
        sky += 1;
        let (x, y) = pixel;
        let (colour, _) = tracer.primary(&ray, &mut PixelRng::new(x, y, 0));
        if colour != lighting.background(mirror.dir.y) {
            wrong.push(format!("pixel ({x}, {y}): {colour} for the sky"));
        }
    }
    eprintln!(
        "{sky} mirror rays to the sky, {} pixels not the sky",
        wrong.len()
    );
    assert!(sky > 5000, "{sky} mirror rays to the sky");
    assert!(wrong.len() <= 12, "{} pixels: {wrong:#?}", wrong.len());
}
