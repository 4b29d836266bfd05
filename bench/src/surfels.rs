//! `isoray-bench surfels`: deforming-point-sampled-surfaces.txt §5 (Fig. 5) and §4.1.4
//! (Fig. 3) on the three generated demos (40 elastic balls in a hollow cube; a 150k-surfel
//! object with ~450 nodes hit by a cannonball; three bouncing clipped cubes).
//!
//! For each scene and image size: ms per frame (median over the animation's frames and
//! `--runs` passes; a frame = preparing the step + tracing primary and shadow rays on the
//! CPU backend) for rebuild, eager refit, lazy, lazy + sphere-node cache, and the auto
//! heuristic (with the modes it chose); sphere tests and surfel intersections per primary
//! and shadow ray; the share of tests the cache saves (camera rays: tests per nearest-hit
//! query, lazy against lazy + cache over the same frames; and all rays per frame), and the
//! most any such cache could save under this traversal (each camera ray given its own hit
//! distance as its bound before it starts: [`oracle_bound`]). Tightness: per tree level, the
//! average ratio of the updated radius (eq. 9 alone; eqs. 9 + 11 bottom-up; and the engine's
//! bound, eqs. 9 + 11 or the sphere around both children where tighter) to the smallest
//! sphere around the deformed surfels below (Welzl, plus the largest leaf radius: spheres
//! here bound discs, not centres), at the middle frame.

use crate::common::{median, per, write_json, Machine};
use clap::Args;
use isoray_render::effects::toggles::Effects;
use isoray_render::kinds::dispatch::Geometry;
use isoray_render::kinds::surfels::counters::SurfelCounters;
use isoray_render::kinds::surfels::deform::{deform_surfel, node_sphere, radius_from_children};
use isoray_render::kinds::surfels::demo::{self, SurfelDemo, SurfelDemoKind};
use isoray_render::kinds::surfels::miniball::miniball;
use isoray_render::kinds::surfels::prepared::{parent_sphere, PreparedSurfels};
use isoray_render::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, UpdateMode};
use isoray_render::scene::{PreparedGeometry, Scene};
use isoray_render::shade::Lighting;
use isoray_render::{CpuBackend, View};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct SurfelsArgs {
    /// Also write the results as JSON to this file.
    #[arg(long)]
    json: Option<std::path::PathBuf>,
    /// Scenes (default: all): balls, impact, heads.
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Multiplies every scene's surfel count (1: the paper's sizes).
    #[arg(long, default_value_t = 1.0)]
    detail: f32,
    /// Animation frames timed per configuration (after the simulation's first `--skip`).
    #[arg(long, default_value_t = 10)]
    frames: usize,
    /// Simulated frames skipped before timing (the objects start moving).
    #[arg(long, default_value_t = 6)]
    skip: usize,
    /// Passes over the frames; the median frame is reported.
    #[arg(long, default_value_t = 2)]
    runs: usize,
    /// Image sizes, WxH.
    #[arg(long, value_delimiter = ',', default_values_t = ["512x384".to_string(), "1280x720".to_string()])]
    sizes: Vec<String>,
    /// Render threads (default: every core).
    #[arg(long)]
    threads: Option<usize>,
    /// Skip the tightness table (it runs Welzl on every node).
    #[arg(long)]
    no_tightness: bool,
    /// Configurations (default: all): rebuild, eager, lazy, lazy+cache, auto+cache.
    #[arg(long, value_delimiter = ',')]
    configs: Vec<String>,
}

#[derive(Serialize)]
struct Row {
    scene: &'static str,
    surfels: usize,
    nodes: usize,
    size: String,
    config: String,
    ms_per_frame: f64,
    prepare_ms: f64,
    sphere_tests_per_ray: f64,
    surfel_tests_per_ray: f64,
    /// Sphere + surfel tests per nearest-hit (camera) ray, the rays the cache serves.
    nearest_tests_per_ray: f64,
    /// Sphere + surfel tests per frame, every ray.
    tests_per_frame: f64,
    rays: u64,
    modes: BTreeMap<String, usize>,
    /// Share of the surfels a frame deformed (median over frames; every one for eager and
    /// rebuild): what auto mode's heuristic reads from the previous step.
    touched: f64,
}

