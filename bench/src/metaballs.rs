//! `isoray-bench metaballs` and `isoray-bench build`: the Fitted BVH paper's measurements.
//!
//! `metaballs` renders each scene of fitted-bvh-metaballs.txt §6 (Table 1) at 640×480 with
//! primary rays only and prints, per acceleration mode (brute force, the tutorial's sorted
//! active list, the BVH with split metaballs, the Fitted BVH): build ms, render ms and fps
//! (medians over `--runs`), and the per-ray counters of the paper's Table 3 (node traversals,
//! leaf intersection tests, metaballs considered). A second table gives each root finder's
//! mean iterations per hit under the Fitted BVH (bezier-clipping-metaballs.txt §6 reports
//! 2.0 for Bézier clipping). Brute force and the active list cost O(N) per ray: on scenes of
//! more than 10,000 balls they trace every k-th row and scale the time by k (the table says
//! so); at 10,000 balls and below they trace every pixel.
//!
//! `build` times the FBVH build with each of the paper's steps switched off in turn (§5.1.2
//! fitting, §5.3.1 tighter boxes, §5.3.2 discarding, the `n²` leaf cost), and the BVH.

use crate::common::{median, per, write_json, Machine};
use clap::Args;
use isoray_render::kinds::metaballs::tree::LeafCost;
use isoray_render::kinds::metaballs::{
    AccelKind, BuildOptions, PrepareOptions, RayCounters, RootFinder,
};
use isoray_render::scene::PreparedGeometry;
use isoray_render::scenes::DemoScene;
use isoray_render::{PreparedScene, Scene};
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

pub(crate) const WIDTH: u32 = 640;
pub(crate) const HEIGHT: u32 = 480;
/// Far limit of every ray, as in the integrator.
pub(crate) const T_MAX: f32 = 1.0e4;
/// Scenes up to this many balls are traced in full by the O(N)-per-ray modes.
const FULL_IMAGE_BALLS: usize = 10_000;

#[derive(Args)]
pub struct MetaballsArgs {
    /// Also write the results as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Scene ids (default: every paper scene).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Acceleration modes: brute, active, bvh, fbvh (default: all four).
    #[arg(long, value_delimiter = ',')]
    modes: Vec<String>,
    /// Timed runs per measurement; the median is reported.
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Root finder for the acceleration table: bezier, secant, march, sphere.
    #[arg(long, default_value = "bezier")]
    finder: String,
    /// Skip the root-finder table.
    #[arg(long)]
    no_finders: bool,
    /// Seconds of animation time at which the scenes are taken.
    #[arg(long, default_value_t = 1.0)]
    time: f64,
    /// Skip the packet table (single rays against 16×16 packets, 640×480 and 1920×1080).
    #[arg(long)]
    no_packets: bool,
    /// Only the packet table (no acceleration-mode or root-finder table).
    #[arg(long)]
    packets_only: bool,
}

#[derive(Args)]
pub struct BuildArgs {
    /// Scene ids (default: every paper scene).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Timed builds per variant; the median is reported.
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Also write the results as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Skip the render after each build (for profiling the build alone).
    #[arg(long)]
    no_render: bool,
    /// The SAH's traversal cost for every variant (default: the engine's).
    #[arg(long)]
    traversal_cost: Option<f32>,
    /// Only the variants whose names contain one of these (e.g. `all,BVH (`).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
}

#[derive(Serialize, Clone)]
struct AccelResult {
    scene: String,
    balls: usize,
    accel: String,
    build_ms: f64,
    render_ms: f64,
    fps: f64,
    /// 1 when every row was traced; k when every k-th row was traced and the time scaled.
    row_stride: u32,
    hit_fraction: f64,
    node_traversals_per_ray: f64,
    leaf_tests_per_ray: f64,
    metaballs_considered_per_ray: f64,
    iterations_per_hit: f64,
}

#[derive(Serialize, Clone)]
struct FinderResult {
    scene: String,
    finder: String,
    render_ms: f64,
    hit_fraction: f64,
    iterations_per_hit: f64,
    iterations_per_ray: f64,
}

