//! `isoray-bench effects`: the cost of each secondary effect, in the shape of
//! fitted-bvh-metaballs.txt Table 2 (fps for ray casting, + hard shadows, + 1 and + 3
//! reflection levels), extended with soft shadows, occlusion and transparency, the rays of
//! each kind a frame traces, and what an effect costs on a scene whose materials cannot use
//! it (the effects plan must make that nothing).
//!
//! A frame is one pass of `--width`×`--height` (640×480 as in the paper) through
//! [`CpuBackend::render_effects`] on a pool of every core; fps is `1000 / median frame ms`
//! over `--runs` frames after one warm-up (one frame when the warm-up took over 10 s). Stochastic effects (soft shadows, occlusion) are
//! measured per pass, i.e. the interactive frame; a resting view accumulates such passes.
//!
//! Rows: ray cast; + hard shadows; + 1 and + 3 reflection levels (with shadows); + soft
//! shadows (4 rays per sphere light per pixel); + occlusion (4 rays per pixel); +
//! transparency (depth peeling, 4 layers, refraction off; also the clip box and further
//! isosurfaces where the scene has them); + refraction (Fresnel-weighted reflection and
//! refraction to depth 3 on top of that). Every row after the first has hard shadows on.
//!
//! Looks: the paper rendered its Table 2 scenes with reflective blobs (Fig. 8a,b), so the
//! paper scenes get mirror share 0.3 on their material, a sphere area light besides their
//! directional light (for soft shadows) and, for the transparency rows, opacity 0.5 with IOR
//! 1.3; the effects demos keep their own looks. The unused-effect rows use each scene's own,
//! unmodified look and switch on effects it cannot use: reflections with no reflective
//! material, refraction and transparency with no transparent one, shadows with every light
//! removed. Each pair is timed interleaved (off, on, off, on, …) and must trace the same
//! rays of every kind.

use crate::common::{demos, median, write_json, Machine};
use clap::Args;
use glam::Vec3;
use isoray_render::effects::available_effects;
use isoray_render::scenes::DemoScene;
use isoray_render::shade::{Light, Lighting};
use isoray_render::{
    CpuBackend, EffectKind, Effects, FrameRays, PreparedScene, RayKind, Scene, View,
};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct EffectsArgs {
    /// Also write the results as JSON to this file.
    #[arg(long)]
    json: Option<std::path::PathBuf>,
    /// Scene ids (default: molecule, tornado-4k, glass, shells, clouds, tets-gyroid).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    #[arg(long, default_value_t = 640)]
    width: u32,
    #[arg(long, default_value_t = 480)]
    height: u32,
    /// Timed frames per configuration; the median is reported.
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Timed frames per side of each unused-effect pair.
    #[arg(long, default_value_t = 9)]
    pair_runs: usize,
    /// Render threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Only these columns of the main table, by name without the "+ " (e.g.
    /// `transparency,refraction`; default: all); the unused-effect pairs are then skipped.
    #[arg(long, value_delimiter = ',')]
    configs: Vec<String>,
}

const DEFAULT_SCENES: [&str; 6] = [
    "molecule",
    "tornado-4k",
    "glass",
    "shells",
    "clouds",
    "tets-gyroid",
];

#[derive(Serialize, Clone)]
struct Row {
    scene: String,
    config: String,
    frame_ms: f64,
    fps: f64,
    /// Rays of each kind in one frame, in [`RayKind::ALL`] order.
    rays: Vec<(String, u64)>,
    /// Geometry queries (first hit, any hit, exit, optical depth) those rays made, and the
    /// root-finder iterations they spent (metaballs).
    queries: u64,
    iterations: u64,
    /// Metaball leaves searched and balls gathered for those searches (0 for other kinds).
    leaf_tests: u64,
    balls_gathered: u64,
}

#[derive(Serialize, Clone)]
struct Unused {
    scene: String,
    effect: String,
    off_ms: f64,
    on_ms: f64,
    overhead_percent: f64,
    rays_off: u64,
    rays_on: u64,
    same_rays_per_kind: bool,
}