#[derive(Serialize)]
struct Tightness {
    scene: &'static str,
    level: usize,
    nodes: usize,
    eq9: f64,
    eq9_11: f64,
    /// Eqs. 9 + 11, or the sphere around both children where tighter (what the engine uses).
    moved: f64,
}

#[derive(Serialize)]
struct Report {
    machine: Machine,
    rows: Vec<Row>,
    tightness: Vec<Tightness>,
}

const CONFIGS: [(&str, UpdateMode, bool); 5] = [
    ("rebuild", UpdateMode::Rebuild, false),
    ("eager", UpdateMode::Eager, false),
    ("lazy", UpdateMode::Lazy, false),
    ("lazy+cache", UpdateMode::Lazy, true),
    ("auto+cache", UpdateMode::Auto, true),
];

pub fn run(args: SurfelsArgs) -> Result<(), String> {
    let backend = CpuBackend::new(args.threads.unwrap_or(0)).map_err(|e| e.to_string())?;
    let mut machine = Machine::here();
    machine.threads = backend.threads();
    println!("# isoray-bench surfels — {}", machine.line());
    let mut report = Report {
        machine,
        rows: Vec::new(),
        tightness: Vec::new(),
    };
    for kind in SurfelDemoKind::ALL {
        let id = &kind.name()["surfel-".len()..];
        if !args.scenes.is_empty() && !args.scenes.iter().any(|s| s == id) {
            continue;
        }
        let t = Instant::now();
        let demo = demo::build(kind, args.detail, args.skip + args.frames)
            .map_err(|e| format!("{id}: {e}"))?;
        println!(
            "\n## {id}: {} surfels, {} simulation nodes, {} spheres, {} levels (model + simulation {:.1} s)",
            demo.model.len(),
            demo.model.nodes.len(),
            demo.model.tree.nodes.len(),
            demo.model.tree.levels(),
            t.elapsed().as_secs_f64()
        );
        for size in &args.sizes {
            let (w, h) = parse_size(size)?;
            println!("\n{size}, shadows on: ms/frame (median), prepare ms, tests per ray (primary + shadow)");
            println!(
                "| config | ms/frame | prepare ms | sphere tests/ray | surfel tests/ray | surfels deformed | modes |"
            );
            println!("|---|---|---|---|---|---|---|");
            let chosen: Vec<_> = CONFIGS
                .into_iter()
                .filter(|(name, ..)| {
                    args.configs.is_empty() || args.configs.iter().any(|c| c == name)
                })
                .collect();
            // Runs outermost, every configuration once in each: a slower or faster spell of
            // a shared machine falls on all of them alike, and the ratios below compare
            // configurations measured side by side.
            let mut samples: Vec<Samples> = chosen.iter().map(|_| Samples::default()).collect();
            for _ in 0..args.runs {
                for (&(_, mode, cache), into) in chosen.iter().zip(&mut samples) {
                    measure_run(&backend, &demo, &args, (w, h), mode, cache, into);
                }
            }
            let mut by_config = BTreeMap::new();
            for (&(name, ..), samples) in chosen.iter().zip(samples) {
                let row = samples.row(&demo, &args, kind.name(), (w, h), name);
                println!(
                    "| {name} | {:.1} | {:.1} | {:.2} | {:.3} | {:.0}% | {:?} |",
                    row.ms_per_frame,
                    row.prepare_ms,
                    row.sphere_tests_per_ray,
                    row.surfel_tests_per_ray,
                    100.0 * row.touched,
                    row.modes
                );
                by_config.insert(
                    name,
                    (
                        row.ms_per_frame,
                        row.nearest_tests_per_ray,
                        row.tests_per_frame,
                        samples.run_ms,
                    ),
                );
                report.rows.push(row);
            }
            if let (Some((rebuild, ..)), Some((lazy_ms, ..)), Some((cache_ms, ..))) = (
                by_config.get("rebuild"),
                by_config.get("lazy"),
                by_config.get("lazy+cache"),
            ) {
                println!(
                    "speed-up over rebuild: lazy {:.2}×, lazy+cache {:.2}× (medians over every frame)",
                    rebuild / lazy_ms,
                    rebuild / cache_ms,
                );
            }
            if let (Some((.., rebuild)), Some((.., cached))) =
                (by_config.get("rebuild"), by_config.get("lazy+cache"))
            {
                let ratios: Vec<f64> = rebuild.iter().zip(cached).map(|(r, c)| r / c).collect();
                let each: Vec<String> = ratios.iter().map(|r| format!("{r:.2}×")).collect();
                println!(
                    "lazy+cache over rebuild run by run (median frame of each, measured side by side): {} (median {:.2}×)",
                    each.join(", "),
                    median(ratios.clone()),
                );
            }
            if let (Some(&(_, plain, plain_all, _)), Some(&(_, cached, cached_all, _))) =
                (by_config.get("lazy"), by_config.get("lazy+cache"))
            {
                println!(
                    "cache (§4.2.2), lazy vs lazy+cache: camera rays {plain:.2} → {cached:.2} sphere + surfel tests/ray, the cache saves {:.1}%; all rays (shadows too) {:.0} → {:.0} tests/frame, {:.1}% saved",
                    100.0 * (1.0 - cached / plain.max(1e-12)),
                    plain_all,
                    cached_all,
                    100.0 * (1.0 - cached_all / plain_all.max(1e-12)),
                );
            }
        }
        for size in &args.sizes {
            let (w, h) = parse_size(size)?;
            let (plain, bounded) = oracle_bound(&demo, args.skip + args.frames / 2, (w, h));
            println!(
                "{size}, camera rays, lazy, one at a time, middle frame: {plain:.2} sphere + surfel tests/ray; given each ray's own hit distance in advance (an oracle: the best bound any cached hit of §4.2.2 could give) {bounded:.2}, {:.1}% saved",
                100.0 * (1.0 - bounded / plain.max(1e-12))
            );
        }
        if !args.no_tightness {
            let rows = tightness(&demo, args.skip + args.frames / 2, kind.name());
            println!("\nTightness at the middle frame (Fig. 3): average updated radius / smallest enclosing radius");
            println!(
                "| level | nodes | eq. 9 | eqs. 9 + 11 | eqs. 9 + 11, moved centres (in use) |"
            );
            println!("|---|---|---|---|---|");
            for r in &rows {
                println!(
                    "| {} | {} | {:.2} | {:.2} | {:.2} |",
                    r.level, r.nodes, r.eq9, r.eq9_11, r.moved
                );
            }
            report.tightness.extend(rows);
        }
    }
    if let Some(path) = &args.json {
        write_json(path, &report)?;
    }
    Ok(())
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or_else(|| format!("size {s}: expected WxH"))?;
    let p = |v: &str| v.parse::<u32>().map_err(|e| format!("size {s}: {e}"));
    Ok((p(w)?, p(h)?))
}