#[derive(Serialize)]
struct Report {
    machine: Machine,
    finder: String,
    accel: Vec<AccelResult>,
    finders: Vec<FinderResult>,
    packets: Vec<crate::metaball_packets::PacketResult>,
}

#[derive(Serialize)]
struct BuildResult {
    scene: String,
    variant: String,
    build_ms: f64,
    render_ms: f64,
    nodes: usize,
    leaves: usize,
    mean_leaf_depth: f64,
    max_depth: usize,
    owned_per_leaf: f64,
    split_per_leaf: f64,
}

#[derive(Serialize)]
struct BuildReport {
    machine: Machine,
    builds: Vec<BuildResult>,
}

/// The four acceleration modes, in table order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Brute,
    Active,
    Bvh,
    Fbvh,
}

impl Mode {
    const ALL: [Mode; 4] = [Mode::Brute, Mode::Active, Mode::Bvh, Mode::Fbvh];

    fn parse(s: &str) -> Result<Mode, String> {
        match s {
            "brute" => Ok(Mode::Brute),
            "active" => Ok(Mode::Active),
            "bvh" => Ok(Mode::Bvh),
            "fbvh" => Ok(Mode::Fbvh),
            other => Err(format!(
                "unknown mode {other:?}: use brute, active, bvh or fbvh"
            )),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Mode::Brute => "brute force",
            Mode::Active => "active list",
            Mode::Bvh => "BVH (split metaballs)",
            Mode::Fbvh => "FBVH",
        }
    }

    fn accel(self, isovalue_floor: f32) -> AccelKind {
        match self {
            Mode::Brute => AccelKind::BruteForce,
            Mode::Active => AccelKind::ActiveList,
            Mode::Bvh => AccelKind::Tree(BuildOptions::bvh()),
            Mode::Fbvh => AccelKind::Tree(BuildOptions::fitted(isovalue_floor)),
        }
    }

    /// Rows between traced rows: O(N)-per-ray modes sample big scenes.
    fn row_stride(self, balls: usize) -> u32 {
        match self {
            Mode::Brute | Mode::Active if balls > FULL_IMAGE_BALLS => {
                ((balls / 2000) as u32).clamp(2, 60)
            }
            _ => 1,
        }
    }
}

fn parse_finder(s: &str) -> Result<RootFinder, String> {
    match s {
        "bezier" => Ok(RootFinder::BezierClipping),
        "secant" => Ok(RootFinder::Secant),
        "march" => Ok(RootFinder::March),
        "sphere" => Ok(RootFinder::SphereTracing),
        other => Err(format!(
            "unknown finder {other:?}: use bezier, secant, march or sphere"
        )),
    }
}

pub(crate) fn pick(scenes: &[String]) -> Result<Vec<DemoScene>, String> {
    if scenes.is_empty() {
        return Ok(DemoScene::PAPER.to_vec());
    }
    scenes
        .iter()
        .map(|id| {
            DemoScene::ALL
                .iter()
                .find(|d| d.id() == id)
                .copied()
                .ok_or_else(|| format!("unknown scene {id:?}"))
        })
        .collect()
}

/// Traces every `stride`-th row of the 640×480 image: (ms, counters).
pub(crate) fn render(prepared: &PreparedScene, demo: DemoScene, stride: u32) -> (f64, RayCounters) {
    // In the prepared scene's frame (the world's for every demo scene, which lie near it).
    let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
    let isovalue = demo.default_isovalue();
    let rows: Vec<u32> = (0..HEIGHT).step_by(stride as usize).collect();
    let started = Instant::now();
    let counters = rows
        .par_iter()
        .map(|&y| {
            let mut c = RayCounters::default();
            for x in 0..WIDTH {
                let ray = rays.through_pixel(x, y);
                let _ = prepared.first_hit_counted(&ray, 0.0, T_MAX, isovalue, &mut c);
            }
            c
        })
        .reduce(RayCounters::default, |mut a, b| {
            a.add(&b);
            a
        });
    (started.elapsed().as_secs_f64() * 1e3, counters)
}

