//! The wgpu device, its queue and the trace pipeline: found once per backend. Errors the
//! device reports later (a lost device, an allocation that failed, a validation error) are
//! caught here instead of panicking (wgpu's default), and turn the device `broken`.

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

/// A device ready to trace.
pub struct GpuDevice {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
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
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("isoray metaballs"),
            source: wgpu::ShaderSource::Wgsl(shader::SOURCE.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("isoray trace"),
            layout: None,
            module: &module,
            entry_point: Some(shader::ENTRY),
            compilation_options: Default::default(),
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Device(format!("the trace kernel: {e}")));
        }
        let layout = pipeline.get_bind_group_layout(0);
        Ok(GpuDevice {
            device,
            queue,
            pipeline,
            layout,
            info,
            broken,
            error,
        })
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
