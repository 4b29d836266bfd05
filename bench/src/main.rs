//! `isoray-bench`: measures the engine against the figures of its seed papers.
//!
//! `isoray-bench metaballs` renders each Fitted-BVH paper scene (fitted-bvh-metaballs.txt §6,
//! Table 1) at 640×480 with primary rays only and prints, per acceleration mode (brute force,
//! the tutorial's sorted active list, the BVH with split metaballs, the Fitted BVH): build ms,
//! render ms and fps (medians over `--runs`), and the per-ray counters of the paper's Table 3.
//! A second table gives each root finder's mean iterations per hit under the Fitted BVH
//! (bezier-clipping-metaballs.txt §6 reports 2.0 for Bézier clipping). Brute force and the
//! active list cost O(N) per ray, so they trace every k-th row and scale the time up; the
//! table says so. See `bench/README.md`.

use clap::{Parser, Subcommand};
use isoray_render::metaball::tree::LeafCost;
use isoray_render::metaball::{AccelKind, BuildOptions, PrepareOptions, RayCounters, RootFinder};
use isoray_render::scene::PreparedGeometry;
use isoray_render::scenes::DemoScene;
use isoray_render::{PreparedScene, Scene};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;
/// Far limit of every ray, as in the integrator.
const T_MAX: f32 = 1.0e4;

#[derive(Parser)]
#[command(about = "isoray benchmarks")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The Fitted BVH paper's scenes: build and render times, Table 3 counters, root finders.
    Metaballs {
        /// Also write the results as JSON to this file.
        #[arg(long)]
        json: Option<std::path::PathBuf>,
        /// Scene ids (default: every paper scene).
        #[arg(long, value_delimiter = ',')]
        scenes: Vec<String>,
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
    },
    /// FBVH build time with each of the paper's steps switched off in turn (and the BVH).
    Build {
        /// Scene ids (default: every paper scene).
        #[arg(long, value_delimiter = ',')]
        scenes: Vec<String>,
        #[arg(long, default_value_t = 5)]
        runs: usize,
    },
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
    machine: String,
    threads: usize,
    finder: String,
    accel: Vec<AccelResult>,
    finders: Vec<FinderResult>,
}

fn main() {
    let cli = Cli::parse();
    match cli.command {
        Command::Build { scenes, runs } => build_ablation(&pick(&scenes), runs.max(1)),
        Command::Metaballs {
            json,
            scenes,
            runs,
            finder,
            no_finders,
            time,
        } => {
            let finder = match finder.as_str() {
                "bezier" => RootFinder::BezierClipping,
                "secant" => RootFinder::Secant,
                "march" => RootFinder::March,
                "sphere" => RootFinder::SphereTracing,
                other => {
                    eprintln!("unknown finder {other:?}: use bezier, secant, march or sphere");
                    std::process::exit(2);
                }
            };
            let demos = pick(&scenes);
            let report = metaballs(&demos, runs.max(1), finder, !no_finders, time);
            if let Some(path) = json {
                let text = serde_json::to_string_pretty(&report).expect("the report serialises");
                if let Err(e) = std::fs::write(&path, text) {
                    eprintln!("could not write {}: {e}", path.display());
                    std::process::exit(1);
                }
            }
        }
    }
}

fn pick(scenes: &[String]) -> Vec<DemoScene> {
    if scenes.is_empty() {
        return DemoScene::PAPER.to_vec();
    }
    let mut out = Vec::new();
    for id in scenes {
        match DemoScene::ALL.iter().find(|d| d.id() == id) {
            Some(&d) => out.push(d),
            None => {
                eprintln!("unknown scene {id:?}");
                std::process::exit(2);
            }
        }
    }
    out
}

/// Build ms (median) and 640×480 render ms of the FBVH with each step off, and of the BVH.
fn build_ablation(demos: &[DemoScene], runs: usize) {
    println!(
        "| scene | structure | build ms | render ms | nodes | leaves | owned/leaf | split/leaf |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|");
    for &demo in demos {
        let state = Arc::new(demo.state_at(1.0));
        let floor = demo.isovalue_slider().0;
        let full = BuildOptions::fitted(floor);
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
            ("BVH (split metaballs)", BuildOptions::bvh()),
        ];
        for (name, opts) in variants {
            let options = PrepareOptions::fitted(floor).with_accel(AccelKind::Tree(opts));
            let mut builds = Vec::new();
            let mut prepared = None;
            for _ in 0..runs {
                let started = Instant::now();
                let p = state.clone().prepare_with(options);
                builds.push(started.elapsed().as_secs_f64() * 1e3);
                prepared = Some(p);
            }
            let prepared = prepared.expect("at least one run");
            let (render_ms, _) = render(&prepared, demo, 1);
            let stats = match prepared.geometry() {
                PreparedGeometry::Metaballs(m) => m.tree_stats().unwrap_or_default(),
            };
            println!(
                "| {} | {name} | {:.2} | {:.1} | {} | {} | {:.2} | {:.2} |",
                demo.id(),
                median(builds),
                render_ms,
                stats.nodes,
                stats.leaves,
                stats.owned_per_leaf,
                stats.split_per_leaf
            );
        }
    }
}