pub fn run(args: MetaballsArgs) -> Result<(), String> {
    let finder = parse_finder(&args.finder)?;
    let demos = pick(&args.scenes)?;
    let modes = if args.modes.is_empty() {
        Mode::ALL.to_vec()
    } else {
        args.modes
            .iter()
            .map(|m| Mode::parse(m))
            .collect::<Result<_, _>>()?
    };
    let runs = args.runs.max(1);
    let machine = Machine::here();
    println!("# isoray-bench metaballs\n");
    println!(
        "{}; 640×480 primary rays, Wyvill kernel, T = 0.5; acceleration table with {}; \
         medians of {runs} run(s).\n",
        machine.line(),
        finder.name()
    );
    let mut accel_rows = Vec::new();
    let mut finder_rows = Vec::new();
    let packet_rows = if args.no_packets {
        Vec::new()
    } else {
        crate::metaball_packets::measure(&demos, runs, args.time)
    };
    for &demo in demos.iter().filter(|_| !args.packets_only) {
        let state = Arc::new(demo.state_at(args.time));
        let floor = demo.isovalue_slider().0;
        let n = state.primitive_count();
        for &mode in &modes {
            // The binary walk for every tree mode: the table compares the paper's two
            // structures node for node (Table 3's traversals); the four-wide walk single rays
            // take by default is measured in the packet table's single-ray rows.
            let options = PrepareOptions {
                wide: false,
                ..PrepareOptions::fitted(floor)
                    .with_accel(mode.accel(floor))
                    .with_finder(finder)
            };
            let (row, _) = measure(&state, demo, mode.name(), options, mode.row_stride(n), runs);
            eprintln!(
                "{:>15} {:<22} build {:>8.2} ms  render {:>9.1} ms",
                demo.id(),
                mode.name(),
                row.build_ms,
                row.render_ms
            );
            accel_rows.push(row);
        }
        if !args.no_finders {
            for f in RootFinder::ALL {
                let options = PrepareOptions::fitted(floor).with_finder(f);
                let (row, c) = measure(&state, demo, f.name(), options, 1, runs);
                finder_rows.push(FinderResult {
                    scene: demo.id().into(),
                    finder: f.name().into(),
                    render_ms: row.render_ms,
                    hit_fraction: row.hit_fraction,
                    iterations_per_hit: per(c.hit_iterations, c.hits),
                    iterations_per_ray: per(c.iterations, c.rays),
                });
                eprintln!(
                    "{:>15} finder {:<20} render {:>9.1} ms",
                    demo.id(),
                    f.name(),
                    row.render_ms
                );
            }
        }
    }
    if !args.packets_only {
        print_tables(&accel_rows, &finder_rows);
    }
    if !packet_rows.is_empty() {
        crate::metaball_packets::print(&packet_rows);
    }
    if let Some(path) = &args.json {
        write_json(
            path,
            &Report {
                machine,
                finder: finder.name().into(),
                accel: accel_rows,
                finders: finder_rows,
                packets: packet_rows,
            },
        )?;
    }
    Ok(())
}

fn measure(
    state: &Arc<Scene>,
    demo: DemoScene,
    name: &str,
    options: PrepareOptions,
    stride: u32,
    runs: usize,
) -> (AccelResult, RayCounters) {
    let mut builds = Vec::new();
    let mut renders = Vec::new();
    let mut counters = RayCounters::default();
    for _ in 0..runs {
        let started = Instant::now();
        let prepared = state.clone().prepare_with(options);
        builds.push(started.elapsed().as_secs_f64() * 1e3);
        let (ms, c) = render(&prepared, demo, stride);
        renders.push(ms * stride as f64);
        counters = c;
    }
    let render_ms = median(renders);
    let c = counters;
    (
        AccelResult {
            scene: demo.id().into(),
            balls: state.primitive_count(),
            accel: name.into(),
            build_ms: median(builds),
            render_ms,
            fps: 1e3 / render_ms,
            row_stride: stride,
            hit_fraction: per(c.hits, c.rays),
            node_traversals_per_ray: per(c.node_traversals, c.rays),
            leaf_tests_per_ray: per(c.leaf_tests, c.rays),
            metaballs_considered_per_ray: per(c.metaballs_considered, c.rays),
            iterations_per_hit: per(c.hit_iterations, c.hits),
        },
        c,
    )
}