#[derive(Serialize)]
struct Report {
    machine: Machine,
    width: u32,
    height: u32,
    rows: Vec<Row>,
    unused: Vec<Unused>,
}

/// Fitted BVH paper, Table 2 (avg fps; GTX 280): ray cast, hard shadows, + 1 reflection level,
/// + 3 reflection levels.
fn paper_table2(scene: &str) -> Option<[f64; 4]> {
    match scene {
        "molecule" => Some([22.3, 17.7, 12.7, 8.2]),
        "tornado-4k" => Some([5.7, 4.9, 3.4, 2.5]),
        _ => None,
    }
}

/// The configurations of the main table: name and effects.
fn configs() -> Vec<(&'static str, Effects)> {
    let off = Effects::OFF;
    let shadows = Effects {
        shadows: true,
        ..off
    };
    vec![
        ("ray cast", off),
        ("+ hard shadows", shadows),
        (
            "+ 1 reflection level",
            Effects {
                reflections: true,
                depth: 1,
                ..shadows
            },
        ),
        (
            "+ 3 reflection levels",
            Effects {
                reflections: true,
                depth: 3,
                ..shadows
            },
        ),
        (
            "+ soft shadows",
            Effects {
                soft_shadows: true,
                light_samples: 4,
                ..shadows
            },
        ),
        (
            "+ occlusion",
            Effects {
                ambient_occlusion: true,
                ao_samples: 4,
                ..shadows
            },
        ),
        (
            "+ transparency",
            Effects {
                transparency: true,
                clip_box: true,
                isosurfaces: true,
                layers: 4,
                ..shadows
            },
        ),
        (
            "+ refraction",
            Effects {
                transparency: true,
                refraction: true,
                clip_box: true,
                isosurfaces: true,
                depth: 3,
                layers: 4,
                ..shadows
            },
        ),
    ]
}

/// The look of the main table: the paper scenes made reflective (and, for the transparency
/// row, transparent) with an added sphere light; the effects demos as they are.
pub(crate) fn table_look(demo: DemoScene, state: &Scene, transparent: bool) -> Scene {
    if DemoScene::EFFECTS.contains(&demo) || demo == DemoScene::TetGyroid {
        return state.clone();
    }
    let mut lighting = state.lighting.clone();
    lighting.materials[0].reflectivity = 0.3;
    if transparent {
        lighting.materials[0].opacity = 0.5;
        lighting.materials[0].ior = 1.3;
    }
    let camera = demo.default_camera();
    let reach = (camera.eye - camera.target).length();
    lighting.lights.push(Light::Sphere {
        center: camera.target + Vec3::new(0.4, 0.8, 0.3) * reach,
        radius: 0.08 * reach,
        color: Vec3::splat(0.6 * reach * reach),
    });
    Scene {
        lighting,
        ..state.clone()
    }
}

fn frame_ms(
    backend: &CpuBackend,
    scene: &PreparedScene,
    view: &View,
    effects: &Effects,
) -> (f64, Vec<(String, u64)>, FrameRays) {
    let started = Instant::now();
    let (_, rays) = backend.render_effects(scene, view, effects);
    let ms = started.elapsed().as_secs_f64() * 1e3;
    let counts = RayKind::ALL
        .iter()
        .map(|&k| (k.name().to_string(), rays.rays.get(k)))
        .collect();
    (ms, counts, rays)
}

