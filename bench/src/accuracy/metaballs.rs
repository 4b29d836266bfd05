//! Metaball settings that trade accuracy for speed, on the paper scenes, against the `f64`
//! reference (`metaballs::reference`: the exact piecewise polynomial along the ray and a
//! certified interval search; no tree, no Bézier clipping): each root finder at a ladder of
//! tolerances, marching's and the secant method's step, and `f32` hits refined in `f64`.

use crate::accuracy::stats::{compare, Answer, Row};
use crate::metaballs::{HEIGHT, T_MAX, WIDTH};
use isoray_render::kinds::metaballs::reference::ReferenceRay;
use isoray_render::kinds::metaballs::{PrepareOptions, RayCounters, RootFinder};
use isoray_render::scene::Geometry;
use isoray_render::scenes::DemoScene;
use rayon::prelude::*;
use std::sync::Arc;

/// What the study varies.
pub struct Settings {
    pub tolerances: Vec<f32>,
    /// Steps of marching and the secant method, fractions of the smallest radius.
    pub steps: Vec<f32>,
}

/// One configuration: its series, its label and its options.
fn configurations(floor: f32, s: &Settings) -> Vec<(String, String, PrepareOptions)> {
    let base = PrepareOptions::fitted(floor);
    let mut out = Vec::new();
    for finder in RootFinder::ALL {
        for &tolerance in &s.tolerances {
            out.push((
                format!("{} (tolerance)", finder.name()),
                format!("tol {tolerance:.0e}"),
                PrepareOptions {
                    tolerance,
                    ..base.with_finder(finder)
                },
            ));
        }
    }
    for finder in [RootFinder::March, RootFinder::Secant] {
        // An infinite step is the secant method's centre projections only; marching needs one.
        for &step in s
            .steps
            .iter()
            .filter(|s| s.is_finite() || finder == RootFinder::Secant)
        {
            out.push((
                format!("{} (step, tol 1e-4)", finder.name()),
                if step.is_finite() {
                    format!("step {step}")
                } else {
                    "centre projections only".into()
                },
                PrepareOptions {
                    step,
                    ..base.with_finder(finder)
                },
            ));
        }
    }
    for finder in RootFinder::ALL {
        out.push((
            "f64 hit refinement (tol 1e-3)".into(),
            finder.name().into(),
            PrepareOptions {
                tolerance: 1e-3,
                refine_f64: true,
                ..base.with_finder(finder)
            },
        ));
    }
    out
}

/// The rows of every configuration on every scene of `demos`.
pub fn rows(demos: &[DemoScene], settings: &Settings, runs: usize, sample: u32) -> Vec<Row> {
    let mut rows = Vec::new();
    for &demo in demos {
        let id = demo.id();
        let state = Arc::new(demo.state_at(1.0));
        let Geometry::Metaballs(balls) = &state.geometry else {
            continue;
        };
        let floor = demo.isovalue_slider().0;
        let isovalue = demo.default_isovalue();
        let rays = demo.default_camera().rays(WIDTH, HEIGHT);
        let pixels = grid(sample);
        let started = std::time::Instant::now();
        let reference: Vec<Answer> = pixels
            .par_iter()
            .map(|&(x, y)| {
                let ray = rays.through_pixel(x, y);
                let r = ReferenceRay::new(
                    balls,
                    ray.origin.as_dvec3(),
                    ray.dir.as_dvec3(),
                    0.0,
                    T_MAX as f64,
                );
                let t = r.first_at_least(isovalue as f64, 0.0)?;
                Some((t, r.normal(t).unwrap_or_default()))
            })
            .collect();
        let extent = balls
            .bounds()
            .map_or(0.0, |(lo, hi)| (hi - lo).max_element()) as f64;
        eprintln!(
            "metaballs {id}: {} balls, extent {extent:.1}, reference on {} rays in {:.1} s",
            balls.balls.len(),
            pixels.len(),
            started.elapsed().as_secs_f64()
        );
        // Scenes too big to trace whole in a few seconds per setting are timed on every
        // `stride`-th row (the time scaled to the whole frame).
        let stride = if balls.balls.len() > 20_000 { 4 } else { 1 };
        for (family, setting, options) in configurations(floor, settings) {
            let prepared = state.clone().prepare_with(options);
            let mut times = Vec::new();
            let mut counters = RayCounters::default();
            for _ in 0..runs {
                let (ms, c) = crate::metaballs::render(&prepared, demo, stride);
                times.push(ms * stride as f64);
                counters = c;
            }
            let answers: Vec<Answer> = pixels
                .par_iter()
                .map(|&(x, y)| {
                    let ray = rays.through_pixel(x, y).in_frame(prepared.frame());
                    prepared
                        .first_hit_counted(&ray, 0.0, T_MAX, isovalue, &mut RayCounters::default())
                        .map(|h| (h.t as f64, h.normal.as_dvec3()))
                })
                .collect();
            let mut row = Row {
                kind: "metaballs",
                scene: id.into(),
                family,
                setting,
                ms: crate::common::median(times),
                extent,
                capped: counters.capped,
                iterations_per_hit: crate::common::per(counters.hit_iterations, counters.hits),
                psnr_db: f64::NAN,
                bytes: f64::NAN,
                ..Row::default()
            };
            compare(&mut row, &answers, &reference);
            eprintln!(
                "  {:<44} {:<24} {:>8.1} ms  lost {:>3} gained {:>3}  p99 {:.1e}",
                row.family, row.setting, row.ms, row.lost, row.gained, row.p99
            );
            rows.push(row);
        }
    }
    rows
}

/// Every `sample`-th pixel of the 640×480 image in x and y.
fn grid(sample: u32) -> Vec<(u32, u32)> {
    (0..HEIGHT)
        .step_by(sample as usize)
        .flat_map(|y| (0..WIDTH).step_by(sample as usize).map(move |x| (x, y)))
        .collect()
}

/// Per finder with a step, the largest step that lost no silhouette pixel on any scene, and
/// the smallest step tried.
pub fn step_bounds(rows: &[Row]) -> Vec<String> {
    let mut out = Vec::new();
    for finder in [RootFinder::March, RootFinder::Secant] {
        let family = format!("{} (step, tol 1e-4)", finder.name());
        let mut settings: Vec<(f64, String, usize, f64)> = Vec::new();
        for r in rows.iter().filter(|r| r.family == family) {
            let step = r
                .setting
                .strip_prefix("step ")
                .and_then(|s| s.parse::<f64>().ok())
                .unwrap_or(f64::INFINITY);
            match settings.iter_mut().find(|s| s.1 == r.setting) {
                Some(s) => {
                    s.2 += r.lost;
                    s.3 += r.ms;
                }
                None => settings.push((step, r.setting.clone(), r.lost, r.ms)),
            }
        }
        settings.sort_by(|a, b| b.0.total_cmp(&a.0));
        // The largest step from which every smaller step keeps the silhouette too.
        let mut bound = None;
        for s in settings.iter().rev() {
            if s.2 == 0 {
                bound = Some(s);
            } else {
                break;
            }
        }
        out.push(match bound {
            Some(s) => format!(
                "{}: loses no silhouette pixel at {} and every smaller step ({:.1} ms/frame summed over the scenes)",
                finder.name(),
                s.1,
                s.3
            ),
            None => format!(
                "{}: loses silhouette pixels at every step tried",
                finder.name()
            ),
        });
    }
    out
}