#[allow(clippy::too_many_arguments)]
/// One configuration's figures, gathered over the runs.
#[derive(Default)]
struct Samples {
    frame_ms: Vec<f64>,
    prepare_ms: Vec<f64>,
    /// The median frame of each run, in run order.
    run_ms: Vec<f64>,
    counters: SurfelCounters,
    rays: u64,
    modes: BTreeMap<String, usize>,
    touched: Vec<f64>,
}

/// One run: `args.frames` steps traced in order on a fresh runtime (an empty cache).
fn measure_run(
    backend: &CpuBackend,
    demo: &SurfelDemo,
    args: &SurfelsArgs,
    (w, h): (u32, u32),
    mode: UpdateMode,
    cache: bool,
    into: &mut Samples,
) {
    let view = View {
        width: w,
        height: h,
        camera: demo.camera,
        isovalue: 0.0,
    };
    let effects = Effects {
        shadows: true,
        ..Effects::OFF
    };
    let runtime = Arc::new(SurfelRuntime::default());
    let mut run = Vec::new();
    for k in args.skip..args.skip + args.frames {
        let start = Instant::now();
        let scene = Scene {
            geometry: Geometry::Surfels(demo.scene(
                k,
                SurfelOptions::new(mode, cache),
                runtime.clone(),
            )),
            lighting: Lighting::default(),
        };
        let prepared = Arc::new(scene).prepare();
        let prep = start.elapsed().as_secs_f64() * 1e3;
        let (_fb, frame_rays) = backend.render_effects(&prepared, &view, &effects);
        run.push(start.elapsed().as_secs_f64() * 1e3);
        into.prepare_ms.push(prep);
        let c = frame_rays.kinds.surfels;
        into.counters = add(into.counters, c);
        into.rays += c.rays;
        if let PreparedGeometry::Surfels(p) = prepared.geometry() {
            *into.modes.entry(p.used.name().to_string()).or_insert(0) += 1;
            into.touched
                .push(p.touched_surfels() as f64 / p.surfels.len().max(1) as f64);
        }
    }
    into.frame_ms.extend(&run);
    into.run_ms.push(median(run));
}

