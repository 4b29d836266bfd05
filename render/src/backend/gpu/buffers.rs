//! One set of GPU buffers, reused from frame to frame: each grows (to the next power of two)
//! only when a frame needs more than it holds, and a kind's arrays are uploaded only when the
//! traced state changes (its [`KindUpload::key`]). One frame: upload, one dispatch, readback.
//! The backend keeps two sets (double buffering, `backend.rs`).

use crate::backend::accumulator::DeviceTimes;
use crate::backend::gpu::device::{GpuDevice, GpuError};
use crate::backend::gpu::kind::{GpuKind, KindUpload};
use crate::backend::gpu::layout::GpuFrame;
use crate::backend::gpu::shader::WORKGROUP;
use crate::backend::gpu::upload::LightingArrays;
use std::any::Any;
use std::sync::{mpsc, Arc};

/// A buffer and the bytes it holds.
struct Slot {
    buffer: wgpu::Buffer,
    capacity: u64,
}

/// Storage bindings of group 0 (1..=5; 0 is the frame's uniform).
const LIGHTS: usize = 0;
const MATERIALS: usize = 1;
const GROUPS: usize = 2;
const ISOSURFACES: usize = 3;
const PIXELS: usize = 4;
const COMMON: usize = 5;

/// One kind's bind group 1: its uniform and arrays, and the key of the state they hold.
#[derive(Default)]
struct KindBuffers {
    params: Option<Slot>,
    arrays: Vec<Option<Slot>>,
    key: Option<(usize, u64)>,
    /// Bytes of the arrays `key` names.
    array_bytes: u64,
    /// The state `key` names, alive while its arrays are here.
    held: Option<Arc<dyn Any + Send + Sync>>,
    /// A state refused for the memory budget: its key, the frame's pixels, why, and the state
    /// (held so that its address names it alone), so that its arrays are not built again for
    /// every frame of that size or larger.
    refused: Option<Refusal>,
}

/// A state refused for the memory budget, and the frame size it was refused at.
struct Refusal {
    key: (usize, u64),
    pixels: u64,
    why: String,
    _held: Arc<dyn Any + Send + Sync>,
}

/// Every buffer a frame uses.
#[derive(Default)]
pub struct FrameBuffers {
    frame: Option<wgpu::Buffer>,
    common: [Option<Slot>; COMMON],
    readback: Option<Slot>,
    kinds: [KindBuffers; 3],
    /// Buffers created so far (a test checks that an unchanged frame creates none).
    pub allocations: u64,
}

/// What one set of buffers may hold on the device: `budget` bytes in all for a frame's
/// kind arrays, output and readback, and no array over `max_binding` (the device's largest
/// storage binding).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Budget {
    pub bytes: u64,
    pub max_binding: u64,
}

const MIB: f64 = 1024.0 * 1024.0;

/// Whether a frame with kind `arrays` and `pixels` output pixels fits `budget`, or why not.
fn check_budget(arrays: &[Vec<u8>], pixels: u64, budget: &Budget) -> Result<(), String> {
    if let Some(big) = arrays
        .iter()
        .map(|a| a.len() as u64)
        .find(|&n| n > budget.max_binding)
    {
        return Err(format!(
            "one of the scene's GPU arrays is {:.1} MiB, over the device's largest storage \
             binding of {:.1} MiB; the CPU traces it",
            big as f64 / MIB,
            budget.max_binding as f64 / MIB
        ));
    }
    let needed = arrays.iter().map(|a| a.len() as u64).sum::<u64>() + 2 * pixels * 16;
    if needed > budget.bytes {
        return Err(format!(
            "the scene needs {:.1} MiB of GPU memory per frame buffer, over the budget of \
             {:.1} MiB (--gpu-memory-mib, halved for double buffering); the CPU traces it",
            needed as f64 / MIB,
            budget.bytes as f64 / MIB
        ));
    }
    Ok(())
}

fn index(kind: GpuKind) -> usize {
    match kind {
        GpuKind::Metaballs => 0,
        GpuKind::Tets => 1,
        GpuKind::Surfels => 2,
    }
}

