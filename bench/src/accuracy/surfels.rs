//! Surfel settings (the MLS iteration cap and convergence threshold of
//! deforming-point-sampled-surfaces.txt §4.2.1) against the brute-force `f64` MLS reference
//! (`surfels::reference`: eq. 12 over every surfel, sign change and bisection; no tree, no
//! fixed neighbourhoods, no iteration from an ellipse). The demos compared clip nothing (§4.3
//! clipping is not in the reference): the elastic balls and the impact, at rest and deformed.

use crate::accuracy::stats::{compare, Answer, Row};
use glam::DVec3;
use isoray_render::kinds::dispatch::{Geometry, PreparedGeometry};
use isoray_render::kinds::surfels::counters::SurfelCounters;
use isoray_render::kinds::surfels::demo::{self, SurfelDemoKind};
use isoray_render::kinds::surfels::prepared::PreparedSurfels;
use isoray_render::kinds::surfels::reference::{first_hit, MlsSurfel};
use isoray_render::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, MLS_EPSILON};
use isoray_render::scene::Scene;
use isoray_render::shade::Lighting;
use isoray_render::{Backend, View};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

const WIDTH: u32 = 320;
const HEIGHT: u32 = 240;

/// The settings varied: iteration caps at the default threshold, thresholds at the default cap.
fn settings() -> Vec<(String, String, u32, f32)> {
    let mut out = Vec::new();
    for n in [2u32, 3, 4, 6, 12] {
        out.push((
            "MLS iterations (ε 1e-4)".into(),
            format!("{n} iterations"),
            n,
            MLS_EPSILON,
        ));
    }
    for eps in [1e-2f32, 1e-3, 1e-5, 1e-6] {
        out.push((
            "MLS threshold ε·h (12 iterations; 1e-4 is the row above)".into(),
            format!("ε {eps:.0e}"),
            12,
            eps,
        ));
    }
    out
}

/// The rows of every setting on each demo (at `detail` of full size), at rest and deformed.
pub fn rows(backend: &Backend, detail: f32, runs: usize, sample: u32) -> Result<Vec<Row>, String> {
    let mut rows = Vec::new();
    for (kind, step) in [
        (SurfelDemoKind::Balls, 20usize),
        (SurfelDemoKind::Impact, 0),
        (SurfelDemoKind::Impact, 12),
    ] {
        let demo = demo::build(kind, detail, step + 1).map_err(|e| e.to_string())?;
        let scene_name = format!("{} step {step}", kind.name());
        let view = View {
            width: WIDTH,
            height: HEIGHT,
            camera: demo.camera,
            isovalue: 0.0,
        };
        let rays = view.camera.rays(WIDTH, HEIGHT);
        let pixels: Vec<(u32, u32)> = (0..HEIGHT)
            .step_by(sample as usize)
            .flat_map(|y| (0..WIDTH).step_by(sample as usize).map(move |x| (x, y)))
            .collect();
        // The reference reads the deformed surfels of a prepared step (data, not code).
        let probe = PreparedSurfels::new(demo.scene(
            step,
            SurfelOptions::default(),
            Arc::new(SurfelRuntime::default()),
        ));
        let surfels: Vec<MlsSurfel> = (0..probe.model.len())
            .map(|k| {
                let mut fresh = false;
                let d = *probe.surfel(k, &mut fresh);
                let stretch = d.leaf_radius as f64 / (probe.model.leaf_radius[k] as f64).max(1e-20);
                MlsSurfel {
                    centre: d.centre.as_dvec3(),
                    normal: d.normal.as_dvec3().normalize_or_zero(),
                    support: probe.model.support[k] as f64 * stretch.max(1e-3),
                    reach: d.leaf_radius as f64,
                }
            })
            .collect();
        let started = Instant::now();
        let reference: Vec<Answer> = pixels
            .par_iter()
            .map(|&(x, y)| {
                let ray = rays.through_pixel(x, y);
                let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
                first_hit(&surfels, o, d, 0.0, 1e4).map(|h| (h.t * d.length(), h.normal))
            })
            .collect();
        let (lo, hi) = surfels.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), s| (lo.min(s.centre), hi.max(s.centre)),
        );
        let extent = (hi - lo).max_element();
        eprintln!(
            "surfels {scene_name}: {} surfels, reference on {} rays in {:.1} s",
            surfels.len(),
            pixels.len(),
            started.elapsed().as_secs_f64()
        );
        for (family, setting, iterations, epsilon) in settings() {
            let options = SurfelOptions {
                mls_iterations: iterations,
                mls_epsilon: epsilon,
                ..SurfelOptions::default()
            };
            let mut times = Vec::new();
            let mut answers = Vec::new();
            let mut capped = 0;
            for _ in 0..runs {
                // A fresh runtime per run: the §4.2.2 cache and the lazy state start cold.
                let scene = Arc::new(Scene {
                    geometry: Geometry::Surfels(demo.scene(
                        step,
                        options,
                        Arc::new(SurfelRuntime::default()),
                    )),
                    lighting: Lighting::default(),
                });
                let t0 = Instant::now();
                let prepared = scene.prepare();
                let surface = backend.render_surface(&prepared, &view);
                times.push(t0.elapsed().as_secs_f64() * 1e3);
                answers = pixels
                    .iter()
                    .map(|&(x, y)| {
                        let [t, nx, ny, nz] = surface.at(x, y);
                        t.is_finite()
                            .then(|| (t as f64, DVec3::new(nx as f64, ny as f64, nz as f64)))
                    })
                    .collect();
                // Capped searches: counted by tracing the compared rays once more.
                if let PreparedGeometry::Surfels(p) = prepared.geometry() {
                    let rays = prepared.primary_rays(&view.camera, WIDTH, HEIGHT);
                    capped = count_capped(p, &rays, &pixels);
                }
            }
            let mut row = Row {
                kind: "surfels",
                scene: scene_name.clone(),
                family,
                setting,
                ms: crate::common::median(times),
                extent,
                capped,
                psnr_db: f64::NAN,
                bytes: f64::NAN,
                ..Row::default()
            };
            compare(&mut row, &answers, &reference);
            eprintln!(
                "  {:<36} {:<14} {:>8.1} ms  lost {:>3} gained {:>3}  p99 {:.1e}  capped {}",
                row.family, row.setting, row.ms, row.lost, row.gained, row.p99, row.capped
            );
            rows.push(row);
        }
    }
    Ok(rows)
}

/// MLS searches that ran out of iterations on the compared rays.
fn count_capped(
    p: &PreparedSurfels,
    rays: &isoray_render::camera::PrimaryRays,
    pixels: &[(u32, u32)],
) -> u64 {
    pixels
        .par_iter()
        .map(|&(x, y)| {
            let ray = rays.through_pixel(x, y);
            let mut c = SurfelCounters::default();
            let _ = p.nearest(&ray, 0.0, 1e4, None, &mut c);
            c.capped
        })
        .sum()
}