impl Samples {
    fn row(
        &self,
        demo: &SurfelDemo,
        args: &SurfelsArgs,
        scene: &'static str,
        (w, h): (u32, u32),
        name: &str,
    ) -> Row {
        let c = self.counters;
        Row {
            scene,
            surfels: demo.model.len(),
            nodes: demo.model.nodes.len(),
            size: format!("{w}x{h}"),
            config: name.to_string(),
            ms_per_frame: median(self.frame_ms.clone()),
            prepare_ms: median(self.prepare_ms.clone()),
            sphere_tests_per_ray: per(c.sphere_tests, self.rays),
            surfel_tests_per_ray: per(c.surfel_tests, self.rays),
            nearest_tests_per_ray: per(
                c.sphere_tests + c.surfel_tests - c.any_tests,
                c.rays - c.any_rays,
            ),
            tests_per_frame: (c.sphere_tests + c.surfel_tests) as f64
                / (args.runs * args.frames).max(1) as f64,
            rays: self.rays,
            modes: self.modes.clone(),
            touched: median(self.touched.clone()),
        }
    }
}

/// The ceiling of the per-pixel cache (§4.2.2) under this traversal: tests per camera ray
/// with no bound, and with each ray's own nearest-hit distance as its bound from the start
/// (what a perfectly cached hit gives), each on a freshly prepared lazy step traced one ray
/// at a time in pixel order.
fn oracle_bound(demo: &SurfelDemo, step: usize, (w, h): (u32, u32)) -> (f64, f64) {
    let fresh = || {
        PreparedSurfels::new(demo.scene(
            step,
            SurfelOptions::new(UpdateMode::Lazy, false),
            Arc::new(SurfelRuntime::default()),
        ))
    };
    let rays = demo.camera.rays(w, h);
    let (plain, bounded) = (fresh(), fresh());
    let (mut a, mut b) = (SurfelCounters::default(), SurfelCounters::default());
    for y in 0..h {
        for x in 0..w {
            let ray = rays.through_pixel(x, y);
            let hit = plain.nearest(&ray, 0.0, f32::INFINITY, None, &mut a);
            // Just beyond the hit: the bounded search still finds it.
            let bound = hit.map_or(f32::INFINITY, |h| h.t * (1.0 + 1e-5));
            let again = bounded.nearest(&ray, 0.0, bound, None, &mut b);
            assert_eq!(hit.map(|h| h.surfel), again.map(|h| h.surfel));
        }
    }
    (
        per(a.sphere_tests + a.surfel_tests, a.rays),
        per(b.sphere_tests + b.surfel_tests, b.rays),
    )
}

