//! `isoray-bench accuracy`: what accuracy costs in time, for the metaball root finders.
//!
//! Each root finder (bezier-clipping-metaballs.txt §3.2 Bézier clipping, fitted-bvh-metaballs.txt
//! §3 projections + secant, the tutorial's marching + bisection, sphere tracing) under the
//! Fitted BVH, at a ladder of hit-distance tolerances: the 640×480 render time (median of
//! `--runs`), and the error of the hit distance against the `f64` reference
//! (`metaballs::reference`: the exact piecewise polynomial, certified interval search) on a
//! grid of the image's rays (every `--sample`-th pixel in x and y): the largest and mean
//! absolute error over rays both hit, and how many rays hit in one and miss in the other.
//! Distances are in world units; the scene's size is printed beside them.

use crate::common::{median, write_json, Machine};
use clap::Args;
use isoray_render::kinds::metaballs::reference::ReferenceRay;
use isoray_render::kinds::metaballs::{PrepareOptions, RayCounters, RootFinder};
use isoray_render::scene::Geometry;
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;

use crate::metaballs::{HEIGHT, T_MAX, WIDTH};

#[derive(Args)]
pub struct AccuracyArgs {
    /// Scene ids (default: pool and molecule).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Hit-distance tolerances, world units.
    #[arg(long, value_delimiter = ',', default_values_t = [1e-1, 1e-2, 1e-3, 1e-4, 1e-5])]
    tolerances: Vec<f32>,
    /// Timed renders per configuration; the median is reported.
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Compare every n-th pixel in x and y with the reference.
    #[arg(long, default_value_t = 8)]
    sample: u32,
    /// Also write the rows as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Also write the rows as CSV to this file.
    #[arg(long)]
    csv: Option<PathBuf>,
}

#[derive(Serialize)]
struct Row {
    scene: String,
    finder: String,
    tolerance: f32,
    render_ms: f64,
    iterations_per_hit: f64,
    max_error: f64,
    mean_error: f64,
    /// 99th percentile of the error over rays both hit.
    p99_error: f64,
    /// The scene's extent (largest side of its bounds), world units.
    extent: f64,
    /// Largest angle between the finder's normal and the reference's, degrees.
    max_normal_deg: f64,
    compared: usize,
    disagreements: usize,
    /// Rays the reference hits and the finder misses (silhouette pixels lost).
    lost: usize,
    /// Rays the finder hits and the reference misses (gained).
    gained: usize,
}

#[derive(Serialize)]
struct Report {
    machine: Machine,
    rows: Vec<Row>,
}