/// Fitted BVH paper, Table 1: (BVH build ms, BVH avg fps, FBVH build ms, FBVH avg fps), an
/// Intel Core 2 E6600 building and an Nvidia GTX 280 rendering.
pub(crate) fn paper_table1(scene: &str) -> Option<(f64, f64, f64, f64)> {
    match scene {
        "scattered-30k" => Some((101.0, 7.4, 79.0, 9.4)),
        "scattered-100k" => Some((160.0, 3.3, 150.0, 4.3)),
        "tornado-4k" => Some((8.0, 4.6, 5.5, 11.0)),
        "tornado-128k" => Some((500.0, 1.0, 290.0, 2.4)),
        "molecule" => Some((8.9, 5.8, 9.9, 17.7)),
        "pool" => Some((41.0, 1.9, 40.0, 7.1)),
        _ => None,
    }
}

fn print_tables(accel: &[AccelResult], finders: &[FinderResult]) {
    println!("## Build and render, 640×480 primary rays\n");
    println!(
        "| scene | balls | mode | build ms | render ms | fps | hits | traversals/ray | \
         leaf tests/ray | metaballs/ray | iter/hit | paper build ms | paper fps |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in accel {
        let sampled = if r.row_stride > 1 {
            format!(" (every {}th row, ×{})", r.row_stride, r.row_stride)
        } else {
            String::new()
        };
        let paper = paper_table1(&r.scene);
        let (pb, pf) = match (r.accel.as_str(), paper) {
            ("BVH (split metaballs)", Some(p)) => (format!("{:.1}", p.0), format!("{:.1}", p.1)),
            ("FBVH", Some(p)) => (format!("{:.1}", p.2), format!("{:.1}", p.3)),
            _ => ("–".into(), "–".into()),
        };
        println!(
            "| {} | {} | {}{} | {:.2} | {:.1} | {:.2} | {:.0}% | {:.1} | {:.2} | {:.1} | {:.2} | {} | {} |",
            r.scene,
            r.balls,
            r.accel,
            sampled,
            r.build_ms,
            r.render_ms,
            r.fps,
            100.0 * r.hit_fraction,
            r.node_traversals_per_ray,
            r.leaf_tests_per_ray,
            r.metaballs_considered_per_ray,
            r.iterations_per_hit,
            pb,
            pf
        );
    }
    println!("\n## FBVH against the others (render time ratios, > 1: FBVH faster)\n");
    println!("| scene | vs BVH | vs active list | vs brute force | FBVH build ms | BVH build ms |");
    println!("|---|---:|---:|---:|---:|---:|");
    let mut scenes: Vec<&str> = accel.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    for scene in scenes {
        let get = |mode: Mode| {
            accel
                .iter()
                .find(|r| r.scene == scene && r.accel == mode.name())
        };
        let Some(f) = get(Mode::Fbvh) else {
            continue;
        };
        let ratio = |other: Option<&AccelResult>, digits: usize| {
            other.map_or("–".to_string(), |o| {
                format!("{:.*}×", digits, o.render_ms / f.render_ms)
            })
        };
        println!(
            "| {scene} | {} | {} | {} | {:.2} | {} |",
            ratio(get(Mode::Bvh), 2),
            ratio(get(Mode::Active), 1),
            ratio(get(Mode::Brute), 1),
            f.build_ms,
            get(Mode::Bvh).map_or("–".to_string(), |b| format!("{:.2}", b.build_ms)),
        );
    }
    println!(
        "\nPaper, Table 3 (Tornado, per ray): BVH 9.3 traversals, 1.2 intersection tests, \
         83.5 metaballs; FBVH 6.2, 0.5, 35.1."
    );
    if !finders.is_empty() {
        println!("\n## Root finders under the FBVH, 640×480\n");
        println!("| scene | finder | render ms | hits | iterations/hit | iterations/ray |");
        println!("|---|---|---:|---:|---:|---:|");
        for r in finders {
            println!(
                "| {} | {} | {:.1} | {:.0}% | {:.2} | {:.2} |",
                r.scene,
                r.finder,
                r.render_ms,
                100.0 * r.hit_fraction,
                r.iterations_per_hit,
                r.iterations_per_ray
            );
        }
        println!(
            "\nIterations: marching and sphere tracing count field evaluations, the secant \
             method its steps after the bracket, Bézier clipping its clips and splits; per hit \
             counts the search that found the hit. Paper (bezier-clipping-metaballs.txt §6): \
             Bézier clipping, 2.0 iterations per intersection."
        );
    }
}

