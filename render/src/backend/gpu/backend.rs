//! The GPU backend: frames the kernel can trace go to the device, everything else (and every
//! frame after the device failed) to a CPU backend it keeps beside it, so a session always
//! gets its frames.
//!
//! On the GPU: ray casting and every effect of the plan (common.wgsl) for each kind whose
//! upload accepts the state (`kind_upload`: metaballs with a Fitted BVH, traced with the
//! state's own root finder; tets; surfels), whose plan the kernel traces (`check_plan`) and
//! whose arrays fit the memory budget; anything else goes to the CPU with the reason logged.

use crate::backend::accumulator::{DeviceTimes, FrameRays, Pass, TracePasses};
use crate::backend::cpu::CpuBackend;
use crate::backend::gpu::buffers::{Budget, FrameBuffers};
use crate::backend::gpu::device::{AdapterChoice, GpuDevice, GpuError};
use crate::backend::gpu::{retrace, upload};
use crate::effects::plan::EffectsPlan;
use crate::effects::rays::RayKind;
use crate::framebuffer::Framebuffer;
use crate::scene::PreparedScene;
use crate::view::View;
use glam::Vec3;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

/// Sets of frame buffers: while one frame's kernel runs or its image is read back, the next
/// frame (another session's, or the same session's next one) uploads into the other set.
pub const SLOTS: usize = 2;

/// The GPU memory a backend may use unless told otherwise: 2 GiB (both buffer sets).
pub const DEFAULT_MEMORY_BUDGET: u64 = 2 << 30;

/// A wgpu device that traces what it can, and a CPU pool for the rest.
pub struct GpuBackend {
    cpu: CpuBackend,
    device: GpuDevice,
    /// The buffer sets; a frame takes the first free one, or waits for the one the rotation
    /// names.
    slots: [Mutex<FrameBuffers>; SLOTS],
    next_slot: AtomicUsize,
    /// What one buffer set may hold.
    budget: Budget,
    name: String,
    /// Whether the device failed (the backend traces on the CPU from then on).
    failed: AtomicBool,
    /// Frames traced on the GPU, and frames the CPU traced instead.
    gpu_frames: AtomicU64,
    cpu_frames: AtomicU64,
    /// Why the last frame the CPU traced instead did not go to the device.
    last_fallback: Mutex<Option<String>>,
}