pub fn run(args: EffectsArgs) -> Result<(), String> {
    let demos = demos(&args.scenes, &DEFAULT_SCENES)?;
    let backend = CpuBackend::new(args.threads).map_err(|e| e.to_string())?;
    let machine = Machine {
        threads: backend.threads(),
        ..Machine::here()
    };
    let runs = args.runs.max(1);
    println!("# isoray-bench effects\n");
    println!(
        "{}; {}×{}, one pass per frame, medians of {runs} frames.\n",
        machine.line(),
        args.width,
        args.height
    );
    let mut rows = Vec::new();
    let mut unused = Vec::new();
    for &demo in &demos {
        let state = demo.state_at(1.0);
        let view = demo.default_view(args.width, args.height);
        let opaque = Arc::new(table_look(demo, &state, false)).prepare();
        let transparent = Arc::new(table_look(demo, &state, true)).prepare();
        for (name, effects) in configs() {
            if !args.configs.is_empty()
                && !args
                    .configs
                    .iter()
                    .any(|c| name.trim_start_matches("+ ") == c)
            {
                continue;
            }
            let scene = if name == "+ transparency" || name == "+ refraction" {
                &transparent
            } else {
                &opaque
            };
            let (warm_ms, _, _) = frame_ms(&backend, scene, &view, &effects);
            // Frames over 10 s (transparency through thousands of atoms) are timed once.
            let timed = if warm_ms > 10_000.0 { 1 } else { runs };
            let mut times = Vec::new();
            let mut counts = Vec::new();
            let mut frame = FrameRays::default();
            for _ in 0..timed {
                let (ms, c, f) = frame_ms(&backend, scene, &view, &effects);
                times.push(ms);
                counts = c;
                frame = f;
            }
            let ms = median(times);
            eprintln!("{:>12} {:<22} {:>9.1} ms", demo.id(), name, ms);
            rows.push(Row {
                scene: demo.id().into(),
                config: name.into(),
                frame_ms: ms,
                fps: 1e3 / ms,
                rays: counts,
                queries: frame.counters.rays,
                iterations: frame.counters.iterations,
                leaf_tests: frame.kinds.metaballs.leaf_tests,
                balls_gathered: frame.kinds.metaballs.metaballs_considered,
            });
        }
        if args.configs.is_empty() {
            unused.extend(unused_rows(
                &backend,
                demo,
                &state,
                &view,
                args.pair_runs.max(1),
            ));
        }
    }
    print_tables(&rows, &unused);
    if let Some(path) = &args.json {
        write_json(
            path,
            &Report {
                machine,
                width: args.width,
                height: args.height,
                rows,
                unused,
            },
        )?;
    }
    Ok(())
}

/// Effects the scene's own look cannot use, each timed against the same frame without it.
fn unused_rows(
    backend: &CpuBackend,
    demo: DemoScene,
    state: &Scene,
    view: &View,
    pair_runs: usize,
) -> Vec<Unused> {
    let own = Arc::new(state.clone()).prepare();
    let available = available_effects(&state.lighting, state.primitive_count());
    let base = state.lighting.effects;
    let mut pairs: Vec<(&str, PreparedScene, Effects, Effects)> = Vec::new();
    if !available.contains(&EffectKind::Reflections) {
        let on = Effects {
            reflections: true,
            depth: 3,
            ..base
        };
        pairs.push((
            "reflections (no reflective material)",
            own.clone(),
            base,
            on,
        ));
    }
    if !available.contains(&EffectKind::Refraction)
        && !available.contains(&EffectKind::Transparency)
    {
        let on = Effects {
            refraction: true,
            transparency: true,
            depth: 3,
            layers: 4,
            ..base
        };
        pairs.push((
            "refraction (no transparent material)",
            own.clone(),
            base,
            on,
        ));
    }
    let dark = Scene {
        lighting: Lighting {
            lights: Vec::new(),
            ..state.lighting.clone()
        },
        ..state.clone()
    };
    let dark_base = Effects {
        shadows: false,
        soft_shadows: false,
        ..base
    };
    pairs.push((
        "shadows (no light)",
        Arc::new(dark).prepare(),
        dark_base,
        Effects {
            shadows: true,
            soft_shadows: true,
            ..dark_base
        },
    ));
    let mut out = Vec::new();
    for (name, scene, off, on) in pairs {
        let _ = frame_ms(backend, &scene, view, &off);
        let _ = frame_ms(backend, &scene, view, &on);
        let (mut t_off, mut t_on) = (Vec::new(), Vec::new());
        let (mut c_off, mut c_on) = (Vec::new(), Vec::new());
        for _ in 0..pair_runs {
            let (ms, c, _) = frame_ms(backend, &scene, view, &off);
            t_off.push(ms);
            c_off = c;
            let (ms, c, _) = frame_ms(backend, &scene, view, &on);
            t_on.push(ms);
            c_on = c;
        }
        let (off_ms, on_ms) = (median(t_off), median(t_on));
        let total = |c: &[(String, u64)]| c.iter().map(|(_, n)| n).sum::<u64>();
        eprintln!(
            "{:>12} unused {:<38} {:>8.1} / {:>8.1} ms",
            demo.id(),
            name,
            off_ms,
            on_ms
        );
        out.push(Unused {
            scene: demo.id().into(),
            effect: name.into(),
            off_ms,
            on_ms,
            overhead_percent: 100.0 * (on_ms - off_ms) / off_ms,
            rays_off: total(&c_off),
            rays_on: total(&c_on),
            same_rays_per_kind: c_off == c_on,
        });
    }
    out
}