/// Makes `slot` hold at least `bytes` (never less than 16), reallocating only to grow.
fn ensure(
    device: &wgpu::Device,
    slot: &mut Option<Slot>,
    allocations: &mut u64,
    usage: wgpu::BufferUsages,
    bytes: u64,
) {
    let bytes = bytes.max(16);
    if slot.as_ref().is_some_and(|s| s.capacity >= bytes) {
        return;
    }
    let capacity = bytes.next_power_of_two();
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("isoray"),
        size: capacity,
        usage,
        mapped_at_creation: false,
    });
    *allocations += 1;
    *slot = Some(Slot { buffer, capacity });
}

/// Writes `data` at the start of `slot`, growing it first if needed.
fn put(
    gpu: &GpuDevice,
    slot: &mut Option<Slot>,
    allocations: &mut u64,
    usage: wgpu::BufferUsages,
    data: &[u8],
) -> Result<(), GpuError> {
    ensure(&gpu.device, slot, allocations, usage, data.len() as u64);
    let slot = slot.as_ref().ok_or_else(no_buffer)?;
    if !data.is_empty() {
        gpu.queue.write_buffer(&slot.buffer, 0, data);
    }
    Ok(())
}

const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_DST);
const UNIFORM: wgpu::BufferUsages = wgpu::BufferUsages::UNIFORM.union(wgpu::BufferUsages::COPY_DST);

