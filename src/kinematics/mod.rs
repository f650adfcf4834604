//! Kinematics of a [`Model`](crate::model::Model): forward kinematics of bodies and markers, the
//! marker Jacobian `J_y = ∂x̂/∂y` with analytic pose and scale columns, and the assembly of the
//! Gauss–Newton model `(H, g, E)` of one frame in proxy space.
//!
//! The CPU implementation ([`cpu`]) is the reference; derivations are in `docs/KINEMATICS.md`.
//! Batches of frames are evaluated behind [`backend::BatchBackend`]: on the CPU
//! ([`backend::CpuBackend`]) or in wgpu compute shaders ([`gpu::WgpuBackend`]). [`synth`]
//! observes a model's smooth motion through it: synthetic trials with their truth.

pub mod assembly;
pub mod backend;
pub mod batch;
pub mod cpu;
pub mod gpu;
pub mod layout;
pub mod synth;

pub use assembly::{FrameProblem, GaussNewton};
pub use backend::{BatchBackend, CpuBackend, EnergyEval, FrameModel};
pub use cpu::Workspace;
pub use layout::Layout;
