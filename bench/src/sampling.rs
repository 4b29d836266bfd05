//! `isoray-bench sampling`: what a resting view's accuracy costs in passes, for the two ways
//! soft shadows and occlusion can draw their sample points (`Sampling` in the render crate's
//! `geom/rng.rs`): independent points in every pass, or the stratified sequence each pass
//! continues (the default).
//!
//! Per scene and effect, the mean of the first `N` passes (pixel centres, no antialiasing
//! jitter, so that only the sampling differs) is compared with a reference: the mean of
//! `--reference-passes` stratified passes after the `--passes` compared, so that it shares
//! no sample point with them (its own noise is printed: half the RMS difference of its two
//! halves). The table gives, for `N` = 1, 2, 4, … `--passes`, the RMS error of
//! each sampling in linear light and in 8-bit sRGB codes, the share of pixels more than 2
//! codes off, and the milliseconds the `N` passes took (both samplings trace the same rays);
//! then where a resting view's refinement would stop (the mean's change from one pass to the
//! next below `accumulator::DEFAULT_THRESHOLD`, the server's rule without antialiasing) and
//! how many stratified passes reach the error of `--passes` independent ones.
//! The golden tests check the same effects against an analytic reference that shares no code
//! with the engine (tests/tests/golden).

use crate::common::{demos, median, write_json, Machine};
use crate::effects::table_look;
use clap::Args;
use glam::Vec3;
use isoray_render::backend::accumulator::{plan_for, TracePasses, DEFAULT_THRESHOLD};
use isoray_render::geom::rng::Sampling;
use isoray_render::shade::linear_to_srgb8;
use isoray_render::{CpuBackend, Effects, EffectsPlan, PreparedScene, View};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct SamplingArgs {
    /// Also write the results as JSON to this file.
    #[arg(long)]
    json: Option<std::path::PathBuf>,
    /// Scene ids (default: glass, molecule, tets-gyroid, surfel-balls).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    #[arg(long, default_value_t = 320)]
    width: u32,
    #[arg(long, default_value_t = 240)]
    height: u32,
    /// The largest number of passes compared (a power of two).
    #[arg(long, default_value_t = 64)]
    passes: u32,
    /// Stratified passes averaged for the reference.
    #[arg(long, default_value_t = 1024)]
    reference_passes: u32,
    /// Render threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
}

const DEFAULT_SCENES: [&str; 4] = ["glass", "molecule", "tets-gyroid", "surfel-balls"];

#[derive(Serialize, Clone, Debug)]
struct Row {
    scene: String,
    effect: String,
    passes: u32,
    /// Milliseconds the passes took, stratified and independent.
    ms: [f64; 2],
    /// RMS error per channel in linear light, stratified and independent.
    rms_linear: [f64; 2],
    /// RMS error per channel in 8-bit sRGB codes.
    rms_codes: [f64; 2],
    /// Share of pixels with a channel more than 2 codes off.
    over_2_codes: [f64; 2],
}

#[derive(Serialize)]
struct Report {
    machine: Machine,
    width: u32,
    height: u32,
    reference_passes: u32,
    rows: Vec<Row>,
}

