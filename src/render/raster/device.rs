//! The wgpu device the rasterizer draws on: the best adapter wgpu finds (a GPU before a CPU
//! driver such as lavapipe), no window, no optional feature.

use super::RasterError;

/// A device and its queue, with the adapter's description.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// "name (type, backend)", for logs and run metadata.
    pub adapter: String,
}

impl Gpu {
    /// The best adapter's device; [`RasterError::NoAdapter`] when wgpu finds none.
    pub fn new() -> Result<Gpu, RasterError> {
        let adapter = crate::kinematics::gpu::adapters_best_first().into_iter().next().ok_or_else(|| {
            RasterError::NoAdapter(format!(
                "wgpu found no adapter (for Vulkan on Linux: a GPU driver, or lavapipe from mesa-vulkan-drivers, \
                 and libvulkan1; VK_ICD_FILENAMES={})",
                std::env::var("VK_ICD_FILENAMES").unwrap_or_else(|_| "<unset>".into())
            ))
        })?;
        let info = adapter.get_info();
        let name = format!("{} ({:?}, {:?})", info.name, info.device_type, info.backend);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("smocap render"),
            required_features: wgpu::Features::empty(),
            required_limits: adapter.limits(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| RasterError::Device(format!("{name}: requesting a device: {e}")))?;
        Ok(Gpu { device, queue, adapter: name })
    }
}