impl GpuBackend {
    /// A device chosen by `choice`, beside a CPU pool of `threads` workers (0: one per core)
    /// that runs the render jobs and traces what the GPU does not; at most `memory_budget`
    /// bytes of scene arrays and frame buffers on the device (both buffer sets together).
    pub fn new(
        threads: usize,
        choice: AdapterChoice,
        memory_budget: u64,
    ) -> Result<GpuBackend, GpuError> {
        let cpu = CpuBackend::new(threads).map_err(|e| GpuError::Device(e.to_string()))?;
        let device = GpuDevice::new(choice)?;
        let name = device.describe();
        let budget = Budget {
            bytes: memory_budget / SLOTS as u64,
            max_binding: device.device.limits().max_storage_buffer_binding_size,
        };
        Ok(GpuBackend {
            cpu,
            device,
            slots: std::array::from_fn(|_| Mutex::new(FrameBuffers::default())),
            next_slot: AtomicUsize::new(0),
            budget,
            name,
            failed: AtomicBool::new(false),
            gpu_frames: AtomicU64::new(0),
            cpu_frames: AtomicU64::new(0),
            last_fallback: Mutex::new(None),
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

    /// Why the last frame traced on the CPU instead did not go to the device.
    pub fn last_fallback(&self) -> Option<String> {
        self.last_fallback.lock().ok().and_then(|w| w.clone())
    }

    /// Buffers created on the device so far, over both buffer sets.
    pub fn allocations(&self) -> u64 {
        self.slots
            .iter()
            .map(|s| s.lock().map_or(0, |b| b.allocations))
            .sum()
    }

    /// Destroys the device as a lost device would be; the next frame finds out and moves to
    /// the CPU (the fallback's tests).
    pub fn lose_device(&self) {
        self.device.destroy();
    }

    /// Holds buffer set `i` as a frame tracing on it would (tests of double buffering).
    #[cfg(test)]
    pub(crate) fn hold_slot(&self, i: usize) -> MutexGuard<'_, FrameBuffers> {
        self.slots[i].lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A buffer set for the next frame: the first free one (so a lone session keeps its
    /// state's arrays in one set and uploads them once), or, when every set is busy, the one
    /// whose turn it is, once its frame is done.
    fn slot(&self) -> Result<MutexGuard<'_, FrameBuffers>, GpuError> {
        for slot in &self.slots {
            if let Ok(guard) = slot.try_lock() {
                return Ok(guard);
            }
        }
        let turn = self.next_slot.fetch_add(1, Ordering::Relaxed);
        self.slots[turn % SLOTS]
            .lock()
            .map_err(|_| GpuError::Failed("a render thread panicked".into()))
    }

    /// Per pixel linear colour and view-axis depth (< 0: a miss) from the GPU, with the stage
    /// times, or why not. `plan`: `None` for ray casting, else refinement pass `pass` with
    /// that plan.
    fn trace(
        &self,
        scene: &PreparedScene,
        view: &View,
        plan: Option<&EffectsPlan>,
        pass: u32,
    ) -> Result<(Vec<[f32; 4]>, DeviceTimes), GpuError> {
        if self.has_failed() {
            return Err(GpuError::Unsupported("the device failed earlier".into()));
        }
        if let Some(plan) = plan {
            upload::check_plan(plan).map_err(GpuError::Unsupported)?;
        }
        let kind = upload::kind_upload(scene, view, plan).map_err(GpuError::Unsupported)?;
        let frame = upload::frame(scene, view, plan, pass);
        let arrays = upload::lighting(scene.lighting_in_frame());
        let mut times = DeviceTimes::default();
        let mut buffers = self.slot()?;
        match buffers.run(
            &self.device,
            &frame,
            kind,
            &arrays,
            &self.budget,
            &mut times,
        ) {
            Ok(pixels) => Ok((pixels, times)),
            Err(e @ GpuError::Unsupported(_)) => Err(e),
            Err(e) => {
                // The device is of no further use: free this set's buffers (the other set's
                // go with its next frame) and trace on the CPU from now on.
                *buffers = FrameBuffers::default();
                self.failed.store(true, Ordering::Release);
                Err(e)
            }
        }
    }

    /// Logs why a frame went to the CPU: a warning when the device failed, a debug line when
    /// the kernel does not trace it yet.
    fn fell_back(&self, e: &GpuError) {
        self.cpu_frames.fetch_add(1, Ordering::Relaxed);
        if let Ok(mut why) = self.last_fallback.lock() {
            *why = Some(e.to_string());
        }
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
    fn render_primary(&self, scene: &PreparedScene, view: &View) -> (Framebuffer, DeviceTimes) {
        match self.trace(scene, view, None, 0) {
            Ok((pixels, times)) => {
                self.gpu_frames.fetch_add(1, Ordering::Relaxed);
                let mut fb = Framebuffer::new(view.width, view.height);
                for (i, p) in pixels.iter().enumerate() {
                    fb.rgb[i * 3..i * 3 + 3]
                        .copy_from_slice(&crate::srgb::encode8_rgb([p[0], p[1], p[2]]));
                    fb.depth[i] = if p[3] < 0.0 { f32::INFINITY } else { p[3] };
                }
                (fb, times)
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
            Ok((mut pixels, device)) => {
                // The pixels the driver cut short (lavapipe's loop budget), by the CPU.
                retrace::retrace_cut(&mut pixels, scene, view, plan, pass);
                self.gpu_frames.fetch_add(1, Ordering::Relaxed);
                let mut rays = FrameRays {
                    device,
                    ..FrameRays::default()
                };
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
