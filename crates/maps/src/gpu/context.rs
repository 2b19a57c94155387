//! Adapter discovery and choice (hardware → software Vulkan), device creation with all adapter limits, and device-error capture.

use std::sync::{Arc, Mutex};

use serde::Serialize;

use errmap_core::{Error, Result};

/// What `errmap gpu-info` reports about one adapter.
#[derive(Debug, Clone, Serialize)]
pub struct AdapterSummary {
    /// The adapter's name as its driver reports it (e.g. `NVIDIA GeForce RTX 4090`,
    /// `llvmpipe (LLVM 17.0.6, 256 bits)`).
    pub name: String,
    /// The graphics API wgpu reaches it through, e.g. `Vulkan`, `Metal`, `Dx12` or `Gl`.
    pub backend: String,
    /// wgpu's device type: `DiscreteGpu`, `IntegratedGpu`, `VirtualGpu`, `Cpu` or `Other`.
    pub device_type: String,
    /// The driver's name; empty where the API does not report one.
    pub driver: String,
    /// The driver's version text; empty where the API does not report one.
    pub driver_info: String,
    /// A CPU implementation such as Mesa lavapipe (llvmpipe).
    pub software: bool,
}

/// The limits errmap depends on, as the chosen device grants them.
#[derive(Debug, Clone, Serialize)]
pub struct LimitsSummary {
    /// Largest buffer, bytes.
    pub max_buffer_size: u64,
    /// Largest storage-buffer binding, bytes: bounds the samples or points of one dispatch.
    pub max_storage_buffer_binding_size: u64,
    /// Storage buffers one shader may bind.
    pub max_storage_buffers_per_shader_stage: u32,
    /// Most workgroups of one dispatch along each dimension.
    pub max_compute_workgroups_per_dimension: u32,
    /// Most invocations (threads) in one workgroup.
    pub max_compute_invocations_per_workgroup: u32,
    /// Workgroup shared memory, bytes.
    pub max_compute_workgroup_storage_size: u32,
    /// Alignment of a uniform binding's offset, bytes (per-epoch steps and networks start
    /// on it).
    pub min_uniform_buffer_offset_alignment: u32,
}

impl LimitsSummary {
    /// The limits errmap depends on, taken from a device's (or adapter's) full set.
    pub fn of(limits: &wgpu::Limits) -> LimitsSummary {
        LimitsSummary {
            max_buffer_size: limits.max_buffer_size,
            max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
            max_storage_buffers_per_shader_stage: limits.max_storage_buffers_per_shader_stage,
            max_compute_workgroups_per_dimension: limits.max_compute_workgroups_per_dimension,
            max_compute_invocations_per_workgroup: limits.max_compute_invocations_per_workgroup,
            max_compute_workgroup_storage_size: limits.max_compute_workgroup_storage_size,
            min_uniform_buffer_offset_alignment: limits.min_uniform_buffer_offset_alignment,
        }
    }
}

fn summarise(info: &wgpu::AdapterInfo) -> AdapterSummary {
    AdapterSummary {
        name: info.name.clone(),
        backend: format!("{:?}", info.backend),
        device_type: format!("{:?}", info.device_type),
        driver: info.driver.clone(),
        driver_info: info.driver_info.clone(),
        software: info.device_type == wgpu::DeviceType::Cpu,
    }
}

/// Preference: discrete, integrated, virtual, other, then software (CPU) adapters.
fn rank(device_type: wgpu::DeviceType) -> u8 {
    match device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

fn instance() -> wgpu::Instance {
    // WGPU_BACKEND and friends still apply, for users who must steer wgpu.
    wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env())
}

/// All adapters wgpu finds, best first (hardware before software), ties kept in
/// enumeration order.
fn adapters(instance: &wgpu::Instance) -> Vec<wgpu::Adapter> {
    let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    adapters.sort_by_key(|a| rank(a.get_info().device_type));
    adapters
}

/// Summaries of every adapter, best first, for `errmap gpu-info`.
pub fn list_adapters() -> Vec<AdapterSummary> {
    adapters(&instance())
        .iter()
        .map(|a| summarise(&a.get_info()))
        .collect()
}

