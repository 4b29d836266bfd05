//! What the CI's Vulkan driver does that the kernel must live with, pinned on the smallest
//! kernel that shows it: lavapipe (Mesa's llvmpipe code generator) runs 8 invocations as one
//! SIMD group on a 256-bit CPU and gives the group ONE budget of 65,535 loop iterations for
//! all its loops together; once it is spent it ends every loop after its current iteration,
//! without an error. A pixel's loops therefore depend on its neighbours' (issue 12's layer
//! disagreements; common.wgsl `CUT`, retrace.rs). On any other adapter every loop finishes.

use std::sync::mpsc;

/// Invocations 0–3 count to `wanted[i]` in one branch, 4–7 in the other, so the group runs
/// the two loops one after the other.
const KERNEL: &str = r#"
@group(0) @binding(0) var<storage, read> wanted: array<u32>;
@group(0) @binding(1) var<storage, read_write> done: array<u32>;

@compute @workgroup_size(8, 1, 1)
fn main(@builtin(local_invocation_index) i: u32) {
    var n = 0u;
    if (i < 4u) {
        loop {
            if (n >= wanted[i]) {
                break;
            }
            n = n + 1u;
        }
    } else {
        loop {
            if (n >= wanted[i]) {
                break;
            }
            n = n + 1u;
        }
    }
    done[i] = n;
}
"#;

/// How far each of 8 invocations counted, wanting `wanted`; and the adapter's name.
fn count(wanted: [u32; 8]) -> ([u32; 8], String) {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
        &instance, None,
    ))
    .expect("a Vulkan adapter (lavapipe in CI)");
    let (device, queue) =
        pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
            .expect("a device");
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("loop budget"),
        source: wgpu::ShaderSource::Wgsl(KERNEL.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("loop budget"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let buffer = |usage| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: 32,
            usage,
            mapped_at_creation: false,
        })
    };
    let input = buffer(wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST);
    let output = buffer(wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC);
    let readback = buffer(wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
    queue.write_buffer(&input, 0, bytemuck::cast_slice(&wanted));
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: output.as_entire_binding(),
            },
        ],
    });
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(1, 1, 1);
    }
    encoder.copy_buffer_to_buffer(&output, 0, &readback, 0, 32);
    queue.submit([encoder.finish()]);
    let slice = readback.slice(..);
    let (tx, rx) = mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("the kernel ran");
    rx.recv().expect("mapped").expect("mapped");
    let view = slice.get_mapped_range().expect("the readback");
    let done: Vec<u32> = bytemuck::pod_collect_to_vec(&view[..]);
    (done.try_into().expect("8 counts"), adapter.get_info().name)
}

#[test]
fn lavapipe_ends_the_loops_of_8_invocations_once_they_ran_65535_iterations_together() {
    let (alone, name) = count([40_000, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(alone[0], 40_000, "{name}: one loop of 40,000 finishes");
    let (both, name) = count([40_000; 8]);
    eprintln!("{name}: {both:?}");
    if name.contains("llvmpipe") && name.contains("256 bits") {
        // The branch run first finishes; the other gets what is left of the budget.
        let (first, second) = (both[0].max(both[4]), both[0].min(both[4]));
        assert_eq!(first, 40_000, "{name}: {both:?}");
        assert!(
            (65_534..=65_536).contains(&(first + second)),
            "{name}: both loops together stop at the budget: {both:?}"
        );
        assert!(both[..4].iter().all(|&n| n == both[0]), "{both:?}");
        assert!(both[4..].iter().all(|&n| n == both[4]), "{both:?}");
    } else {
        assert_eq!(both, [40_000; 8], "{name}: every loop finishes");
    }
}