/// Build ms (median) and 640×480 render ms of the FBVH with each step off, and of the BVH.
pub fn build_ablation(args: BuildArgs) -> Result<(), String> {
    let demos = pick(&args.scenes)?;
    let runs = args.runs.max(1);
    let machine = Machine::here();
    println!("# isoray-bench build\n");
    println!("{}; medians of {runs} build(s).\n", machine.line());
    println!(
        "| scene | structure | build ms | render ms | nodes | leaves | leaf depth (mean, max) | owned/leaf | split/leaf |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|");
    let mut rows = Vec::new();
    for &demo in &demos {
        let state = Arc::new(demo.state_at(1.0));
        let floor = demo.isovalue_slider().0;
        let full = BuildOptions {
            traversal_cost: args
                .traversal_cost
                .unwrap_or(BuildOptions::fitted(floor).traversal_cost),
            ..BuildOptions::fitted(floor)
        };
        let variants: [(&str, BuildOptions); 6] = [
            ("FBVH, all of §5", full),
            (
                "FBVH without fitting (§5.1.2)",
                BuildOptions {
                    fit_boxes: false,
                    ..full
                },
            ),
            (
                "FBVH without tight boxes (§5.3.1)",
                BuildOptions {
                    tight_boxes: false,
                    ..full
                },
            ),
            (
                "FBVH without discarding (§5.3.2)",
                BuildOptions {
                    discard_split: false,
                    ..full
                },
            ),
            (
                "FBVH with SAH leaf cost n",
                BuildOptions {
                    leaf_cost: LeafCost::Linear,
                    ..full
                },
            ),
            (
                "BVH (split metaballs)",
                BuildOptions {
                    traversal_cost: full.traversal_cost,
                    ..BuildOptions::bvh()
                },
            ),
        ];
        for (name, opts) in variants {
            if !args.only.is_empty() && !args.only.iter().any(|o| name.contains(o.as_str())) {
                continue;
            }
            let options = PrepareOptions::fitted(floor).with_accel(AccelKind::Tree(opts));
            let mut builds = Vec::new();
            let mut prepared = None;
            for _ in 0..runs {
                let started = Instant::now();
                let p = state.clone().prepare_with(options);
                builds.push(started.elapsed().as_secs_f64() * 1e3);
                prepared = Some(p);
            }
            let Some(prepared) = prepared else {
                continue;
            };
            let render_ms = if args.no_render {
                f64::NAN
            } else {
                render(&prepared, demo, 1).0
            };
            let stats = match prepared.geometry() {
                PreparedGeometry::Metaballs(m) => m.tree_stats().unwrap_or_default(),
                PreparedGeometry::Tets(_) | PreparedGeometry::Surfels(_) => Default::default(),
            };
            let row = BuildResult {
                scene: demo.id().into(),
                variant: name.into(),
                build_ms: median(builds),
                render_ms,
                nodes: stats.nodes,
                leaves: stats.leaves,
                mean_leaf_depth: stats.mean_leaf_depth,
                max_depth: stats.max_depth,
                owned_per_leaf: stats.owned_per_leaf,
                split_per_leaf: stats.split_per_leaf,
            };
            println!(
                "| {} | {name} | {:.2} | {:.1} | {} | {} | {:.1}, {} | {:.2} | {:.2} |",
                row.scene,
                row.build_ms,
                row.render_ms,
                row.nodes,
                row.leaves,
                row.mean_leaf_depth,
                row.max_depth,
                row.owned_per_leaf,
                row.split_per_leaf
            );
            rows.push(row);
        }
    }
    if let Some(path) = &args.json {
        write_json(
            path,
            &BuildReport {
                machine,
                builds: rows,
            },
        )?;
    }
    Ok(())
}