pub fn run(args: AccuracyArgs) -> Result<(), String> {
    if args.runs == 0 || args.sample == 0 {
        return Err("--runs and --sample must be at least 1".into());
    }
    if let Some(t) = args
        .tolerances
        .iter()
        .find(|t| !(t.is_finite() && **t > 0.0))
    {
        return Err(format!("tolerance {t} must be a positive number"));
    }
    let ids: Vec<String> = if args.scenes.is_empty() {
        vec!["pool".into(), "molecule".into()]
    } else {
        args.scenes.clone()
    };
    let machine = Machine::here();
    println!("# isoray-bench accuracy\n");
    println!(
        "{}; {WIDTH}×{HEIGHT} primary rays under the Fitted BVH, render ms the median of {} \
         run(s); errors against the f64 reference on every {}th pixel in x and y.\n",
        machine.line(),
        args.runs,
        args.sample
    );
    let mut rows = Vec::new();
    for demo in crate::metaballs::pick(&ids)? {
        let id = demo.id();
        let state = Arc::new(demo.state_at(1.0));
        let Geometry::Metaballs(balls) = &state.geometry else {
            return Err(format!("{id} is not a metaball scene"));
        };
        let floor = demo.isovalue_slider().0;
        let isovalue = demo.default_isovalue();
        let rays = demo.default_camera().rays(WIDTH, HEIGHT);
        let pixels: Vec<(u32, u32)> = (0..HEIGHT)
            .step_by(args.sample as usize)
            .flat_map(|y| {
                (0..WIDTH)
                    .step_by(args.sample as usize)
                    .map(move |x| (x, y))
            })
            .collect();
        // The reference once per scene: the first hit in the ray's own parameter.
        let reference: Vec<Option<(f64, glam::DVec3)>> = pixels
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
            .map_or(0.0, |(lo, hi)| (hi - lo).max_element());
        eprintln!("{id}: scene extent {extent:.1} world units");
        for finder in RootFinder::ALL {
            for &tolerance in &args.tolerances {
                let options = PrepareOptions {
                    tolerance,
                    ..PrepareOptions::fitted(floor).with_finder(finder)
                };
                let prepared = state.clone().prepare_with(options);
                let mut times = Vec::new();
                let mut counters = RayCounters::default();
                for _ in 0..args.runs {
                    let (ms, c) = crate::metaballs::render(&prepared, demo, 1);
                    times.push(ms);
                    counters = c;
                }
                let answers: Vec<Option<(f64, glam::DVec3)>> = pixels
                    .par_iter()
                    .map(|&(x, y)| {
                        let ray = rays.through_pixel(x, y);
                        prepared
                            .first_hit_counted(
                                &ray,
                                0.0,
                                T_MAX,
                                isovalue,
                                &mut RayCounters::default(),
                            )
                            .map(|h| (h.t as f64, h.normal.as_dvec3()))
                    })
                    .collect();
                let (mut errors, mut lost, mut gained, mut max_normal_deg) =
                    (Vec::new(), 0, 0, 0.0f64);
                for (a, r) in answers.iter().zip(&reference) {
                    match (a, r) {
                        (Some((a, na)), Some((r, nr))) => {
                            errors.push((a - r).abs());
                            let cos = na.dot(*nr).clamp(-1.0, 1.0);
                            max_normal_deg = max_normal_deg.max(cos.acos().to_degrees());
                        }
                        (None, None) => {}
                        (None, Some(_)) => lost += 1,
                        (Some(_), None) => gained += 1,
                    }
                }
                errors.sort_by(f64::total_cmp);
                let compared = errors.len();
                let max_error = errors.last().copied().unwrap_or(0.0);
                let sum: f64 = errors.iter().sum();
                let p99_error = errors
                    .get((compared * 99 / 100).min(compared.saturating_sub(1)))
                    .copied()
                    .unwrap_or(0.0);
                let disagreements = lost + gained;
                let row = Row {
                    scene: id.to_string(),
                    finder: finder.name().into(),
                    tolerance,
                    render_ms: median(times),
                    iterations_per_hit: crate::common::per(counters.hit_iterations, counters.hits),
                    max_error,
                    mean_error: sum / compared.max(1) as f64,
                    p99_error,
                    extent: extent as f64,
                    max_normal_deg,
                    compared,
                    disagreements,
                    lost,
                    gained,
                };
                eprintln!(
                    "{id} {:<20} tol {tolerance:e}: {:.1} ms, max error {:.2e}",
                    row.finder, row.render_ms, row.max_error
                );
                rows.push(row);
            }
        }
    }
    println!(
        "| scene | finder | tolerance | render ms | iterations/hit | max error | p99 error | \
         mean error | max/extent | normal ° | rays compared | lost | gained |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {} | {} | {:.0e} | {:.1} | {:.2} | {:.1e} | {:.1e} | {:.1e} | {:.1e} | {:.2} | {} | {} | {} |",
            r.scene,
            r.finder,
            r.tolerance,
            r.render_ms,
            r.iterations_per_hit,
            r.max_error,
            r.p99_error,
            r.mean_error,
            r.max_error / r.extent.max(1e-30),
            r.max_normal_deg,
            r.compared,
            r.lost,
            r.gained
        );
    }
    println!(
        "\nHit/miss disagreements are rays that only graze the surface (within the f32 field's \
         rounding) or, for marching, cross a stretch thinner than its step."
    );
    if let Some(path) = &args.csv {
        let mut text = String::from(
            "kind,scene,setting,tolerance,render_ms,iterations_per_hit,max_error,mean_error,\
             p99_error,relative_max_error,max_normal_deg,compared,lost,gained\n",
        );
        for r in &rows {
            text.push_str(&format!(
                "metaballs,{},{},{:e},{:.3},{:.3},{:e},{:e},{:e},{:e},{:.4},{},{},{}\n",
                r.scene,
                r.finder,
                r.tolerance,
                r.render_ms,
                r.iterations_per_hit,
                r.max_error,
                r.mean_error,
                r.p99_error,
                r.max_error / r.extent.max(1e-30),
                r.max_normal_deg,
                r.compared,
                r.lost,
                r.gained
            ));
        }
        std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    if let Some(path) = &args.json {
        write_json(path, &Report { machine, rows })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn bad_arguments_are_named() {
        let args = |runs, sample, tolerances: Vec<f32>| super::AccuracyArgs {
            scenes: vec![],
            tolerances,
            runs,
            sample,
            json: None,
            csv: None,
        };
        assert!(super::run(args(0, 8, vec![1e-3])).is_err());
        assert!(super::run(args(1, 0, vec![1e-3])).is_err());
        let e = super::run(args(1, 8, vec![-1.0])).expect_err("a negative tolerance is refused");
        assert!(e.contains("-1"), "{e}");
    }
}
