//! `isoray-bench`: measures the engine against the figures of its seed papers. One binary,
//! one subcommand per study, each in its own module; `bench/README.md` says what each
//! measures and at what size.

mod accuracy;
mod common;
mod effects;
#[cfg(feature = "gpu")]
mod gpu;
mod ingest;
mod load;
mod load_cluster;
mod metaball_packets;
mod metaballs;
mod overlap;
mod sampling;
mod stream;
mod surfels;
mod tets;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(about = "isoray benchmarks (build with --release)")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The Fitted BVH paper's scenes: build and render times per acceleration mode, Table 3
    /// counters, root finders.
    Metaballs(metaballs::MetaballsArgs),
    /// FBVH build time with each of the paper's steps switched off in turn (and the BVH).
    Build(metaballs::BuildArgs),
    /// The tet paper's tables (§8): builds, fps, traversal counters, memory, time steps.
    Tets(tets::TetsArgs),
    /// Store ingest: MB/s of `.npy` steps pushed over loopback HTTP into the scene store.
    Ingest(ingest::IngestArgs),
    /// fps per secondary effect (the Fitted BVH paper's Table 2), rays per kind, and what
    /// an effect no material can use costs.
    Effects(effects::EffectsArgs),
    /// What accuracy costs in time: each root finder at a ladder of tolerances, render ms
    /// against the hit-distance error measured with the f64 reference.
    Accuracy(accuracy::AccuracyArgs),
    /// Streaming: codecs along a camera path; sessions over loopback websockets.
    Stream(stream::Args),
    /// Many websocket viewers driving their cameras against a running server or load
    /// balancer: per-viewer fps, input-to-frame latency percentiles and the frame size the
    /// server's adaptive controller settled on.
    Load(load::LoadArgs),
    /// One websocket viewer of an animated demo (default the 100,000-ball Scattered): frame
    /// interval against the headers' max(build, trace) and build + trace (issue 14, Fig. 7).
    Overlap(overlap::OverlapArgs),
    /// The deforming-surfels paper (§5, Fig. 3, Fig. 5): ms per frame for rebuild, eager
    /// refit, lazy and lazy + cache; tests per ray; radius tightness per level.
    Surfels(surfels::SurfelsArgs),
    /// What a resting view's accuracy costs in passes: soft shadows and occlusion with
    /// stratified against independent sample points, RMS error against a many-pass reference.
    Sampling(sampling::SamplingArgs),
    /// The GPU backend beside the CPU backend (feature `gpu`): the paper scenes, a million
    /// balls, the tet data sets and the surfel demos at 640×480 and 1920×1080, with upload,
    /// trace and readback apart.
    #[cfg(feature = "gpu")]
    Gpu(gpu::GpuArgs),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Metaballs(args) => metaballs::run(args),
        Command::Build(args) => metaballs::build_ablation(args),
        Command::Tets(args) => tets::run(args),
        Command::Ingest(args) => ingest::run(args),
        Command::Effects(args) => effects::run(args),
        Command::Accuracy(args) => accuracy::run(args),
        Command::Stream(args) => stream::run(args),
        Command::Load(args) => load::run(args),
        Command::Overlap(args) => overlap::run(args),
        Command::Surfels(args) => surfels::run(args),
        Command::Sampling(args) => sampling::run(args),
        #[cfg(feature = "gpu")]
        Command::Gpu(args) => gpu::run(args),
    };
    if let Err(e) = result {
        eprintln!("isoray-bench: {e}");
        std::process::exit(2);
    }
}
