//! Finding wgpu adapters: what each is (for choosing and for run metadata), and the best one.

use super::Precision;
use crate::kinematics::backend::BackendError;

/// What an adapter is, for choosing and for run metadata.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AdapterSummary {
    pub name: String,
    /// "DiscreteGpu", "IntegratedGpu", "Cpu", ...
    pub device_type: String,
    pub backend: String,
    pub driver: String,
    pub driver_info: String,
    /// A real GPU (discrete or integrated), as `--backend auto` requires.
    pub real_gpu: bool,
}

impl AdapterSummary {
    pub(super) fn of(info: &wgpu::AdapterInfo) -> AdapterSummary {
        AdapterSummary {
            name: info.name.clone(),
            device_type: format!("{:?}", info.device_type),
            backend: format!("{:?}", info.backend),
            driver: info.driver.clone(),
            driver_info: info.driver_info.clone(),
            real_gpu: matches!(info.device_type, wgpu::DeviceType::DiscreteGpu | wgpu::DeviceType::IntegratedGpu),
        }
    }
}

impl std::fmt::Display for AdapterSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({}, {}, driver {} {})", self.name, self.device_type, self.backend, self.driver, self.driver_info)
    }
}

/// Backends searched for adapters (those compiled in for this platform).
pub fn searched_backends() -> String {
    format!("{:?}", wgpu::Instance::enabled_backend_features())
}

fn instance() -> wgpu::Instance {
    wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env())
}

/// Preference order: discrete, integrated, virtual, other, CPU.
fn rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// Every adapter wgpu finds on every backend, best first ([`rank`]); no device is created.
/// Shared by the solver's backend and the rasterizer.
pub fn adapters_best_first() -> Vec<wgpu::Adapter> {
    let mut a = pollster::block_on(instance().enumerate_adapters(wgpu::Backends::all()));
    a.sort_by_key(|a| rank(a.get_info().device_type));
    a
}

/// Every adapter wgpu finds, best first (no device is created).
pub fn list_adapters() -> Vec<AdapterSummary> {
    adapters_best_first().iter().map(|a| AdapterSummary::of(&a.get_info())).collect()
}

/// The best adapter (for f64: the best offering `SHADER_F64`), or an error naming what was
/// searched.
pub(super) fn best_adapter(precision: Precision) -> Result<wgpu::Adapter, BackendError> {
    let a = adapters_best_first();
    if precision == Precision::F64 && !a.is_empty() {
        let names: Vec<String> = a.iter().map(|a| a.get_info().name).collect();
        return a.into_iter().find(|a| a.features().contains(wgpu::Features::SHADER_F64)).ok_or_else(|| {
            BackendError::NoAdapter(format!(
                "no wgpu adapter offers SHADER_F64 (f64 in shaders); found: {}; use the f32 shaders \
                 (--backend wgpu) or the CPU backend",
                names.join(", ")
            ))
        });
    }
    a.into_iter().next().ok_or_else(|| {
        BackendError::NoAdapter(format!(
            "wgpu found no adapter on backends {} (for Vulkan on Linux: a GPU driver, or lavapipe from \
             mesa-vulkan-drivers, and libvulkan1; VK_ICD_FILENAMES={})",
            searched_backends(),
            std::env::var("VK_ICD_FILENAMES").unwrap_or_else(|_| "<unset>".into())
        ))
    })
}