fn add(mut a: SurfelCounters, b: SurfelCounters) -> SurfelCounters {
    use isoray_render::geom::counters::KindCounters;
    a.add(&b);
    a
}

/// Fig. 3: per level, the mean of (eq. 9 radius), (min of eq. 9, eq. 11 bottom-up) and the engine's bound
/// ([`parent_sphere`] bottom-up) over the smallest sphere around the deformed surfel discs below.
fn tightness(demo: &SurfelDemo, step: usize, scene: &'static str) -> Vec<Tightness> {
    let runtime = Arc::new(SurfelRuntime::default());
    let p = PreparedSurfels::new(demo.scene(
        step,
        SurfelOptions::new(UpdateMode::Lazy, false),
        runtime,
    ));
    let model = &p.model;
    let tree = &model.tree;
    let deformed: Vec<_> = (0..model.len())
        .map(|s| deform_surfel(model, &p.u, &p.g, s))
        .collect();
    let n = tree.nodes.len();
    let mut eq9 = vec![(glam::Vec3::ZERO, 0f32); n];
    let mut both = vec![(glam::Vec3::ZERO, 0f32); n];
    let mut moved = vec![(glam::Vec3::ZERO, 0f32); n];
    for i in (0..n).rev() {
        let node = tree.nodes[i];
        if node.is_leaf() {
            let d = deformed[node.kids[1] as usize];
            eq9[i] = (d.centre, d.leaf_radius);
            both[i] = eq9[i];
            moved[i] = eq9[i];
        } else {
            eq9[i] = node_sphere(model, &p.step, i);
            let kids = node.kids.map(|k| both[k as usize]);
            both[i] = (eq9[i].0, eq9[i].1.min(radius_from_children(eq9[i].0, kids)));
            moved[i] = parent_sphere(eq9[i].0, eq9[i].1, node.kids.map(|k| moved[k as usize]));
        }
    }
    // Smallest spheres bottom-up need the surfels below each node: collect by preorder range.
    let mut sums: BTreeMap<usize, (usize, f64, f64, f64)> = BTreeMap::new();
    let mut stack = vec![(0usize, 0usize)];
    let mut below: Vec<u32> = Vec::new();
    while let Some((i, level)) = stack.pop() {
        let node = tree.nodes[i];
        if node.is_leaf() {
            continue;
        }
        below.clear();
        let mut s2 = vec![i];
        while let Some(k) = s2.pop() {
            let nk = tree.nodes[k];
            if nk.is_leaf() {
                below.push(nk.kids[1]);
            } else {
                s2.extend(nk.kids.map(|c| c as usize));
            }
        }
        // Cap the work on huge nodes: the top levels of the 150k object have few nodes.
        let pts: Vec<glam::Vec3> = below.iter().map(|&s| deformed[s as usize].centre).collect();
        let rho = below
            .iter()
            .map(|&s| deformed[s as usize].leaf_radius)
            .fold(0f32, f32::max);
        let best = miniball(&pts).radius + rho as f64;
        let e = sums.entry(level).or_insert((0, 0.0, 0.0, 0.0));
        e.0 += 1;
        e.1 += eq9[i].1 as f64 / best;
        e.2 += both[i].1 as f64 / best;
        e.3 += moved[i].1 as f64 / best;
        stack.extend(node.kids.map(|k| (k as usize, level + 1)));
    }
    sums.into_iter()
        .map(|(level, (count, a, b, m))| Tightness {
            scene,
            level,
            nodes: count,
            eq9: a / count as f64,
            eq9_11: b / count as f64,
            moved: m / count as f64,
        })
        .collect()
}
