//! The closed set of render backends and the one place that matches on it.
//!
//! The seam is the pass ([`TracePasses`]): a backend traces a frame of primary rays or one
//! pass of an effects plan; what is built from passes (effects frames, refinement) lives
//! above it in [`crate::backend::accumulator`], written once. The wgpu backend (feature
//! `gpu`) is the variant `Gpu(GpuBackend)`, its type in `backend/gpu/` implementing
//! [`TracePasses`].

use crate::backend::accumulator::{self, Accumulator, DeviceTimes, FrameRays, TracePasses};
use crate::backend::cpu::{CpuBackend, PoolError};
#[cfg(feature = "gpu")]
use crate::backend::gpu::backend::GpuBackend;
#[cfg(feature = "gpu")]
use crate::backend::gpu::device::{AdapterChoice, GpuError};
use crate::effects::toggles::Effects;
use crate::framebuffer::{Framebuffer, SurfaceBuffer};
use crate::scene::PreparedScene;
use crate::view::View;

/// The render backends, a closed set: the pass-level seam the server renders through. A new
/// backend (the wgpu one) is a new variant; each method dispatches here and nowhere else.
pub enum Backend {
    /// Tiles traced on a rayon pool of this machine's cores.
    Cpu(CpuBackend),
    /// Compute shaders on a wgpu device, with a CPU pool beside it for the render jobs and
    /// for what the kernel does not trace.
    /// (Boxed: the device and its buffers are far larger than a pool handle.)
    #[cfg(feature = "gpu")]
    Gpu(Box<GpuBackend>),
}

impl Backend {
    /// The CPU backend with `threads` workers (0: one per core).
    pub fn cpu(threads: usize) -> Result<Backend, PoolError> {
        Ok(Backend::Cpu(CpuBackend::new(threads)?))
    }

    /// The GPU backend on the adapter wgpu prefers (a software one such as lavapipe
    /// included), beside a CPU pool of `threads` workers, filling at most `memory_budget`
    /// bytes of the device.
    #[cfg(feature = "gpu")]
    pub fn gpu(threads: usize, memory_budget: u64) -> Result<Backend, GpuError> {
        Ok(Backend::Gpu(Box::new(GpuBackend::new(
            threads,
            AdapterChoice::Any,
            memory_budget,
        )?)))
    }

    /// A hardware GPU when there is one (`device_type` not `Cpu`; at most `memory_budget`
    /// bytes of it), else the CPU; with why the GPU was not taken.
    pub fn auto(
        threads: usize,
        #[cfg_attr(not(feature = "gpu"), allow(unused_variables))] memory_budget: u64,
    ) -> Result<(Backend, Option<String>), PoolError> {
        #[cfg(feature = "gpu")]
        {
            match GpuBackend::new(threads, AdapterChoice::HardwareOnly, memory_budget) {
                Ok(gpu) => Ok((Backend::Gpu(Box::new(gpu)), None)),
                Err(e) => Ok((Backend::cpu(threads)?, Some(e.to_string()))),
            }
        }
        #[cfg(not(feature = "gpu"))]
        {
            Ok((
                Backend::cpu(threads)?,
                Some("built without the `gpu` feature".into()),
            ))
        }
    }

    /// The backend's name, for logs and metrics.
    pub fn name(&self) -> &'static str {
        match self {
            Backend::Cpu(_) => "cpu",
            #[cfg(feature = "gpu")]
            Backend::Gpu(_) => "gpu",
        }
    }

    /// Worker threads that trace on the CPU.
    pub fn threads(&self) -> usize {
        match self {
            Backend::Cpu(cpu) => cpu.threads(),
            #[cfg(feature = "gpu")]
            Backend::Gpu(gpu) => gpu.cpu().threads(),
        }
    }

    /// Runs a render job (trace and encode of one frame) on the backend's workers without
    /// waiting for it.
    pub fn spawn(&self, job: impl FnOnce() + Send + 'static) {
        match self {
            Backend::Cpu(cpu) => cpu.spawn(job),
            #[cfg(feature = "gpu")]
            Backend::Gpu(gpu) => gpu.cpu().spawn(job),
        }
    }

    /// Renders one frame with primary rays only, blocking the caller until it is done.
    pub fn render(&self, scene: &PreparedScene, view: &View) -> Framebuffer {
        match self {
            Backend::Cpu(cpu) => cpu.render_primary(scene, view).0,
            #[cfg(feature = "gpu")]
            Backend::Gpu(gpu) => gpu.render_primary(scene, view).0,
        }
    }

    /// The primary hits' distances along the ray and outward normals, blocking (the
    /// `format: "npy"` output).
    pub fn render_surface(&self, scene: &PreparedScene, view: &View) -> SurfaceBuffer {
        match self {
            Backend::Cpu(cpu) => cpu.render_surface(scene, view),
            // Distances and normals are read back from the CPU's trace for now.
            #[cfg(feature = "gpu")]
            Backend::Gpu(gpu) => gpu.cpu().render_surface(scene, view),
        }
    }

    /// [`Backend::render_surface`] under `effects` (their clip box); see
    /// [`CpuBackend::render_surface_effects`].
    pub fn render_surface_effects(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
    ) -> SurfaceBuffer {
        match self {
            Backend::Cpu(cpu) => cpu.render_surface_effects(scene, view, effects),
            #[cfg(feature = "gpu")]
            Backend::Gpu(gpu) => gpu.cpu().render_surface_effects(scene, view, effects),
        }
    }

    /// Renders one frame with `effects` (its first refinement pass), blocking; see
    /// [`accumulator::render_effects`](crate::backend::accumulator::render_effects).
    pub fn render_effects(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
    ) -> (Framebuffer, FrameRays) {
        match self {
            Backend::Cpu(cpu) => accumulator::render_effects(cpu, scene, view, effects),
            #[cfg(feature = "gpu")]
            Backend::Gpu(gpu) => accumulator::render_effects(gpu.as_ref(), scene, view, effects),
        }
    }

    /// Adds one refinement pass to `accumulator`; see
    /// [`accumulator::refine`](crate::backend::accumulator::refine).
    pub fn refine(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
        accumulator: &mut Accumulator,
    ) -> Framebuffer {
        match self {
            Backend::Cpu(cpu) => accumulator::refine(cpu, scene, view, effects, accumulator),
            #[cfg(feature = "gpu")]
            Backend::Gpu(gpu) => {
                accumulator::refine(gpu.as_ref(), scene, view, effects, accumulator)
            }
        }
    }

    /// Refines until `accumulator` converges; see
    /// [`accumulator::refine_until_converged`](crate::backend::accumulator::refine_until_converged).
    pub fn refine_until_converged(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
        accumulator: &mut Accumulator,
    ) -> (Framebuffer, DeviceTimes) {
        match self {
            Backend::Cpu(cpu) => {
                accumulator::refine_until_converged(cpu, scene, view, effects, accumulator)
            }
            #[cfg(feature = "gpu")]
            Backend::Gpu(gpu) => {
                accumulator::refine_until_converged(gpu.as_ref(), scene, view, effects, accumulator)
            }
        }
    }
}