impl FrameBuffers {
    /// Uploads what changed of the frame: the uniform, the lighting arrays, and the kind's
    /// uniform and (when its key changed) arrays.
    fn upload(
        &mut self,
        gpu: &GpuDevice,
        frame: &GpuFrame,
        kind: KindUpload<'_>,
        lighting: &LightingArrays,
        budget: &Budget,
    ) -> Result<(), GpuError> {
        let k = &mut self.kinds[index(kind.kind)];
        let pixels = frame.width as u64 * frame.height as u64;
        if let Some(r) = &k.refused {
            if r.key == kind.key && pixels >= r.pixels {
                return Err(GpuError::Unsupported(r.why.clone()));
            }
        }
        if k.key != Some(kind.key) {
            let arrays = (kind.arrays)();
            if let Err(why) = check_budget(&arrays, pixels, budget) {
                k.refused = Some(Refusal {
                    key: kind.key,
                    pixels,
                    why: why.clone(),
                    _held: kind.hold,
                });
                return Err(GpuError::Unsupported(why));
            }
            k.refused = None;
            k.arrays.resize_with(arrays.len(), || None);
            for (slot, data) in k.arrays.iter_mut().zip(&arrays) {
                put(gpu, slot, &mut self.allocations, STORAGE, data)?;
            }
            k.key = Some(kind.key);
            k.array_bytes = arrays.iter().map(|a| a.len() as u64).sum();
            k.held = Some(kind.hold);
        } else if k.array_bytes + 2 * pixels * 16 > budget.bytes {
            return Err(GpuError::Unsupported(format!(
                "a {}x{} frame of this scene needs more GPU memory than the budget of \
                 {:.1} MiB; the CPU traces it",
                frame.width,
                frame.height,
                budget.bytes as f64 / MIB
            )));
        }
        put(
            gpu,
            &mut k.params,
            &mut self.allocations,
            UNIFORM,
            &kind.params,
        )?;
        let allocations = &mut self.allocations;
        put(
            gpu,
            &mut self.common[LIGHTS],
            allocations,
            STORAGE,
            bytemuck::cast_slice(&lighting.lights),
        )?;
        put(
            gpu,
            &mut self.common[MATERIALS],
            allocations,
            STORAGE,
            bytemuck::cast_slice(&lighting.materials),
        )?;
        put(
            gpu,
            &mut self.common[GROUPS],
            allocations,
            STORAGE,
            bytemuck::cast_slice(&lighting.groups),
        )?;
        put(
            gpu,
            &mut self.common[ISOSURFACES],
            allocations,
            STORAGE,
            bytemuck::cast_slice(&lighting.isosurfaces),
        )?;
        let out_bytes = frame.width as u64 * frame.height as u64 * 16;
        ensure(
            &gpu.device,
            &mut self.common[PIXELS],
            allocations,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            out_bytes,
        );
        ensure(
            &gpu.device,
            &mut self.readback,
            allocations,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            out_bytes,
        );
        if self.frame.is_none() {
            self.frame = Some(gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("isoray frame"),
                size: std::mem::size_of::<GpuFrame>() as u64,
                usage: UNIFORM,
                mapped_at_creation: false,
            }));
            *allocations += 1;
        }
        let frame_buffer = self.frame.as_ref().ok_or_else(no_buffer)?;
        gpu.queue
            .write_buffer(frame_buffer, 0, bytemuck::bytes_of(frame));
        Ok(())
    }

    /// Traces one frame described by `frame` through `kind`'s state with `lighting`'s
    /// arrays, returning per pixel linear colour and depth along the view axis (< 0: a miss).
    /// A state or frame over `budget` is `Unsupported` (the CPU traces it), before anything
    /// is allocated for it.
    pub fn run(
        &mut self,
        gpu: &GpuDevice,
        frame: &GpuFrame,
        kind: KindUpload<'_>,
        lighting: &LightingArrays,
        budget: &Budget,
        times: &mut DeviceTimes,
    ) -> Result<Vec<[f32; 4]>, GpuError> {
        let started = std::time::Instant::now();
        let which = kind.kind;
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        self.upload(gpu, frame, kind, lighting, budget)?;
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Failed(format!("allocation: {e}")));
        }
        times.upload_us = started.elapsed().as_micros() as u64;

        let started = std::time::Instant::now();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let frame_buffer = self.frame.as_ref().ok_or_else(no_buffer)?;
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: frame_buffer.as_entire_binding(),
        }];
        for (k, slot) in self.common.iter().enumerate() {
            let slot = slot.as_ref().ok_or_else(no_buffer)?;
            entries.push(wgpu::BindGroupEntry {
                binding: k as u32 + 1,
                resource: slot.buffer.as_entire_binding(),
            });
        }
        let pipeline = gpu.pipeline(which);
        let common = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("isoray common"),
            layout: &gpu.common_layout,
            entries: &entries,
        });
        let k = &self.kinds[index(which)];
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: k
                .params
                .as_ref()
                .ok_or_else(no_buffer)?
                .buffer
                .as_entire_binding(),
        }];
        for (j, slot) in k.arrays.iter().enumerate() {
            let slot = slot.as_ref().ok_or_else(no_buffer)?;
            entries.push(wgpu::BindGroupEntry {
                binding: j as u32 + 1,
                resource: slot.buffer.as_entire_binding(),
            });
        }
        let kind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("isoray kind"),
            layout: &pipeline.kind_layout,
            entries: &entries,
        });
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            pass.set_pipeline(&pipeline.pipeline);
            pass.set_bind_group(0, &common, &[]);
            pass.set_bind_group(1, &kind_group, &[]);
            pass.dispatch_workgroups(
                frame.width.div_ceil(WORKGROUP),
                frame.height.div_ceil(WORKGROUP),
                1,
            );
        }
        let out_bytes = frame.width as u64 * frame.height as u64 * 16;
        let out = self.common[PIXELS].as_ref().ok_or_else(no_buffer)?;
        let readback = self.readback.as_ref().ok_or_else(no_buffer)?;
        encoder.copy_buffer_to_buffer(&out.buffer, 0, &readback.buffer, 0, out_bytes);
        gpu.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Failed(format!("trace: {e}")));
        }
        let slice = readback.buffer.slice(0..out_bytes);
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        gpu.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Failed(format!("poll: {e}")))?;
        times.trace_us = started.elapsed().as_micros() as u64;
        let started = std::time::Instant::now();
        rx.recv()
            .map_err(|_| GpuError::Failed("the readback was dropped".into()))?
            .map_err(|e| GpuError::Failed(format!("readback: {e}")))?;
        let result = {
            let view = slice
                .get_mapped_range()
                .map_err(|e| GpuError::Failed(format!("readback: {e}")))?;
            bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(&view[..])
        };
        readback.buffer.unmap();
        if let Some(failure) = gpu.failure() {
            return Err(GpuError::Failed(failure));
        }
        times.readback_us = started.elapsed().as_micros() as u64;
        times.passes = 1;
        Ok(result)
    }
}

fn no_buffer() -> GpuError {
    GpuError::Failed("a buffer is missing".into())
}
