#![allow(clippy::needless_range_loop)] // index loops read closest to the equations in numerical code
//! smocap: joint scale–pose canonicalization of marker-based motion capture.
//!
//! Data flows through the modules in this order: [`io`] (marker files, model files) →
//! [`model`] (immutable tree, scales, markers, proxy map) → [`kinematics`] (forward kinematics,
//! Jacobians, Gauss–Newton assembly) → [`solve`] (trust-region QP, QP backends, calibration) →
//! [`pipeline`] (trials, reports) → [`archive`] (whole datasets to MCAP) → [`render`] (glTF scenes,
//! cameras, 2D ground truth, previews) → the `smocap` command line;
//! [`eval`] holds the evaluation studies built on the pipeline; [`body`] is the skinned CC0 body mesh
//! (with its adult shape space) that dresses a solved skeleton.

pub mod archive;
pub mod body;
pub mod cli;
pub mod eval;
pub mod io;
pub mod kinematics;
pub mod model;
pub mod pipeline;
pub mod render;
pub mod solve;
