//! `isoray-bench metaballs`' packet table (issue 14): the Fitted BVH traced by single rays
//! and by 16×16 packets in the same run, at 640×480 and 1920×1080, for primary rays and for
//! hard shadows towards one point light.
//!
//! Primary rays go through `PreparedScene::primary_hits` tile by tile (the renderer's path),
//! once with `PrepareOptions::packets` off and once on; the shadow pass starts from the
//! packet's primary hits (untimed) and traces a ray from each hit towards the light, single
//! rays through `any_hit_counted` against the renderer's choices: the tile's shadow rays
//! handed to the kind's `any_hits_towards` (two packets, the first 64 rays leaving witnesses
//! in the tile's hint for the rest, where `shadow_packet_pays`), or, where the tile's rays
//! are too spread out for a packet to gain, one by one through `occluded_counted` with the
//! same hint. Runs of the two alternate, medians over `--runs`; rays per second per core
//! divide by the worker threads.

use crate::common::median;
use isoray_render::kinds::contract::{OcclusionHint, PreparedKind};
use isoray_render::kinds::metaballs::{PrepareOptions, PreparedMetaballs, RayCounters};
use isoray_render::ray::Ray;
use isoray_render::scene::PreparedGeometry;
use isoray_render::scenes::DemoScene;
use isoray_render::Scene;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

const TILE: u32 = 16;
const T_MAX: f32 = 1.0e4;
/// The image sizes of the table.
const SIZES: [(u32, u32); 2] = [(640, 480), (1920, 1080)];

#[derive(Serialize, Clone)]
pub(crate) struct PacketResult {
    scene: String,
    width: u32,
    height: u32,
    /// "primary" or "hard shadows".
    rays_kind: String,
    rays: usize,
    single_ms: f64,
    packet_ms: f64,
    single_rays_per_s_per_core: f64,
    packet_rays_per_s_per_core: f64,
    speedup: f64,
}

fn tiles(width: u32, height: u32) -> Vec<(u32, u32, u32, u32)> {
    (0..height)
        .step_by(TILE as usize)
        .flat_map(|y| {
            (0..width)
                .step_by(TILE as usize)
                .map(move |x| (x, y, (x + TILE).min(width), (y + TILE).min(height)))
        })
        .collect()
}

/// Milliseconds of `f`, medians over `runs` for each of the two, run alternately.
fn alternate(runs: usize, mut single: impl FnMut(), mut packet: impl FnMut()) -> (f64, f64) {
    let (mut s, mut p) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let started = Instant::now();
        single();
        s.push(started.elapsed().as_secs_f64() * 1e3);
        let started = Instant::now();
        packet();
        p.push(started.elapsed().as_secs_f64() * 1e3);
    }
    (median(s), median(p))
}

fn row(scene: &str, (w, h): (u32, u32), kind: &str, rays: usize, ms: (f64, f64)) -> PacketResult {
    let threads = rayon::current_num_threads() as f64;
    let per_core = |ms: f64| rays as f64 / (ms * 1e-3) / threads;
    PacketResult {
        scene: scene.into(),
        width: w,
        height: h,
        rays_kind: kind.into(),
        rays,
        single_ms: ms.0,
        packet_ms: ms.1,
        single_rays_per_s_per_core: per_core(ms.0),
        packet_rays_per_s_per_core: per_core(ms.1),
        speedup: ms.0 / ms.1,
    }
}

