//! The GPU backend: frames the kernel can trace go to the device, everything else (and every
//! frame after the device failed) to a CPU backend it keeps beside it, so a session always
//! gets its frames.
//!
//! On the GPU: ray casting and every effect of the plan (common.wgsl) for each kind whose
//! upload accepts the state (metaball states with a Fitted BVH and the marching finder; see
//! `kind_upload`: metaballs, tets and surfels) and plan (`check_plan`); anything else goes to
//! the CPU with the reason logged.

use crate::backend::accumulator::{FrameRays, Pass, TracePasses};
use crate::backend::cpu::CpuBackend;
use crate::backend::gpu::buffers::{FrameBuffers, GpuTimes};
use crate::backend::gpu::device::{AdapterChoice, GpuDevice, GpuError};
use crate::backend::gpu::upload;
use crate::effects::plan::EffectsPlan;
use crate::effects::rays::RayKind;
use crate::framebuffer::Framebuffer;
use crate::scene::PreparedScene;
use crate::shade::linear_to_srgb8;
use crate::view::View;
use glam::Vec3;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

/// The device and its buffers; `None` once the device failed.
struct Live {
    device: GpuDevice,
    buffers: FrameBuffers,
}

/// A wgpu device that traces what it can, and a CPU pool for the rest.
pub struct GpuBackend {
    cpu: CpuBackend,
    live: Mutex<Option<Live>>,
    name: String,
    /// Whether the device failed (the backend traces on the CPU from then on).
    failed: AtomicBool,
    /// Frames traced on the GPU, and frames the CPU traced instead.
    gpu_frames: AtomicU64,
    cpu_frames: AtomicU64,
    last_times: Mutex<GpuTimes>,
}

impl GpuBackend {
    /// A device chosen by `choice`, beside a CPU pool of `threads` workers (0: one per core)
    /// that runs the render jobs and traces what the GPU does not.
    pub fn new(threads: usize, choice: AdapterChoice) -> Result<GpuBackend, GpuError> {
        let cpu = CpuBackend::new(threads).map_err(|e| GpuError::Device(e.to_string()))?;
        let device = GpuDevice::new(choice)?;
        let name = device.describe();
        Ok(GpuBackend {
            cpu,
            live: Mutex::new(Some(Live {
                device,
                buffers: FrameBuffers::default(),
            })),
            name,
            failed: AtomicBool::new(false),
            gpu_frames: AtomicU64::new(0),
            cpu_frames: AtomicU64::new(0),
            last_times: Mutex::new(GpuTimes::default()),
        })
    }

    /// The adapter: name, type, API and driver.
    pub fn adapter(&self) -> &str {
        &self.name
    }

    /// The CPU pool beside the device.
    pub fn cpu(&self) -> &CpuBackend {
        &self.cpu
    }

    /// Whether the device failed and the CPU traces every frame now.
    pub fn has_failed(&self) -> bool {
        self.failed.load(Ordering::Acquire)
    }

    /// Frames traced on the GPU and on the CPU so far.
    pub fn frames(&self) -> (u64, u64) {
        (
            self.gpu_frames.load(Ordering::Relaxed),
            self.cpu_frames.load(Ordering::Relaxed),
        )
    }

    /// Upload and trace (with readback) times of the last GPU frame.
    pub fn last_times(&self) -> GpuTimes {
        self.last_times.lock().map(|t| *t).unwrap_or_default()
    }

    /// Buffers created on the device so far.
    pub fn allocations(&self) -> u64 {
        match self.live.lock() {
            Ok(live) => live.as_ref().map_or(0, |l| l.buffers.allocations),
            Err(_) => 0,
        }
    }

    /// Destroys the device as a lost device would be; the next frame finds out and moves to
    /// the CPU (the fallback's tests).
    pub fn lose_device(&self) {
        if let Ok(live) = self.live.lock() {
            if let Some(l) = live.as_ref() {
                l.device.destroy();
            }
        }
    }