/// The effects compared: soft shadows alone, and occlusion alone.
fn effects() -> [(&'static str, Effects); 2] {
    [
        (
            "soft shadows",
            Effects {
                shadows: true,
                soft_shadows: true,
                ..Effects::OFF
            },
        ),
        (
            "occlusion",
            Effects {
                ambient_occlusion: true,
                ..Effects::OFF
            },
        ),
    ]
}

/// The running sum of passes `first..first + passes`, and what they cost.
struct Sum {
    sum: Vec<Vec3>,
    first: u32,
    passes: u32,
    ms: f64,
    /// Mean absolute change per channel the last pass made to the mean (the measure a
    /// resting view's refinement stops on, `Accumulator`).
    change: f64,
}

impl Sum {
    fn new(pixels: usize) -> Sum {
        Sum {
            sum: vec![Vec3::ZERO; pixels],
            first: 0,
            passes: 0,
            ms: 0.0,
            change: f64::INFINITY,
        }
    }

    fn add(
        &mut self,
        backend: &CpuBackend,
        scene: &PreparedScene,
        view: &View,
        plan: &EffectsPlan,
    ) {
        let started = Instant::now();
        let pass = backend.trace_pass(scene, view, plan, self.first + self.passes);
        self.ms += started.elapsed().as_secs_f64() * 1e3;
        let k = self.passes as f32;
        let mut change = 0.0f64;
        for (s, c) in self.sum.iter_mut().zip(&pass.color) {
            if k > 0.0 {
                change += ((*c - *s / k).abs() / (k + 1.0)).element_sum() as f64;
            }
            *s += *c;
        }
        if k > 0.0 {
            self.change = change / (3 * self.sum.len().max(1)) as f64;
        }
        self.passes += 1;
    }

    fn mean(&self) -> Vec<Vec3> {
        let k = self.passes.max(1) as f32;
        self.sum.iter().map(|s| *s / k).collect()
    }
}

/// RMS per channel in linear light, RMS in sRGB codes, share of pixels more than 2 codes off.
fn errors(image: &[Vec3], reference: &[Vec3]) -> (f64, f64, f64) {
    let (mut linear, mut codes, mut over) = (0.0f64, 0.0f64, 0usize);
    for (a, b) in image.iter().zip(reference) {
        let d = *a - *b;
        linear += d.length_squared() as f64;
        let mut worst = 0u8;
        for c in 0..3 {
            let k = linear_to_srgb8(a[c]).abs_diff(linear_to_srgb8(b[c]));
            codes += (k as f64).powi(2);
            worst = worst.max(k);
        }
        over += (worst > 2) as usize;
    }
    let n = reference.len().max(1) as f64;
    (
        (linear / (3.0 * n)).sqrt(),
        (codes / (3.0 * n)).sqrt(),
        over as f64 / n,
    )
}

pub fn run(args: SamplingArgs) -> Result<(), String> {
    if !args.passes.is_power_of_two() || args.reference_passes < 2 * args.passes {
        return Err("--passes must be a power of two, --reference-passes at least twice it".into());
    }
    let backend = CpuBackend::new(args.threads).map_err(|e| e.to_string())?;
    let machine = Machine {
        threads: backend.threads(),
        ..Machine::here()
    };
    println!("# isoray-bench sampling: {}", machine.line());
    let mut rows = Vec::new();
    for demo in demos(&args.scenes, &DEFAULT_SCENES)? {
        let id = demo.id();
        let state = demo.state_at(1.0);
        let scene = Arc::new(table_look(demo, &state, false)).prepare();
        let view = demo.default_view(args.width, args.height);
        for (effect, effects) in effects() {
            let plan = plan_for(&scene, &effects);
            if !plan.is_stochastic() {
                println!(
                    "{id:>12} {effect:<13} not sampled on this scene (no sphere light or ambient)"
                );
                continue;
            }
            rows.extend(compare(&backend, &scene, &view, plan, id, effect, &args));
        }
    }
    if let Some(path) = &args.json {
        let report = Report {
            machine,
            width: args.width,
            height: args.height,
            reference_passes: args.reference_passes,
            rows,
        };
        write_json(path, &report)?;
    }
    Ok(())
}

/// The table of one scene and effect.
fn compare(
    backend: &CpuBackend,
    scene: &PreparedScene,
    view: &View,
    plan: EffectsPlan,
    id: &str,
    effect: &str,
    args: &SamplingArgs,
) -> Vec<Row> {
    let pixels = (view.width * view.height) as usize;
    let stratified = EffectsPlan {
        sampling: Sampling::Stratified,
        ..plan
    };
    let independent = EffectsPlan {
        sampling: Sampling::Independent,
        ..plan
    };
    // The reference, in two halves for its own noise, from passes after those compared
    // (`passes..`): it shares no sample point with the images it judges.
    let half = args.reference_passes / 2;
    let mut halves = [Sum::new(pixels), Sum::new(pixels)];
    halves[0].first = args.passes;
    halves[1].first = args.passes + half;
    for sum in &mut halves {
        for _ in 0..half {
            sum.add(backend, scene, view, &stratified);
        }
    }
    let [a, b] = [halves[0].mean(), halves[1].mean()];
    let reference: Vec<Vec3> = a.iter().zip(&b).map(|(p, q)| (*p + *q) * 0.5).collect();
    let (noise, noise_codes, _) = errors(&a, &b);
    let pass_ms = median(vec![halves[0].ms / half as f64, halves[1].ms / half as f64]);
    println!(
        "{id:>12} {effect:<13} {}x{}: reference {} stratified passes ({pass_ms:.1} ms a pass), \
         its own RMS error about {:.2e} linear, {:.2} codes",
        view.width,
        view.height,
        args.reference_passes,
        noise / 2.0,
        noise_codes / 2.0
    );
    println!(
        "{:>12} {:<13} {:>6} {:>9} {:>9} {:>12} {:>12} {:>8} {:>8} {:>9} {:>9}",
        "scene",
        "effect",
        "passes",
        "ms strat",
        "ms indep",
        "RMS strat",
        "RMS indep",
        "codes s",
        "codes i",
        ">2 s",
        ">2 i"
    );
    let mut sums = [Sum::new(pixels), Sum::new(pixels)];
    // Where the server's rule (the mean's change below its threshold) would stop, and the
    // RMS error there.
    let mut stops: [Option<(u32, f64)>; 2] = [None, None];
    let mut rows = Vec::new();
    let mut n = 1;
    while n <= args.passes {
        for ((sum, plan), stop) in sums
            .iter_mut()
            .zip([&stratified, &independent])
            .zip(&mut stops)
        {
            while sum.passes < n {
                sum.add(backend, scene, view, plan);
                if stop.is_none() && sum.change < DEFAULT_THRESHOLD as f64 {
                    *stop = Some((sum.passes, errors(&sum.mean(), &reference).0));
                }
            }
        }
        let [(ls, cs, os), (li, ci, oi)] = [
            errors(&sums[0].mean(), &reference),
            errors(&sums[1].mean(), &reference),
        ];
        let row = Row {
            scene: id.to_string(),
            effect: effect.to_string(),
            passes: n,
            ms: [sums[0].ms, sums[1].ms],
            rms_linear: [ls, li],
            rms_codes: [cs, ci],
            over_2_codes: [os, oi],
        };
        println!(
            "{:>12} {:<13} {:>6} {:>9.0} {:>9.0} {:>12.3e} {:>12.3e} {:>8.2} {:>8.2} {:>8.2}% {:>8.2}%",
            id, effect, n, row.ms[0], row.ms[1], ls, li, cs, ci, 100.0 * os, 100.0 * oi
        );
        rows.push(row);
        n *= 2;
    }
    let stop = |s: Option<(u32, f64)>| match s {
        Some((n, rms)) => format!("after {n} passes (RMS {rms:.3e})"),
        None => format!("not within {} passes", args.passes),
    };
    println!(
        "{id:>12} {effect:<13} a resting view's refinement (mean change below {:.0e}) stops: \
         stratified {}, independent {}",
        DEFAULT_THRESHOLD,
        stop(stops[0]),
        stop(stops[1])
    );
    let last = rows.last().map_or(0.0, |r| r.rms_linear[1]);
    match rows.iter().find(|r| r.rms_linear[0] <= last) {
        Some(r) => println!(
            "{id:>12} {effect:<13} stratified reaches {} independent passes' RMS error in {} passes",
            args.passes, r.passes
        ),
        None => println!("{id:>12} {effect:<13} stratified does not reach {} independent passes' error", args.passes),
    }
    rows
}
