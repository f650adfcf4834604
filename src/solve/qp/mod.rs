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

pub use boxqp::{BoxQp, BoxQpSettings};
pub use clarabel_backend::{ClarabelQp, ClarabelQpSettings};

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
    /// NaN or infinity where a finite number is required (`what` names the input: "h", "g",
    /// "a", …; `index` is the flat index into it, column-major for matrices).
    #[error("QP input {what} has a non-finite entry at index {index}")]
    NonFinite { what: &'static str, index: usize },
}

impl QpProblem<'_> {
    /// Checks shapes, bound consistency and finiteness, returning the number of variables `n`.
    ///
    /// `h` (upper triangle only) and `g` must be finite; `lb[i] ≤ ub[i]` with `lb[i] < +∞`
    /// and `ub[i] > -∞`. Cost `O(n²)`, no allocation.
    pub fn validate(&self) -> Result<usize, QpError> {
        let n = self.g.len();
        let (h_rows, h_cols) = self.h.shape();
        if h_rows != n || h_cols != n || self.lb.len() != n || self.ub.len() != n {
            return Err(QpError::Dimensions { h_rows, h_cols, g: n, lb: self.lb.len(), ub: self.ub.len() });
        }
        // Branch-free scans (they vectorise); locate the offender only on failure.
        let all_finite = |v: &[f64]| !v.iter().fold(false, |bad, x| bad | !x.is_finite());
        let g = self.g.as_slice();
        if !all_finite(g) {
            let index = g.iter().position(|v| !v.is_finite()).unwrap_or(0);
            return Err(QpError::NonFinite { what: "g", index });
        }
        let h = self.h.as_slice();
        for j in 0..n {
            let col = &h[j * n..=j * n + j];
            if !all_finite(col) {
                let i = col.iter().position(|v| !v.is_finite()).unwrap_or(0);
                return Err(QpError::NonFinite { what: "h", index: j * n + i });
            }
        }
        for (index, (&lb, &ub)) in self.lb.iter().zip(self.ub.iter()).enumerate() {
            if lb.is_nan() || ub.is_nan() || lb > ub {
                return Err(QpError::InconsistentBounds { index, lb, ub });
            }
            if lb == f64::INFINITY || ub == f64::NEG_INFINITY {
                return Err(QpError::Infeasible(format!("variable {index} has bounds [{lb}, {ub}]")));
            }
        }
        Ok(n)
    }

    /// `½ xᵀ H x + gᵀ x`, reading only the upper triangle of `H`; NaN if `x` has the wrong length.
    pub fn objective(&self, x: &DVector<f64>) -> f64 {
        let n = self.g.len();
        if x.len() != n || self.h.shape() != (n, n) {
            return f64::NAN;
        }
        let h = self.h.as_slice();
        let mut quad = 0.0;
        for j in 0..n {
            let col = &h[j * n..j * n + j];
            let off: f64 = col.iter().zip(x.iter()).map(|(a, b)| a * b).sum();
            quad += x[j] * (2.0 * off + h[j * n + j] * x[j]);
        }
        0.5 * quad + self.g.dot(x)
    }
}

/// A QP backend. Implementations keep their workspace between calls so that the per-frame
/// hot path does not allocate once sizes are stable.
pub trait QpSolver: Send {
    /// Short name for reports ("boxqp", "clarabel").
    fn name(&self) -> &'static str;
    /// Solve `problem`. On entry `x` holds the warm start (it may be outside the bounds; it is
    /// projected first); on exit it holds the solution.
    fn solve(&mut self, problem: &QpProblem<'_>, x: &mut DVector<f64>) -> Result<QpStats, QpError>;

    /// Sets general linear constraints `lo ≤ A x ≤ hi` for the following solves (`None` clears
    /// them). Backends that handle bounds only refuse constraints.
    fn set_linear_constraints(&mut self, constraints: Option<LinearConstraints>) -> Result<(), QpError> {
        match constraints {
            None => Ok(()),
            Some(_) => Err(QpError::Backend {
                backend: self.name(),
                status: "general linear constraints need the clarabel backend".into(),
            }),
        }
    }
}
