//! Shadow rays on the surfel demos as a viewer sees them (320×240): every shadow ray the
//! renderer casts from a hit facing the light ([`shadow_rays`]: the surfels' surface and the
//! floor), answered as the renderer answers it (`integrator::trace_shadows`: packets towards
//! one light) and by the `f64` MLS reference over every surfel of each body
//! ([`surface_trace`]), not the engine's tree, neighbourhoods or iteration.

use super::shadow_rays;
use super::surfel_demos::{demo_case, demo_surfels, surface_trace, MlsGroups, Surfaces};
use super::surfels::coherence;
use glam::DVec3;
use isoray_render::integrator::trace_shadows;
use isoray_render::kinds::counters::SceneCounters;
use isoray_render::kinds::surfels::demo::{self, SurfelDemo, SurfelDemoKind};
use isoray_render::kinds::surfels::reference::MlsSurfel;
use isoray_render::scenes::DemoScene;
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
fn the_surfel_demos_shadow_rays() {
    // Per demo: its detail as served, `near` as the camera suite's, and steps with the most
    // shadow rays the reference lets through (by a margin) that the engine may block. None
    // in the frames the camera suite checks; a few in the strike's and the landing's frames,
    // where bodies press together and the two definitions of the surface part (see
    // `surfel_demos`): measured 1 at the impact's step 6, 16 and 1 at the ball pit's steps
    // 18 and 42 (one of the 16 from the floor; 315 and 91 before `OUTWARD`, and 34 at step 60,
    // 12 at the impact's step 6). The clipped cubes are traced face by face, cut as the
    // camera suite cuts them. No ray the reference blocks may get through anywhere. About
    // 480,000 shadow rays, 400,000 of them from the floors of the ball pit and the cubes.
    for (kind, detail, near, steps) in [
        (
            SurfelDemoKind::Impact,
            1.0f32,
            2e-3,
            &[(6usize, 3usize), (60, 0), (210, 0)][..],
        ),
        (
            SurfelDemoKind::Balls,
            0.1,
            5e-3,
            &[(0, 0), (18, 20), (42, 4), (60, 0), (120, 0)],
        ),
        (SurfelDemoKind::Heads, 0.05, 2e-3, &[(90, 0), (150, 0)]),
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
        let mut must_block = 0;
        for &(step, most) in steps {
            let t = check_step(kind, &demo, step, &surfaces, (near, margin));
            let name = kind.name();
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
        }
        assert!(
            must_block > 40,
            "{}: {must_block} rays to block",
            kind.name()
        );
    }
}
