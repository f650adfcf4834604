#![allow(clippy::needless_range_loop)] // index loops read closest to the equations in numerical code
//! smocap: joint scale–pose canonicalization of marker-based motion capture.
//!
//! Data flows through the modules in this order: [`io`] (marker files, model files) →
//! [`model`] (immutable tree, scales, markers, proxy map) → [`kinematics`] (forward kinematics,
//! Jacobians, Gauss–Newton assembly) → [`solve`] (trust-region QP, QP backends, calibration) →
//! [`pipeline`] (input, calibration, running, results) → [`archive`] (whole datasets to MCAP) →
//! [`body`] (a skinned CC0 body mesh on the solved skeleton), [`retarget`] (humanoid robots),
//! [`render`] (glTF scenes, cameras, 2D ground truth, previews)
//! and [`eval`] (the evaluation studies) → the `smocap` command line. A module imports only from
//! the layers before it (`docs/ARCHITECTURE.md`, checked by `tests/architecture.rs`); `io` reads
//! files into [`model`]'s types, so [`model`] sits below it.

pub mod archive;
pub mod body;
pub mod cli;
pub mod eval;
pub mod io;
pub mod kinematics;
pub mod model;
pub mod pipeline;
pub mod render;
pub mod retarget;
pub mod solve;
