//! The WGSL the backend compiles: a scalar prelude, the model's header, `shaders/common.wgsl` and
//! one [`Kernel`], in the chosen [`Precision`].

use super::pack;

/// What both kernels share (bindings, addressing, the per-body, chain and row steps).
pub const COMMON: &str = include_str!("../../../shaders/common.wgsl");
/// One workgroup per frame (the default).
pub const COOPERATIVE: &str = include_str!("../../../shaders/cooperative.wgsl");
/// One invocation per frame.
pub const PER_FRAME: &str = include_str!("../../../shaders/per_frame.wgsl");
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

    /// Bytes per shader word.
    pub fn word(self) -> usize {
        match self {
            Precision::F32 => 4,
            Precision::F64 => 8,
        }
    }
}

/// How the work of one frame is spread over the GPU (docs/KINEMATICS.md, "GPU kernels").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Kernel {
    /// One workgroup of [`WORKGROUP`] invocations per frame: bodies by tree level, markers'
    /// Jacobian rows and the entries of `g` and `H` spread over the invocations.
    #[default]
    Cooperative,
    /// One invocation per frame (latency-bound on one thread; kept for comparison).
    PerFrame,
}

/// Invocations per workgroup in both kernels (`WG` in `shaders/cooperative.wgsl`).
pub const WORKGROUP: usize = 64;

impl Kernel {
    /// The kernel's WGSL (after [`COMMON`]).
    pub fn source(self) -> &'static str {
        match self {
            Kernel::Cooperative => COOPERATIVE,
            Kernel::PerFrame => PER_FRAME,
        }
    }

    /// "cooperative" or "per-frame".
    pub fn name(self) -> &'static str {
        match self {
            Kernel::Cooperative => "cooperative",
            Kernel::PerFrame => "per-frame",
        }
    }

    /// Scratch words per frame of capacity.
    pub fn scratch_rows(self, rows: &pack::Rows) -> usize {
        match self {
            Kernel::Cooperative => rows.scratch_coop,
            Kernel::PerFrame => rows.scratch,
        }
    }

    /// Workgroups dispatched for `n` frames.
    pub fn workgroups(self, n: usize) -> usize {
        match self {
            Kernel::Cooperative => n,
            Kernel::PerFrame => n.div_ceil(WORKGROUP),
        }
    }

    /// Frames one dimension of a dispatch can cover, given the adapter's workgroup limit.
    pub fn frames_per_dispatch(self, max_workgroups: usize) -> usize {
        match self {
            Kernel::Cooperative => max_workgroups,
            Kernel::PerFrame => max_workgroups * WORKGROUP,
        }
    }
}

/// The complete WGSL of a model packed as `packed`, for chunks of `cap` frames.
pub fn shader_source(packed: &pack::Packed, cap: usize, precision: Precision, kernel: Kernel) -> String {
    format!("{}\n{}\n{}\n{}", precision.prelude(), packed.header(cap), COMMON, kernel.source())
}
