//! Tet settings against the brute-force `f64` reference (`tets::reference`: every tet, the
//! plane of its linear field and barycentric coordinates; no marching-tets table, no BVH):
//! single rays against the engine's 16×16 packets, faceted against smooth normals. The engine
//! has no `f64` path for tets (its edge-plane tests are `f32` only), so there is no `f32`
//! against `f64` row.

use crate::accuracy::stats::{compare, Answer, Row};
use crate::metaballs::{HEIGHT, T_MAX, WIDTH};
use glam::DVec3;
use isoray_render::kinds::dispatch::PreparedGeometry;
use isoray_render::kinds::tets::prepared::{Normals, TetOptions};
use isoray_render::kinds::tets::reference::reference_hit;
use isoray_render::kinds::tets::traverse::TetQuery;
use isoray_render::kinds::tets::{TetCounters, TetScene};
use isoray_render::scene::{Geometry, PreparedScene};
use isoray_render::scenes::DemoScene;
use isoray_render::{Backend, View};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// The rows of the tet demo: packets and single rays, faceted and smooth normals.
pub fn rows(backend: &Backend, runs: usize, sample: u32) -> Result<Vec<Row>, String> {
    let demo = DemoScene::TetGyroid;
    let state = Arc::new(demo.state_at(1.0));
    let Geometry::Tets(step) = &state.geometry else {
        return Err("tets-gyroid is not a tet scene".into());
    };
    let isovalue = demo.default_isovalue();
    let camera = demo.default_camera();
    let rays = camera.rays(WIDTH, HEIGHT);
    let pixels: Vec<(u32, u32)> = (0..HEIGHT)
        .step_by(sample as usize)
        .flat_map(|y| (0..WIDTH).step_by(sample as usize).map(move |x| (x, y)))
        .collect();
    let started = Instant::now();
    let reference: Vec<Answer> = pixels
        .par_iter()
        .map(|&(x, y)| {
            let ray = rays.through_pixel(x, y);
            let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
            let (t, tet) = reference_hit(
                step.positions(),
                step.scalars(),
                step.mesh().tets(),
                o,
                d,
                0.0,
                T_MAX as f64,
                isovalue as f64,
            )?;
            Some((t * d.length(), -gradient(step, tet).normalize_or_zero()))
        })
        .collect();
    let extent = step
        .bounds()
        .map_or(0.0, |(lo, hi)| (hi - lo).max_element()) as f64;
    eprintln!(
        "tets {}: {} tets, reference on {} rays in {:.1} s",
        demo.id(),
        step.mesh().tets().len(),
        pixels.len(),
        started.elapsed().as_secs_f64()
    );
    let view = View {
        width: WIDTH,
        height: HEIGHT,
        camera,
        isovalue,
    };
    let mut rows = Vec::new();
    for (normals, label) in [(Normals::Faceted, "faceted"), (Normals::Smooth, "smooth")] {
        let prepared = state.clone().prepare_tets_with(TetOptions {
            normals,
            ..TetOptions::default()
        });
        for packets in [true, false] {
            let mut times = Vec::new();
            let mut answers = Vec::new();
            for _ in 0..runs {
                let t0 = Instant::now();
                let image = if packets {
                    packet_frame(backend, &prepared, &view)
                } else {
                    single_frame(&prepared, &view)?
                };
                times.push(t0.elapsed().as_secs_f64() * 1e3);
                answers = pixels
                    .iter()
                    .map(|&(x, y)| image[(y * WIDTH + x) as usize])
                    .collect();
            }
            let mut row = Row {
                kind: "tets",
                scene: demo.id().into(),
                family: format!("{label} normals"),
                setting: if packets {
                    "16×16 packets".into()
                } else {
                    "single rays".into()
                },
                ms: crate::common::median(times),
                extent,
                psnr_db: f64::NAN,
                bytes: f64::NAN,
                ..Row::default()
            };
            compare(&mut row, &answers, &reference);
            eprintln!(
                "  {:<16} {:<14} {:>8.1} ms  lost {} gained {}  max {:.1e}",
                row.family, row.setting, row.ms, row.lost, row.gained, row.max
            );
            rows.push(row);
        }
    }
    Ok(rows)
}

/// Every pixel's hit through the backend's primary path (tets: 16×16 packets).
fn packet_frame(backend: &Backend, prepared: &PreparedScene, view: &View) -> Vec<Answer> {
    let surface = backend.render_surface(prepared, view);
    (0..view.height)
        .flat_map(|y| (0..view.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let [t, nx, ny, nz] = surface.at(x, y);
            t.is_finite()
                .then(|| (t as f64, DVec3::new(nx as f64, ny as f64, nz as f64)))
        })
        .collect()
}

/// Every pixel's hit by the single-ray traversal.
fn single_frame(prepared: &PreparedScene, view: &View) -> Result<Vec<Answer>, String> {
    let PreparedGeometry::Tets(tets) = prepared.geometry() else {
        return Err("not a tet scene".into());
    };
    let q = TetQuery::single(view.isovalue);
    let rays = prepared.primary_rays(&view.camera, view.width, view.height);
    Ok((0..view.height)
        .into_par_iter()
        .flat_map_iter(|y| {
            let rays = &rays;
            let q = &q;
            (0..view.width).map(move |x| {
                let ray = rays.through_pixel(x, y);
                let mut c = TetCounters::default();
                tets.first_hit(&ray, 0.0, T_MAX, q, &mut c).map(|hit| {
                    let rec = tets.hit_record(&ray, &hit, q);
                    (rec.t as f64, rec.normal.as_dvec3())
                })
            })
        })
        .collect())
}

/// The gradient of the linear field in tet `tet` (the reference's flat normal, outward is
/// down the field).
fn gradient(step: &TetScene, tet: u32) -> DVec3 {
    let ids = step.mesh().tets()[tet as usize];
    let p = ids.map(|v| step.positions()[v as usize].as_dvec3());
    let s = ids.map(|v| step.scalars()[v as usize] as f64);
    let e = [p[1] - p[0], p[2] - p[0], p[3] - p[0]];
    let det = e[0].dot(e[1].cross(e[2]));
    (e[1].cross(e[2]) * (s[1] - s[0])
        + e[2].cross(e[0]) * (s[2] - s[0])
        + e[0].cross(e[1]) * (s[3] - s[0]))
        / det
}
