//! The wgpu device, its queue and the trace pipeline: found once per backend. Errors the
//! device reports later (a lost device, an allocation that failed, a validation error) are
//! caught here instead of panicking (wgpu's default), and turn the device `broken`.

use crate::backend::gpu::kind::GpuKind;
use crate::backend::gpu::shader;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// Why the GPU backend could not start or could not trace.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter: {0}")]
    NoAdapter(String),
    #[error("no hardware GPU (only {0})")]
    SoftwareOnly(String),
    #[error("the GPU device could not be created: {0}")]
    Device(String),
    /// The frame needs something the kernel does not trace yet; the CPU traces it.
    #[error("{0}")]
    Unsupported(String),
    /// The device was lost or ran out of memory, or wgpu reported an error: the backend
    /// moves to the CPU for good.
    #[error("the GPU failed: {0}")]
    Failed(String),
}

/// Which adapters may serve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdapterChoice {
    /// The adapter wgpu prefers (`WGPU_BACKEND`, `WGPU_ADAPTER_NAME` honoured), a software
    /// one (lavapipe) included.
    Any,
    /// A hardware GPU only (`device_type` not `Cpu`): `--backend auto`.
    HardwareOnly,
}

/// One kind's trace pipeline and the layout of its bind group 1.
pub struct KindPipeline {
    pub pipeline: wgpu::ComputePipeline,
    pub kind_layout: wgpu::BindGroupLayout,
}

/// A device ready to trace.
pub struct GpuDevice {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// Bind group 0, the same for every kind: the frame, lights, materials, groups,
    /// isosurfaces and the output.
    pub common_layout: wgpu::BindGroupLayout,
    /// One pipeline per [`GpuKind`], in [`GpuKind::ALL`]'s order.
    pipelines: Vec<KindPipeline>,
    pub info: wgpu::AdapterInfo,
    /// Set by the device-lost and uncaptured-error callbacks.
    broken: Arc<AtomicBool>,
    error: Arc<Mutex<Option<String>>>,
}

impl GpuDevice {
    /// Finds an adapter, opens a device and compiles the kernel.
    pub fn new(choice: AdapterChoice) -> Result<GpuDevice, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = match choice {
            AdapterChoice::Any => pollster::block_on(
                wgpu::util::initialize_adapter_from_env_or_default(&instance, None),
            )
            .map_err(|e| GpuError::NoAdapter(e.to_string()))?,
            AdapterChoice::HardwareOnly => {
                let adapters =
                    pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
                let mut software = Vec::new();
                let mut hardware = None;
                for a in adapters {
                    let info = a.get_info();
                    if info.device_type == wgpu::DeviceType::Cpu {
                        software.push(info.name);
                    } else if hardware.is_none() {
                        hardware = Some(a);
                    }
                }
                match hardware {
                    Some(a) => a,
                    None if software.is_empty() => {
                        return Err(GpuError::NoAdapter("no adapter found".into()))
                    }
                    None => return Err(GpuError::SoftwareOnly(software.join(", "))),
                }
            }
        };
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("isoray"),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        let broken = Arc::new(AtomicBool::new(false));
        let error = Arc::new(Mutex::new(None));
        {
            let (broken, error) = (Arc::clone(&broken), Arc::clone(&error));
            device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
                record(&broken, &error, e.to_string());
            }));
        }
        {
            let (broken, error) = (Arc::clone(&broken), Arc::clone(&error));
            device.set_device_lost_callback(move |reason, message| {
                record(
                    &broken,
                    &error,
                    format!("device lost ({reason:?}): {message}"),
                );
            });
        }
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let common_layout = layout(&device, "isoray common", 4, true);
        let pipelines = GpuKind::ALL
            .iter()
            .map(|&kind| pipeline(&device, &common_layout, kind))
            .collect();
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Device(format!("the trace kernel: {e}")));
        }
        Ok(GpuDevice {
            device,
            queue,
            common_layout,
            pipelines,
            info,
            broken,
            error,
        })
    }

    /// The pipeline of `kind`.
    pub fn pipeline(&self, kind: GpuKind) -> &KindPipeline {
        let i = GpuKind::ALL.iter().position(|&k| k == kind).unwrap_or(0);
        &self.pipelines[i]
    }

    /// The adapter's name and driver, for logs.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}, {})",
            self.info.name, self.info.device_type, self.info.backend, self.info.driver
        )
    }

    /// Whether a callback reported the device lost or an uncaptured error; with the message.
    pub fn failure(&self) -> Option<String> {
        if !self.broken.load(Ordering::Acquire) {
            return None;
        }
        Some(
            self.error
                .lock()
                .ok()
                .and_then(|e| e.clone())
                .unwrap_or_else(|| "unknown error".into()),
        )
    }

    /// Destroys the device, as a lost device would be (tests of the fallback).
    pub fn destroy(&self) {
        self.device.destroy();
    }
}

fn record(broken: &AtomicBool, error: &Mutex<Option<String>>, message: String) {
    if let Ok(mut e) = error.lock() {
        e.get_or_insert(message);
    }
    broken.store(true, Ordering::Release);
}

/// A bind group layout: a uniform at binding 0, `arrays` read-only storage arrays after it,
/// and (with `output`) one read-write storage array last.
fn layout(
    device: &wgpu::Device,
    label: &str,
    arrays: usize,
    output: bool,
) -> wgpu::BindGroupLayout {
    let compute = wgpu::ShaderStages::COMPUTE;
    let storage = |binding: u32, read_only: bool| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: compute,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let mut entries = vec![wgpu::BindGroupLayoutEntry {
        binding: 0,
        visibility: compute,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }];
    for k in 0..arrays {
        entries.push(storage(k as u32 + 1, true));
    }
    if output {
        entries.push(storage(arrays as u32 + 1, false));
    }
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &entries,
    })
}

/// Compiles `kind`'s kernel (common.wgsl + the kind's part) with explicit layouts.
fn pipeline(device: &wgpu::Device, common: &wgpu::BindGroupLayout, kind: GpuKind) -> KindPipeline {
    let kind_layout = layout(device, kind.name(), kind.arrays(), false);
    let source = kind.kernel();
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(kind.name()),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(kind.name()),
        bind_group_layouts: &[Some(common), Some(&kind_layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(kind.name()),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(shader::ENTRY),
        compilation_options: Default::default(),
        cache: None,
    });
    KindPipeline {
        pipeline,
        kind_layout,
    }
}