    /// Per pixel linear colour and view-axis depth (< 0: a miss) from the GPU, or why not.
    /// `plan`: `None` for ray casting, else refinement pass `pass` with that plan.
    fn trace(
        &self,
        scene: &PreparedScene,
        view: &View,
        plan: Option<&EffectsPlan>,
        pass: u32,
    ) -> Result<Vec<[f32; 4]>, GpuError> {
        let mut guard = self
            .live
            .lock()
            .map_err(|_| GpuError::Failed("a render thread panicked".into()))?;
        let Some(live) = guard.as_mut() else {
            return Err(GpuError::Unsupported("the device failed earlier".into()));
        };
        if let Some(plan) = plan {
            upload::check_plan(plan).map_err(GpuError::Unsupported)?;
        }
        let kind = upload::kind_upload(scene, view, plan).map_err(GpuError::Unsupported)?;
        let frame = upload::frame(scene, view, plan, pass);
        let arrays = upload::lighting(scene.lighting_in_frame());
        let mut times = GpuTimes::default();
        let result = live
            .buffers
            .run(&live.device, &frame, kind, &arrays, &mut times);
        match result {
            Ok(pixels) => {
                if let Ok(mut t) = self.last_times.lock() {
                    *t = times;
                }
                Ok(pixels)
            }
            Err(e) => {
                // The device is of no further use: drop it and trace on the CPU from now on.
                *guard = None;
                self.failed.store(true, Ordering::Release);
                Err(e)
            }
        }
    }

    /// Logs why a frame went to the CPU: a warning when the device failed, a debug line when
    /// the kernel does not trace it yet.
    fn fell_back(&self, e: &GpuError) {
        self.cpu_frames.fetch_add(1, Ordering::Relaxed);
        match e {
            GpuError::Unsupported(why) => {
                tracing::debug!(reason = %why, "frame traced on the CPU");
            }
            GpuError::NoAdapter(_)
            | GpuError::SoftwareOnly(_)
            | GpuError::Device(_)
            | GpuError::Failed(_) => {
                tracing::warn!(error = %e, adapter = %self.name, "GPU failed; the CPU traces from now on");
            }
        }
    }
}

impl TracePasses for GpuBackend {
    fn render_primary(&self, scene: &PreparedScene, view: &View) -> Framebuffer {
        match self.trace(scene, view, None, 0) {
            Ok(pixels) => {
                self.gpu_frames.fetch_add(1, Ordering::Relaxed);
                let mut fb = Framebuffer::new(view.width, view.height);
                for (i, p) in pixels.iter().enumerate() {
                    fb.rgb[i * 3..i * 3 + 3]
                        .copy_from_slice(&[p[0], p[1], p[2]].map(linear_to_srgb8));
                    fb.depth[i] = if p[3] < 0.0 { f32::INFINITY } else { p[3] };
                }
                fb
            }
            Err(e) => {
                self.fell_back(&e);
                self.cpu.render_primary(scene, view)
            }
        }
    }

    fn trace_pass(
        &self,
        scene: &PreparedScene,
        view: &View,
        plan: &EffectsPlan,
        pass: u32,
    ) -> Pass {
        match self.trace(scene, view, Some(plan), pass) {
            Ok(pixels) => {
                self.gpu_frames.fetch_add(1, Ordering::Relaxed);
                let mut rays = FrameRays::default();
                rays.rays.add_n(RayKind::Primary, pixels.len() as u64);
                Pass {
                    color: pixels.iter().map(|p| Vec3::new(p[0], p[1], p[2])).collect(),
                    depth: pixels
                        .iter()
                        .map(|p| if p[3] < 0.0 { f32::INFINITY } else { p[3] })
                        .collect(),
                    rays,
                }
            }
            Err(e) => {
                self.fell_back(&e);
                self.cpu.trace_pass(scene, view, plan, pass)
            }
        }
    }
}