/// An open device and what went wrong on it since the last check.
pub struct GpuContext {
    /// The open device (every limit the adapter offers).
    pub device: wgpu::Device,
    /// The device's command queue.
    pub queue: wgpu::Queue,
    /// The adapter the device was opened on.
    pub adapter: AdapterSummary,
    /// The limits the device grants.
    pub limits: wgpu::Limits,
    /// The subgroup size when subgroup operations are enabled and the adapter has a single
    /// size (lavapipe: 8 with 256-bit SIMD); the CPU-adapter kernels use it.
    pub subgroup_size: Option<u32>,
    /// wgpu's pipeline-cache key of the adapter when the device keeps pipeline caches
    /// (`Features::PIPELINE_CACHE`, Vulkan).
    pub pipeline_cache_key: Option<String>,
    errors: Arc<Mutex<Vec<String>>>,
    lost: Arc<Mutex<Option<String>>>,
}

impl GpuContext {
    /// Opens the best adapter: hardware first, then (if `allow_software`) a software Vulkan
    /// adapter (lavapipe). The device gets every limit the adapter offers.
    pub fn open(allow_software: bool) -> Result<GpuContext> {
        let instance = instance();
        let mut candidates = adapters(&instance);
        if !allow_software && !candidates.is_empty() {
            let software: Vec<String> = candidates
                .iter()
                .map(|a| a.get_info())
                .filter(|i| i.device_type == wgpu::DeviceType::Cpu)
                .map(|i| i.name)
                .collect();
            candidates.retain(|a| a.get_info().device_type != wgpu::DeviceType::Cpu);
            if candidates.is_empty() {
                return Err(Error::device(
                    format!(
                        "only a software adapter ({}), and a hardware GPU was asked for",
                        software.join(", ")
                    ),
                    format!(
                        "use {} gpu or auto to train on it",
                        errmap_core::setting::words(crate::Setting::Backend)
                    ),
                ));
            }
        }
        if candidates.is_empty() {
            return Err(Error::device(
                "no GPU adapter found (no Vulkan, Metal or DX12 device)",
                format!("install a GPU driver, or Mesa's software Vulkan driver (Debian/Ubuntu: apt-get install mesa-vulkan-drivers), or use {} cpu", errmap_core::setting::words(crate::Setting::Backend)),
            ));
        }
        let mut failures = Vec::new();
        for adapter in candidates {
            let info = adapter.get_info();
            let descriptor = wgpu::DeviceDescriptor {
                label: Some("errmap"),
                // Subgroup operations where offered (the CPU-adapter kernels' lane reduction),
                // and pipeline caches (kept between runs: src/gpu/pipeline_cache.rs).
                required_features: adapter.features()
                    & (wgpu::Features::SUBGROUP | wgpu::Features::PIPELINE_CACHE),
                required_limits: adapter.limits(),
                ..Default::default()
            };
            match pollster::block_on(adapter.request_device(&descriptor)) {
                Ok((device, queue)) => return Ok(GpuContext::wrap(device, queue, &info)),
                Err(e) => failures.push(format!("{}: {e}", info.name)),
            }
        }
        Err(Error::device(
            format!("no adapter could open a device ({})", failures.join("; ")),
            format!(
                "update the GPU driver or use {} cpu",
                errmap_core::setting::words(crate::Setting::Backend)
            ),
        ))
    }