/// The packet rows of `demos` at `time`.
pub(crate) fn measure(demos: &[DemoScene], runs: usize, time: f64) -> Vec<PacketResult> {
    let mut out = Vec::new();
    for &demo in demos {
        let state = Arc::new(demo.state_at(time));
        let floor = demo.isovalue_slider().0;
        let on = PrepareOptions::fitted(floor);
        let off = PrepareOptions {
            packets: false,
            ..on
        };
        let (single, packet) = (
            Arc::<Scene>::clone(&state).prepare_with(off),
            state.prepare_with(on),
        );
        let m: Arc<PreparedMetaballs> = match packet.geometry() {
            PreparedGeometry::Metaballs(m) => m.clone(),
            PreparedGeometry::Tets(_) | PreparedGeometry::Surfels(_) => continue,
        };
        let isovalue = demo.default_isovalue();
        for size in SIZES {
            let rays = packet.primary_rays(&demo.default_camera(), size.0, size.1);
            let tiles = tiles(size.0, size.1);
            let trace = |scene: &isoray_render::PreparedScene| {
                tiles.par_iter().for_each(|&rect| {
                    let mut c = RayCounters::default();
                    let hits = scene.primary_hits(&rays, rect, isovalue, T_MAX, &mut c);
                    std::hint::black_box(hits);
                })
            };
            let ms = alternate(runs, || trace(&single), || trace(&packet));
            let n = (size.0 * size.1) as usize;
            out.push(row(demo.id(), size, "primary", n, ms));
            eprintln!(
                "{:>15} {}×{} primary  single {:>8.1} ms  packets {:>8.1} ms",
                demo.id(),
                size.0,
                size.1,
                ms.0,
                ms.1
            );
            // Shadow rays of each tile's hits towards a light above and beside the eye.
            let eye = rays.through_pixel(0, 0).origin;
            let light = eye + glam::Vec3::new(3.0, 5.0, 1.0) * (1.0 + eye.length() * 0.2);
            let packets: Vec<(Vec<Ray>, Vec<f32>)> = tiles
                .par_iter()
                .map(|&rect| {
                    let mut c = RayCounters::default();
                    packet
                        .primary_hits(&rays, rect, isovalue, T_MAX, &mut c)
                        .iter()
                        .filter_map(|(_, h)| h.as_ref())
                        .map(|h| {
                            let origin = h.position + h.normal * 1e-3;
                            let to = light - origin;
                            (Ray::new(origin, to), to.length())
                        })
                        .unzip()
                })
                .collect();
            let shadow_rays: usize = packets.iter().map(|p| p.0.len()).sum();
            let ms = alternate(
                runs,
                || {
                    packets.par_iter().for_each(|(rays, t_max)| {
                        let mut c = RayCounters::default();
                        for (ray, &hi) in rays.iter().zip(t_max) {
                            std::hint::black_box(m.any_hit_counted(ray, 0.0, hi, isovalue, &mut c));
                        }
                    })
                },
                || {
                    packets.par_iter().for_each(|(rays, t_max)| {
                        let mut c = RayCounters::default();
                        if rays.is_empty() {
                            return;
                        }
                        // As the renderer's shadow batch does (`integrator::batch`): the
                        // tile's rays handed to the kind together, traced as packets where
                        // they are coherent enough, otherwise one by one; one hint for the
                        // tile (witnesses, then the leaves of the last blocked rays, answer
                        // first).
                        let mut hint = OcclusionHint::default();
                        let light = Some(light);
                        let starts = &[]; // not known, and metaballs take no account of it
                        if let Some(found) = m.any_hits_towards(
                            rays, 0.0, t_max, light, isovalue, starts, &mut hint, &mut c,
                        ) {
                            std::hint::black_box(found);
                            return;
                        }
                        for (ray, &hi) in rays.iter().zip(t_max) {
                            let span = (0.0, hi);
                            let blocked =
                                m.occluded_counted(ray, span, isovalue, &mut hint, &mut c);
                            std::hint::black_box(blocked);
                        }
                    })
                },
            );
            out.push(row(demo.id(), size, "hard shadows", shadow_rays, ms));
            eprintln!(
                "{:>15} {}×{} shadows  single {:>8.1} ms  packets {:>8.1} ms",
                demo.id(),
                size.0,
                size.1,
                ms.0,
                ms.1
            );
        }
    }
    out
}

pub(crate) fn print(rows: &[PacketResult]) {
    println!("\n## Single rays against 16×16 packets (Fitted BVH, Bézier clipping)\n");
    println!(
        "| scene | size | rays | count | single ms | packet ms | single Mrays/s/core | \
         packet Mrays/s/core | packets vs single |"
    );
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        println!(
            "| {} | {}×{} | {} | {} | {:.1} | {:.1} | {:.2} | {:.2} | {:.2}× |",
            r.scene,
            r.width,
            r.height,
            r.rays_kind,
            r.rays,
            r.single_ms,
            r.packet_ms,
            r.single_rays_per_s_per_core / 1e6,
            r.packet_rays_per_s_per_core / 1e6,
            r.speedup
        );
    }
}