fn print_tables(rows: &[Row], unused: &[Unused]) {
    let configs: Vec<&str> = configs().iter().map(|c| c.0).collect();
    println!(
        "## Frames per second with each effect (the shape of fitted-bvh-metaballs.txt Table 2)\n"
    );
    let mut header = String::from("| scene |");
    for c in &configs {
        header.push_str(&format!(" {c} |"));
    }
    println!("{header} paper: ray cast / hard / +1 / +3 |");
    println!("|---|{}---|", "---:|".repeat(configs.len()));
    let mut scenes: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    for scene in &scenes {
        let mut line = format!("| {scene} |");
        for c in &configs {
            let fps = rows
                .iter()
                .find(|r| r.scene == *scene && r.config == *c)
                .map_or(0.0, |r| r.fps);
            line.push_str(&format!(" {fps:.2} |"));
        }
        let paper = paper_table2(scene).map_or("–".to_string(), |p| {
            format!("{} / {} / {} / {}", p[0], p[1], p[2], p[3])
        });
        println!("{line} {paper} |");
    }
    println!("\nPaper (Table 2, Nvidia GTX 280, 640×480): Molecule 22.3 / 17.7 / 12.7 / 8.2 fps, Tornado 5.7 / 4.9 / 3.4 / 2.5.");

    println!("\n## Rays per frame, by kind\n");
    let kinds: Vec<&str> = RayKind::ALL.iter().map(|k| k.name()).collect();
    println!(
        "| scene | configuration | {} | total | geometry queries | iterations | metaball leaves searched | balls gathered |",
        kinds.join(" | ")
    );
    println!(
        "|---|---|{}---:|---:|---:|---:|---:|",
        "---:|".repeat(kinds.len())
    );
    for r in rows {
        let counts: Vec<String> = r.rays.iter().map(|(_, n)| n.to_string()).collect();
        let total: u64 = r.rays.iter().map(|(_, n)| n).sum();
        println!(
            "| {} | {} | {} | {total} | {} | {} | {} | {} |",
            r.scene,
            r.config,
            counts.join(" | "),
            r.queries,
            r.iterations,
            r.leaf_tests,
            r.balls_gathered
        );
    }

    println!("\n## Effects the scene cannot use: switched on against off (interleaved medians)\n");
    println!("| scene | effect switched on | off ms | on ms | overhead | rays off | rays on | same rays per kind |");
    println!("|---|---|---:|---:|---:|---:|---:|---|");
    for u in unused {
        println!(
            "| {} | {} | {:.2} | {:.2} | {:+.2}% | {} | {} | {} |",
            u.scene,
            u.effect,
            u.off_ms,
            u.on_ms,
            u.overhead_percent,
            u.rays_off,
            u.rays_on,
            if u.same_rays_per_kind { "yes" } else { "NO" }
        );
    }
}