fn machine() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    format!("{model}, {} threads", rayon::current_num_threads())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Traces every `stride`-th row of the 640×480 image: (ms, counters).
fn render(prepared: &PreparedScene, demo: DemoScene, stride: u32) -> (f64, RayCounters) {
    let rays = demo.default_camera().rays(WIDTH, HEIGHT);
    let isovalue = demo.default_isovalue();
    let started = Instant::now();
    let rows: Vec<u32> = (0..HEIGHT).step_by(stride as usize).collect();
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

fn per(n: u64, d: u64) -> f64 {
    n as f64 / d.max(1) as f64
}

fn metaballs(
    demos: &[DemoScene],
    runs: usize,
    finder: RootFinder,
    with_finders: bool,
    time: f64,
) -> Report {
    let machine = machine();
    println!("# isoray-bench metaballs\n");
    println!(
        "{machine}; 640×480 primary rays, Wyvill kernel, T = 0.5; acceleration table with {}; \
         medians of {runs} run(s).\n",
        finder.name()
    );
    let mut accel_rows = Vec::new();
    let mut finder_rows = Vec::new();
    for &demo in demos {
        let state = Arc::new(demo.state_at(time));
        let isovalue_floor = demo.isovalue_slider().0;
        let n = state.primitive_count();
        // O(N)-per-ray modes trace a subset of rows.
        let stride = ((n / 1500) as u32).clamp(1, 60);
        let modes: [(&str, AccelKind, u32); 4] = [
            ("brute force", AccelKind::BruteForce, stride),
            ("active list", AccelKind::ActiveList, stride),
            (
                "BVH (split metaballs)",
                AccelKind::Tree(BuildOptions::bvh()),
                1,
            ),
            (
                "FBVH",
                AccelKind::Tree(BuildOptions::fitted(isovalue_floor)),
                1,
            ),
        ];
        for (name, kind, stride) in modes {
            let options = PrepareOptions::fitted(isovalue_floor)
                .with_accel(kind)
                .with_finder(finder);
            let (row, _) = measure(&state, demo, name, options, stride, runs);
            eprintln!(
                "{:>15} {:<22} build {:>8.2} ms  render {:>9.1} ms",
                demo.id(),
                name,
                row.build_ms,
                row.render_ms
            );
            accel_rows.push(row);
        }
        if with_finders {
            for f in RootFinder::ALL {
                let options = PrepareOptions::fitted(isovalue_floor).with_finder(f);
                let (row, c) = measure(&state, demo, f.name(), options, 1, 1);
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
    print_tables(&accel_rows, &finder_rows);
    Report {
        machine,
        threads: rayon::current_num_threads(),
        finder: finder.name().into(),
        accel: accel_rows,
        finders: finder_rows,
    }
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
fn paper_table1(scene: &str) -> Option<(f64, f64, f64, f64)> {
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
    println!("| scene | balls | mode | build ms | render ms | fps | hits | traversals/ray | leaf tests/ray | metaballs/ray | iter/hit | paper build ms | paper fps |");
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
    let scenes: Vec<&str> = {
        let mut s: Vec<&str> = accel.iter().map(|r| r.scene.as_str()).collect();
        s.dedup();
        s
    };
    for scene in scenes {
        let get = |mode: &str| accel.iter().find(|r| r.scene == scene && r.accel == mode);
        if let (Some(f), Some(b), Some(a), Some(bf)) = (
            get("FBVH"),
            get("BVH (split metaballs)"),
            get("active list"),
            get("brute force"),
        ) {
            println!(
                "| {scene} | {:.2}× | {:.1}× | {:.1}× | {:.2} | {:.2} |",
                b.render_ms / f.render_ms,
                a.render_ms / f.render_ms,
                bf.render_ms / f.render_ms,
                f.build_ms,
                b.build_ms
            );
        }
    }
    println!("\nPaper, Table 3 (Tornado, per ray): BVH 9.3 traversals, 1.2 intersection tests, 83.5 metaballs; FBVH 6.2, 0.5, 35.1.");
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
        println!("\nPaper (bezier-clipping-metaballs.txt §6): Bézier clipping, 2.0 iterations per intersection.");
    }
}
