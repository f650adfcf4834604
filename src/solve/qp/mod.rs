//! Small dense convex QPs: `min ½ xᵀ H x + gᵀ x` subject to `lb ≤ x ≤ ub`
//! (and, for the clarabel backend, general linear constraints `lo ≤ A x ≤ hi`).
//!
//! Two backends behind [`QpSolver`]:
//! - [`BoxQp`]: projected Newton (as MuJoCo's `mju_boxQP`), allocation-free after the first call
//!   for a given size — the default for the per-frame trust-region step;
//! - [`ClarabelQp`]: the interior-point solver clarabel, reused across solves through its
//!   `update_*` API, for general linear constraints and as the oracle in tests.

mod boxqp;
mod clarabel_backend;

pub use boxqp::BoxQp;
pub use clarabel_backend::ClarabelQp;

use nalgebra::{DMatrix, DVector};

/// One QP instance. `h` must be symmetric positive semi-definite (only the upper triangle
/// may be read); `lb[i] ≤ ub[i]` (equal bounds fix a variable; infinite bounds are allowed).
pub struct QpProblem<'a> {
    pub h: &'a DMatrix<f64>,
    pub g: &'a DVector<f64>,
    pub lb: &'a DVector<f64>,
    pub ub: &'a DVector<f64>,
}

/// General linear constraints `lo ≤ A x ≤ hi` (rows with `lo == hi` are equalities;
/// infinite sides are dropped).
#[derive(Clone, Debug)]
pub struct LinearConstraints {
    pub a: DMatrix<f64>,
    pub lo: DVector<f64>,
    pub hi: DVector<f64>,
}

/// How a solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum QpStatus {
    /// Optimality conditions met to the solver's tolerance.
    Solved,
    /// Iteration cap reached; `x` is the best feasible point found.
    MaxIterations,
}

/// Statistics of one solve.
#[derive(Clone, Copy, Debug)]
pub struct QpStats {
    pub status: QpStatus,
    pub iterations: u32,
    /// `½ xᵀ H x + gᵀ x` at the returned `x`.
    pub objective: f64,
}

/// Failures that leave no usable solution.
#[derive(Debug, thiserror::Error)]
pub enum QpError {
    #[error("QP dimensions disagree: H is {h_rows}x{h_cols}, g has {g}, bounds have {lb} and {ub}")]
    Dimensions { h_rows: usize, h_cols: usize, g: usize, lb: usize, ub: usize },
    #[error("QP bounds are inconsistent at variable {index}: lb = {lb} > ub = {ub}")]
    InconsistentBounds { index: usize, lb: f64, ub: f64 },
    #[error("QP Hessian is not positive definite on the free set (pivot {pivot} = {value:e})")]
    NotPositiveDefinite { pivot: usize, value: f64 },
    #[error("QP is infeasible: {0}")]
    Infeasible(String),
    #[error("QP backend {backend} failed: {status}")]
    Backend { backend: &'static str, status: String },
}

/// A QP backend. Implementations keep their workspace between calls so that the per-frame
/// hot path does not allocate once sizes are stable.
pub trait QpSolver: Send {
    /// Short name for reports ("boxqp", "clarabel").
    fn name(&self) -> &'static str;
    /// Solve `problem`. On entry `x` holds the warm start (it may be outside the bounds; it is
    /// projected first); on exit it holds the solution.
    fn solve(&mut self, problem: &QpProblem<'_>, x: &mut DVector<f64>) -> Result<QpStats, QpError>;
}