    fn wrap(device: wgpu::Device, queue: wgpu::Queue, info: &wgpu::AdapterInfo) -> GpuContext {
        let errors = Arc::new(Mutex::new(Vec::new()));
        let lost = Arc::new(Mutex::new(None));
        let sink = Arc::clone(&errors);
        // Without a handler wgpu panics on an uncaptured error; errmap reports it instead.
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut list) = sink.lock() {
                list.push(e.to_string());
            }
        }));
        let lost_sink = Arc::clone(&lost);
        device.set_device_lost_callback(move |reason, message| {
            if let Ok(mut slot) = lost_sink.lock() {
                *slot = Some(format!("{reason:?}: {message}"));
            }
        });
        let limits = device.limits();
        let subgroup_size = (device.features().contains(wgpu::Features::SUBGROUP)
            && info.subgroup_min_size == info.subgroup_max_size)
            .then_some(info.subgroup_min_size);
        let pipeline_cache_key = device
            .features()
            .contains(wgpu::Features::PIPELINE_CACHE)
            .then(|| wgpu::util::pipeline_cache_key(info))
            .flatten();
        GpuContext {
            device,
            queue,
            adapter: summarise(info),
            limits,
            subgroup_size,
            pipeline_cache_key,
            errors,
            lost,
        }
    }

    /// Name for notes: "NVIDIA GeForce RTX 4090 (Vulkan)" or "llvmpipe (…) (Vulkan, software)".
    pub fn describe(&self) -> String {
        format!(
            "{} ({}{})",
            self.adapter.name,
            self.adapter.backend,
            if self.adapter.software {
                ", software"
            } else {
                ""
            }
        )
    }

    /// Turns a lost device or any error wgpu reported since the last call into `Error::device`.
    pub fn check(&self, during: &str) -> Result<()> {
        if let Some(reason) = self.lost.lock().ok().and_then(|slot| slot.clone()) {
            return Err(Error::device(
                format!("the device was lost while {during} ({reason})"),
                format!(
                    "retry; if it repeats, update the GPU driver or use {} cpu",
                    errmap_core::setting::words(crate::Setting::Backend)
                ),
            ));
        }
        let errors: Vec<String> = self
            .errors
            .lock()
            .map(|mut list| std::mem::take(&mut *list))
            .unwrap_or_default();
        if let Some(first) = errors.first() {
            let oom = first.to_lowercase().contains("out of memory");
            return Err(Error::device(
                format!("{during} failed: {first}"),
                if oom {
                    format!("the batch does not fit in GPU memory: train fewer parts at once, use a coarser training grid, or use {} cpu", errmap_core::setting::words(crate::Setting::Backend))
                } else {
                    format!(
                        "this is a bug in errmap's GPU path; use {} cpu and report it",
                        errmap_core::setting::words(crate::Setting::Backend)
                    )
                },
            ));
        }
        Ok(())
    }

    /// Waits for all submitted work, reporting device loss or timeouts as `Error::device`.
    pub fn wait(&self, during: &str) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| {
                Error::device(
                    format!("waiting for the GPU while {during} failed: {e}"),
                    format!(
                        "retry; if it repeats, use {} cpu",
                        errmap_core::setting::words(crate::Setting::Backend)
                    ),
                )
            })?;
        self.check(during)
    }

    /// Copies `size` bytes of a storage buffer back to the host.
    pub fn read_buffer(&self, source: &wgpu::Buffer, size: u64, during: &str) -> Result<Vec<u8>> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("errmap readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("errmap readback"),
            });
        encoder.copy_buffer_to_buffer(source, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        let slice = staging.slice(..);
        let (sender, receiver) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |result| {
            let _ = sender.send(result);
        });
        self.wait(during)?;
        match receiver.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => {
                return Err(Error::device(
                    format!("reading results back while {during} failed: {e}"),
                    format!(
                        "retry, or use {} cpu",
                        errmap_core::setting::words(crate::Setting::Backend)
                    ),
                ))
            }
            Err(_) => {
                return Err(Error::device(
                    format!("the GPU never answered while {during}"),
                    format!(
                        "retry, or use {} cpu",
                        errmap_core::setting::words(crate::Setting::Backend)
                    ),
                ))
            }
        }
        let bytes = slice
            .get_mapped_range()
            .map_err(|e| {
                Error::device(
                    format!("mapping results while {during}: {e}"),
                    format!(
                        "retry, or use {} cpu",
                        errmap_core::setting::words(crate::Setting::Backend)
                    ),
                )
            })?
            .to_vec();
        staging.unmap();
        Ok(bytes)
    }
}
