//! `isoray-bench gpu` (feature `gpu`): the GPU backend beside the CPU backend, in the same
//! run, on the Fitted BVH paper's scenes, a million scattered balls, the tet paper's data set
//! stand-ins and the surfel demos, at 640×480 and 1920×1080 (primary rays, shaded).
//!
//! Per scene and size:
//! - CPU ms: the CPU backend's frame (the same prepared state);
//! - GPU, state unchanged: the frame's wall time and the device's upload, trace and readback
//!   (`DeviceTimes`), medians over `--runs` frames after one warm-up frame;
//! - GPU, a new state every frame (animated): the state's CPU build (update + acceleration
//!   structure), its upload (the kind's arrays built and written) and the whole frame
//!   (build + GPU frame), medians over `--runs` new states;
//! - the paper's figure to compare with: the Fitted BVH paper's GTX 280 fps (Table 1, FBVH
//!   column) for its scenes, the tet paper's 2-core laptop fps (Table 2) for its data sets.
//!
//! Frames the GPU refuses (over the memory budget, a plan it does not trace) are named with
//! the reason instead of timed. The adapter is printed with the table: on a machine without a
//! GPU, `WGPU_BACKEND=vulkan` runs it on lavapipe (software), which says nothing of GPU speed.

use crate::common::{median, write_json, Machine};
use clap::Args;
use isoray_render::backend::accumulator::TracePasses;
use isoray_render::backend::gpu::backend::DEFAULT_MEMORY_BUDGET;
use isoray_render::backend::gpu::{AdapterChoice, GpuBackend};
use isoray_render::camera::Camera;
use isoray_render::scene::{Geometry, Scene};
use isoray_render::scenes::{scattered_at, DemoScene};
use isoray_render::{CpuBackend, PreparedScene, View};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct GpuArgs {
    /// Also write the results as JSON to this file.
    #[arg(long)]
    json: Option<std::path::PathBuf>,
    /// Scenes (default: all): the demo ids of the paper scenes, tet and surfel demos,
    /// `scattered-1m`, and the tet data sets `tet:<id>` (ell32p, bucky, bluntfin, tjet,
    /// fusion, sf1).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Frame sizes, WIDTHxHEIGHT.
    #[arg(long, value_delimiter = ',', default_values_t = ["640x480".to_string(), "1920x1080".to_string()])]
    sizes: Vec<String>,
    /// Timed frames per measurement; the median is reported.
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Multiplies the tet data sets' tet counts (1: the paper's sizes).
    #[arg(long, default_value_t = 1.0)]
    tet_scale: f64,
    /// Skip the CPU column (for sizes where the CPU takes minutes).
    #[arg(long)]
    no_cpu: bool,
    /// GPU memory budget, MiB.
    #[arg(long, default_value_t = DEFAULT_MEMORY_BUDGET >> 20)]
    memory_mib: u64,
}

