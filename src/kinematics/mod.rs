//! Kinematics of a [`Model`](crate::model::Model): forward kinematics of bodies and markers, the
//! marker Jacobian `J_y = ∂x̂/∂y` with analytic pose and scale columns, and the assembly of the
//! Gauss–Newton model `(H, g, E)` of one frame in proxy space.
//!
//! The CPU implementation ([`cpu`]) is the reference; derivations are in `docs/KINEMATICS.md`.

pub mod assembly;
pub mod batch;
pub mod cpu;
pub mod layout;

pub use assembly::{FrameProblem, GaussNewton};
pub use cpu::Workspace;
pub use layout::Layout;
