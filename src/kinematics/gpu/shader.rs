//! The WGSL the backend compiles: `shaders/batch.wgsl` after a scalar prelude and the model's
//! header, in the chosen [`Precision`].

use super::pack;

/// The shader source; [`shader_source`] prepends the scalar prelude and the model's header.
pub const SHADER: &str = include_str!("../../../shaders/batch.wgsl");
/// The f32 prelude: `real = f32` and the built-in sin/cos.
pub const REAL_F32: &str = include_str!("../../../shaders/real_f32.wgsl");
/// The f64 prelude: `real = f64` and sin/cos computed in f64 (WGSL has none).
pub const REAL_F64: &str = include_str!("../../../shaders/real_f64.wgsl");

/// The scalar type the shaders compute in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// Every GPU; positions agree with the f64 CPU reference to ~1e-6 m.
    #[default]
    F32,
    /// Needs `wgpu::Features::SHADER_F64`; agrees with the CPU reference to ~1e-12. Consumer GPUs
    /// run f64 at 1/32–1/64 of their f32 rate; data-centre GPUs (H100: 1/2) much faster.
    F64,
}

impl Precision {
    /// The WGSL prelude defining `real`, `sn` and `cs`.
    pub fn prelude(self) -> &'static str {
        match self {
            Precision::F32 => REAL_F32,
            Precision::F64 => REAL_F64,
        }
    }

    /// "f32" or "f64".
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

/// The complete WGSL of a model packed as `packed`, for chunks of `cap` frames.
pub fn shader_source(packed: &pack::Packed, cap: usize, precision: Precision) -> String {
    format!("{}\n{}\n{}", precision.prelude(), packed.header(cap), SHADER)
}