/// A scene to measure: its state at a time, and how it is viewed.
struct Case {
    id: String,
    state: Box<dyn Fn(f64) -> Scene>,
    camera: Camera,
    isovalue: f32,
    /// The paper's fps to compare with, and which figure it is.
    paper: Option<(f64, &'static str)>,
}

#[derive(Serialize)]
struct Row {
    scene: String,
    width: u32,
    height: u32,
    cpu_ms: Option<f64>,
    /// Static state: whole GPU frame, and its device stages.
    gpu_ms: Option<f64>,
    upload_ms: f64,
    trace_ms: f64,
    readback_ms: f64,
    /// A new state every frame: CPU build, upload, whole frame (build + GPU frame).
    build_ms: f64,
    new_state_upload_ms: f64,
    animated_ms: Option<f64>,
    paper_fps: Option<f64>,
    paper_what: Option<&'static str>,
    refused: Option<String>,
}

#[derive(Serialize)]
struct Report {
    machine: Machine,
    adapter: String,
    rows: Vec<Row>,
}

const DEFAULT_SCENES: [&str; 14] = [
    "scattered-30k",
    "scattered-100k",
    "tornado-4k",
    "tornado-128k",
    "molecule",
    "pool",
    "scattered-1m",
    "tets-gyroid",
    "tets-bucky",
    "tet:ell32p",
    "tet:bucky",
    "tet:bluntfin",
    "surfel-balls",
    "surfel-impact",
];

fn case(id: &str, tet_scale: f64) -> Result<Case, String> {
    if let Some(demo) = DemoScene::ALL.into_iter().find(|d| d.id() == id) {
        let paper = crate::metaballs::paper_table1(id).map(|p| (p.3, "GTX 280 fps (FBVH)"));
        return Ok(Case {
            id: id.into(),
            state: Box::new(move |t| demo.state_at(t)),
            camera: demo.default_camera(),
            isovalue: demo.default_isovalue(),
            paper,
        });
    }
    if id == "scattered-1m" {
        let lighting = DemoScene::Scattered100k.lighting();
        let (_, camera) = scattered_at(1_000_000, 0.0);
        return Ok(Case {
            id: id.into(),
            state: Box::new(move |t| Scene {
                geometry: Geometry::Metaballs(scattered_at(1_000_000, t).0),
                lighting: lighting.clone(),
            }),
            camera,
            isovalue: DemoScene::Scattered100k.default_isovalue(),
            paper: None,
        });
    }
    if let Some(set) = id.strip_prefix("tet:") {
        let (tets, camera, isovalue, laptop) = crate::tets::stand_in(set, tet_scale)
            .ok_or_else(|| format!("unknown tet data set {set:?}"))?;
        let lighting = DemoScene::TetGyroid.lighting();
        return Ok(Case {
            id: id.into(),
            // The stand-ins are one time step: every "new state" is the same data rebuilt.
            state: Box::new(move |_| Scene {
                geometry: Geometry::Tets(tets.clone()),
                lighting: lighting.clone(),
            }),
            camera,
            isovalue,
            paper: Some((laptop, "2-core laptop fps (tet paper, Table 2)")),
        });
    }
    Err(format!("unknown scene {id:?}"))
}

fn size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or_else(|| format!("size {s:?} is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| {
        v.parse::<u32>()
            .ok()
            .filter(|&n| (1..=8192).contains(&n))
            .ok_or_else(|| format!("size {s:?}: {v:?} is not a side in 1..=8192"))
    };
    Ok((parse(w)?, parse(h)?))
}

fn ms(us: u64) -> f64 {
    us as f64 / 1000.0
}

/// One scene at one size: the CPU frame, the GPU frame on an unchanged state, and the GPU
/// frame of a new state every time.
fn measure(
    gpu: &GpuBackend,
    cpu: &CpuBackend,
    c: &Case,
    (width, height): (u32, u32),
    args: &GpuArgs,
) -> Row {
    let view = View {
        width,
        height,
        camera: c.camera,
        isovalue: c.isovalue,
    };
    let prepare = |t: f64| -> PreparedScene { Arc::new((c.state)(t)).prepare() };
    let scene = prepare(1.0);
    let timed = |f: &dyn Fn()| {
        let t = Instant::now();
        f();
        t.elapsed().as_secs_f64() * 1e3
    };
    let cpu_ms = (!args.no_cpu).then(|| {
        median(
            (0..args.runs)
                .map(|_| timed(&|| drop(cpu.render_primary(&scene, &view))))
                .collect(),
        )
    });
    let mut row = Row {
        scene: c.id.clone(),
        width,
        height,
        cpu_ms,
        gpu_ms: None,
        upload_ms: 0.0,
        trace_ms: 0.0,
        readback_ms: 0.0,
        build_ms: 0.0,
        new_state_upload_ms: 0.0,
        animated_ms: None,
        paper_fps: c.paper.map(|p| p.0),
        paper_what: c.paper.map(|p| p.1),
        refused: None,
    };
    let (_, warm) = gpu.render_primary(&scene, &view);
    if warm.passes == 0 {
        row.refused = Some(gpu.last_fallback().unwrap_or_else(|| "refused".into()));
        return row;
    }
    let (mut wall, mut up, mut tr, mut rb) = (vec![], vec![], vec![], vec![]);
    for _ in 0..args.runs {
        let t = Instant::now();
        let (_, d) = gpu.render_primary(&scene, &view);
        wall.push(t.elapsed().as_secs_f64() * 1e3);
        up.push(ms(d.upload_us));
        tr.push(ms(d.trace_us));
        rb.push(ms(d.readback_us));
    }
    row.gpu_ms = Some(median(wall));
    (row.upload_ms, row.trace_ms, row.readback_ms) = (median(up), median(tr), median(rb));
    let (mut build, mut upload, mut whole) = (vec![], vec![], vec![]);
    for k in 0..args.runs {
        let t = Instant::now();
        let next = prepare(1.0 + 0.05 * (k + 1) as f64);
        let built = t.elapsed().as_secs_f64() * 1e3;
        let (_, d) = gpu.render_primary(&next, &view);
        whole.push(t.elapsed().as_secs_f64() * 1e3);
        build.push(built);
        upload.push(ms(d.upload_us));
    }
    row.build_ms = median(build);
    row.new_state_upload_ms = median(upload);
    row.animated_ms = Some(median(whole));
    row
}

pub fn run(args: GpuArgs) -> Result<(), String> {
    let ids: Vec<String> = if args.scenes.is_empty() {
        DEFAULT_SCENES.iter().map(|s| s.to_string()).collect()
    } else {
        args.scenes.clone()
    };
    let cases = ids
        .iter()
        .map(|id| case(id, args.tet_scale))
        .collect::<Result<Vec<_>, _>>()?;
    let sizes = args
        .sizes
        .iter()
        .map(|s| size(s))
        .collect::<Result<Vec<_>, _>>()?;
    let gpu = GpuBackend::new(0, AdapterChoice::Any, args.memory_mib << 20)
        .map_err(|e| format!("the GPU backend: {e}"))?;
    let cpu = CpuBackend::new(0).map_err(|e| e.to_string())?;
    let machine = Machine::here();
    println!("# isoray-bench gpu\n");
    println!("CPU: {}", machine.line());
    println!("GPU adapter: {}\n", gpu.adapter());
    println!(
        "| scene | size | CPU ms | GPU ms | upload | trace | readback | GPU fps | × CPU | \
         build (new state) | upload (new state) | animated ms | animated fps | paper fps | × paper |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut rows = Vec::new();
    for c in &cases {
        for &s in &sizes {
            let r = measure(&gpu, &cpu, c, s, &args);
            print_row(&r);
            rows.push(r);
        }
    }
    println!(
        "\npaper fps: the Fitted BVH paper's GTX 280 (Table 1, FBVH column) for its scenes, the \
         tet paper's 2-core laptop (Table 2) for the tet data sets."
    );
    let report = Report {
        machine,
        adapter: gpu.adapter().to_string(),
        rows,
    };
    if let Some(path) = &args.json {
        write_json(path, &report)?;
    }
    Ok(())
}

fn print_row(r: &Row) {
    let opt = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.1}"));
    if let Some(why) = &r.refused {
        println!(
            "| {} | {}×{} | {} | refused: {why} |||||||||||||",
            r.scene,
            r.width,
            r.height,
            opt(r.cpu_ms)
        );
        return;
    }
    let fps = r.gpu_ms.map(|m| 1e3 / m);
    let animated_fps = r.animated_ms.map(|m| 1e3 / m);
    println!(
        "| {} | {}×{} | {} | {} | {:.2} | {:.2} | {:.2} | {} | {} | {:.1} | {:.2} | {} | {} | {} | {} |",
        r.scene,
        r.width,
        r.height,
        opt(r.cpu_ms),
        opt(r.gpu_ms),
        r.upload_ms,
        r.trace_ms,
        r.readback_ms,
        opt(fps),
        opt(r.cpu_ms.zip(r.gpu_ms).map(|(c, g)| c / g)),
        r.build_ms,
        r.new_state_upload_ms,
        opt(r.animated_ms),
        opt(animated_fps),
        opt(r.paper_fps),
        opt(fps.zip(r.paper_fps).map(|(f, p)| f / p)),
    );
}
