//! The adapter (Vulkan, else GL), device and queue.

use super::*;

/// True for adapters that run on the CPU (lavapipe, llvmpipe, SwiftShader).
pub fn is_software(info: &wgpu::AdapterInfo) -> bool {
    let name = info.name.to_lowercase();
    info.device_type == wgpu::DeviceType::Cpu
        || ["llvmpipe", "lavapipe", "softpipe", "swiftshader"]
            .iter()
            .any(|s| name.contains(s))
}

/// An adapter, its device and queue.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    /// Errors wgpu reported outside an error scope (instead of its default panic).
    pub(super) uncaptured: Arc<Mutex<Vec<String>>>,
}

impl GpuContext {
    /// The best adapter: discrete, integrated, virtual, then software (only when
    /// `allow_software`); Vulkan, else GL.
    pub fn new(allow_software: bool) -> Result<Self, GpuError> {
        // Vulkan first; GL (which probes EGL and window systems) only when Vulkan has nothing.
        let mut adapters = Vec::new();
        for backends in [wgpu::Backends::VULKAN, wgpu::Backends::GL] {
            let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
                backends,
                ..wgpu::InstanceDescriptor::new_without_display_handle()
            });
            adapters.extend(pollster::block_on(instance.enumerate_adapters(backends)));
            if adapters
                .iter()
                .any(|a| allow_software || !is_software(&a.get_info()))
            {
                break;
            }
        }
        let rank = |info: &wgpu::AdapterInfo| {
            let kind = match info.device_type {
                _ if is_software(info) => 4,
                wgpu::DeviceType::DiscreteGpu => 0,
                wgpu::DeviceType::IntegratedGpu => 1,
                wgpu::DeviceType::VirtualGpu => 2,
                _ => 3,
            };
            (kind, u8::from(info.backend != wgpu::Backend::Vulkan))
        };
        let found: Vec<String> = adapters.iter().map(|a| describe(&a.get_info())).collect();
        let adapter = adapters
            .into_iter()
            .filter(|a| allow_software || !is_software(&a.get_info()))
            .min_by_key(|a| rank(&a.get_info()));
        let Some(adapter) = adapter else {
            return Err(if found.is_empty() {
                GpuError::NoAdapter
            } else {
                GpuError::OnlySoftware {
                    found: found.join("; "),
                }
            });
        };
        let info = adapter.get_info();
        let limits = adapter.limits();
        if limits.max_storage_buffers_per_shader_stage < 7 {
            return Err(GpuError::Device {
                adapter: describe(&info),
                what: format!(
                    "needs 7 storage buffers per shader stage, the adapter has {}",
                    limits.max_storage_buffers_per_shader_stage
                ),
            });
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("harmonic"),
            // The stage clock's timestamps, where the adapter has them.
            required_features: adapter.features() & super::clock::FEATURES,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: describe(&info),
            what: e.to_string(),
        })?;
        Ok(Self::from_device(device, queue, info, limits))
    }

    /// A context on a device the caller made: a windowed application's, from an adapter
    /// compatible with its surface (`examples/viewer.rs`).
    pub fn from_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        info: wgpu::AdapterInfo,
        limits: wgpu::Limits,
    ) -> Self {
        let uncaptured = Arc::new(Mutex::new(Vec::new()));
        let sink = uncaptured.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        Self {
            device,
            queue,
            info,
            limits,
            uncaptured,
        }
    }

    /// One context per process and kind (hardware only, or software allowed), made on first use:
    /// every simulation shares its device.
    pub fn shared(allow_software: bool) -> Result<Arc<GpuContext>, GpuError> {
        static HARDWARE: OnceLock<Result<Arc<GpuContext>, GpuError>> = OnceLock::new();
        static ANY: OnceLock<Result<Arc<GpuContext>, GpuError>> = OnceLock::new();
        let cell = if allow_software { &ANY } else { &HARDWARE };
        cell.get_or_init(|| GpuContext::new(allow_software).map(Arc::new))
            .clone()
    }

    /// "name (backend, device type)".
    pub fn describe(&self) -> String {
        describe(&self.info)
    }

    pub fn is_software(&self) -> bool {
        is_software(&self.info)
    }

    /// Runs `f` inside a validation and an out-of-memory error scope.
    pub(crate) fn scoped<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T, GpuError> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let e1 = pollster::block_on(validation.pop());
        let e2 = pollster::block_on(oom.pop());
        let stray = self
            .uncaptured
            .lock()
            .map(|mut v| v.drain(..).collect::<Vec<_>>())
            .unwrap_or_default();
        match e1
            .or(e2)
            .map(|e| e.to_string())
            .or(stray.into_iter().next())
        {
            Some(e) => Err(GpuError::Device {
                adapter: self.describe(),
                what: format!("{what}: {e}"),
            }),
            None => Ok(out),
        }
    }
}

pub(super) fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}
