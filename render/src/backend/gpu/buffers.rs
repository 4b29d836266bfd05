//! The GPU buffers of a backend, reused from frame to frame: each grows (to the next power
//! of two) only when a frame needs more than it holds, and the scene's tree and balls are
//! uploaded only when the traced state changes. One frame: upload, one dispatch, readback.

use crate::backend::gpu::device::{GpuDevice, GpuError};
use crate::backend::gpu::layout::{GpuFrame, GpuGroup, GpuLight, GpuMaterial};
use crate::backend::gpu::shader::WORKGROUP;
use crate::backend::gpu::upload;
use crate::kinds::metaballs::engine::PreparedMetaballs;
use crate::kinds::metaballs::tree::Tree;
use std::sync::{mpsc, Arc};

/// A buffer and the bytes it holds.
struct Slot {
    buffer: wgpu::Buffer,
    capacity: u64,
}

/// Storage binding order of the kernel (bindings 1..=7; 0 is the frame's uniform).
const NODES: usize = 0;
const LEAF_BALLS: usize = 1;
const BALLS: usize = 2;
const LIGHTS: usize = 3;
const MATERIALS: usize = 4;
const GROUPS: usize = 5;
const PIXELS: usize = 6;
const STORAGE: usize = 7;

/// Every buffer a frame uses.
#[derive(Default)]
pub struct FrameBuffers {
    frame: Option<wgpu::Buffer>,
    storage: [Option<Slot>; STORAGE],
    readback: Option<Slot>,
    /// The state whose tree and balls are on the GPU (kept alive, so its address names it),
    /// and the address of the tree uploaded from it.
    uploaded: Option<(Arc<PreparedMetaballs>, usize)>,
    /// Buffers created so far (a test checks that an unchanged frame creates none).
    pub allocations: u64,
}

/// Time spent per stage of a frame, microseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuTimes {
    pub upload_us: u64,
    pub trace_us: u64,
}

impl FrameBuffers {
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

    /// Writes `data` at the start of storage slot `index`, growing it first if needed.
    fn put(&mut self, gpu: &GpuDevice, index: usize, data: &[u8]) -> Result<(), GpuError> {
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        Self::ensure(
            &gpu.device,
            &mut self.storage[index],
            &mut self.allocations,
            usage,
            data.len() as u64,
        );
        let slot = self.storage[index].as_ref().ok_or_else(no_buffer)?;
        if !data.is_empty() {
            gpu.queue.write_buffer(&slot.buffer, 0, data);
        }
        Ok(())
    }

    /// Traces one frame described by `frame` through `tree` of `metaballs` with `lighting`'s
    /// arrays, returning per pixel linear colour and depth along the view axis (< 0: a miss).
    pub fn run(
        &mut self,
        gpu: &GpuDevice,
        frame: &GpuFrame,
        metaballs: &Arc<PreparedMetaballs>,
        tree: &Tree,
        lighting: (&[GpuLight], &[GpuMaterial], &[GpuGroup]),
        times: &mut GpuTimes,
    ) -> Result<Vec<[f32; 4]>, GpuError> {
        let started = std::time::Instant::now();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let tree_key = tree as *const Tree as usize;
        let same = self
            .uploaded
            .as_ref()
            .is_some_and(|(m, key)| Arc::ptr_eq(m, metaballs) && *key == tree_key);
        if !same {
            let (nodes, leaf_balls) = upload::nodes(tree);
            let balls = upload::balls(metaballs.scene());
            self.put(gpu, NODES, bytemuck::cast_slice(&nodes))?;
            self.put(gpu, LEAF_BALLS, bytemuck::cast_slice(&leaf_balls))?;
            self.put(gpu, BALLS, bytemuck::cast_slice(&balls))?;
            self.uploaded = Some((Arc::clone(metaballs), tree_key));
        }
        let (lights, materials, groups) = lighting;
        self.put(gpu, LIGHTS, bytemuck::cast_slice(lights))?;
        self.put(gpu, MATERIALS, bytemuck::cast_slice(materials))?;
        self.put(gpu, GROUPS, bytemuck::cast_slice(groups))?;
        let pixels = frame.width as u64 * frame.height as u64;
        let out_bytes = pixels * 16;
        Self::ensure(
            &gpu.device,
            &mut self.storage[PIXELS],
            &mut self.allocations,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            out_bytes,
        );
        Self::ensure(
            &gpu.device,
            &mut self.readback,
            &mut self.allocations,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            out_bytes,
        );
        if self.frame.is_none() {
            self.frame = Some(gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("isoray frame"),
                size: std::mem::size_of::<GpuFrame>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
            self.allocations += 1;
        }
        let frame_buffer = self.frame.as_ref().ok_or_else(no_buffer)?;
        gpu.queue
            .write_buffer(frame_buffer, 0, bytemuck::bytes_of(frame));
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Failed(format!("allocation: {e}")));
        }
        times.upload_us = started.elapsed().as_micros() as u64;

        let started = std::time::Instant::now();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: frame_buffer.as_entire_binding(),
        }];
        for (k, slot) in self.storage.iter().enumerate() {
            let slot = slot.as_ref().ok_or_else(no_buffer)?;
            entries.push(wgpu::BindGroupEntry {
                binding: k as u32 + 1,
                resource: slot.buffer.as_entire_binding(),
            });
        }
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("isoray trace"),
            layout: &gpu.layout,
            entries: &entries,
        });
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            pass.set_pipeline(&gpu.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(
                frame.width.div_ceil(WORKGROUP),
                frame.height.div_ceil(WORKGROUP),
                1,
            );
        }
        let out = self.storage[PIXELS].as_ref().ok_or_else(no_buffer)?;
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
        times.trace_us = started.elapsed().as_micros() as u64;
        Ok(result)
    }
}

fn no_buffer() -> GpuError {
    GpuError::Failed("a buffer is missing".into())
}
