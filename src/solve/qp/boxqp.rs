//! Projected-Newton box QP, after MuJoCo's `mju_boxQP` (Tassa, Mansard & Todorov 2014,
//! "Control-limited differential dynamic programming").
//!
//! Solves `min f(x) = ½ xᵀ H x + gᵀ x` s.t. `lb ≤ x ≤ ub`. Each iteration:
//! 1. gradient `∇f = H x + g` (kept up to date incrementally: `∇f ← ∇f + H d` after a step `d`);
//! 2. clamped set `C = {i : lb = ub, or x = lb and ∇f > 0, or x = ub and ∇f < 0}`; the rest is
//!    the free set `F` (a zero gradient at a bound is *free*, which resolves degenerate
//!    complementarity). The projected gradient is `∇f` on `F` and zero on `C`, so
//!    `‖∇f_F‖∞ ≤ tol·(1 + ‖g‖∞)` is the first-order (KKT) stopping test;
//! 3. if `C` changed, dense Cholesky `H_FF = L Lᵀ` into preallocated workspace;
//! 4. Newton direction `d_F = −H_FF⁻¹ ∇f_F`, `d_C = 0` (the minimiser over `F` with `C` held);
//! 5. projected Armijo search: `x(t) = P(x + t d)`, accept the first `t = β^k` with
//!    `f(x(t)) − f(x) ≤ σ t ∇fᵀd`. Variables that the projection blocks were at a bound with an
//!    inward (or zero) gradient, so blocking only makes the initial slope more negative: a small
//!    enough `t` always passes.
//!
//! Stops on the projected-gradient test (`Solved`), a relative decrease below
//! `min_relative_improvement` or a line search that cannot decrease `f` (both `Solved`:
//! converged to working precision), or the iteration cap (`MaxIterations`).
//!
//! Singular `H_FF` (PSD `H`): a pivot `≤ ε s` (`ε = regularization`, `s` = largest free diagonal
//! entry, or 1) triggers one refactorisation of `H_FF + ε s I`; a pivot `≤ ½ ε s` there means
//! `H_FF` is indefinite → [`QpError::NotPositiveDefinite`]. A regularised step that no bound
//! blocks and along which `f` is nearly linear (`dᵀHd < 10⁻⁶ |∇fᵀd|`) means `f` is unbounded
//! below on the box → also `NotPositiveDefinite`, naming the singular pivot.
//!
//! Only the upper triangle of `H` is read. Workspace grows to the largest `n` seen; no
//! allocation afterwards.

use super::{QpError, QpProblem, QpSolver, QpStats, QpStatus};
use nalgebra::DVector;
use serde::{Deserialize, Serialize};

/// Tuning of [`BoxQp`]. Defaults are chosen for well-scaled problems with `n ≲ 100`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default)]
pub struct BoxQpSettings {
    /// Newton iterations before giving up with [`QpStatus::MaxIterations`]. Default 100.
    pub max_iterations: u32,
    /// Stop when `max_{i∈F} |∇f_i| ≤ gradient_tolerance · (1 + ‖g‖∞)`. Default 1e-10.
    pub gradient_tolerance: f64,
    /// Stop when a step decreases `f` by less than this times `|f|`. Default 1e-12.
    pub min_relative_improvement: f64,
    /// Backtracking factor `β ∈ (0, 1)` of the line search (out-of-range values use 0.5).
    /// Default 0.5.
    pub line_search_factor: f64,
    /// Armijo constant `σ`: fraction of the predicted linear decrease required. Default 0.1.
    pub armijo: f64,
    /// Smallest step length tried before the line search gives up. Default 1e-20.
    pub min_step: f64,
    /// Relative singularity threshold and diagonal shift `ε` for the Cholesky of `H_FF`
    /// (scaled by the largest free diagonal entry). Default 1e-10.
    pub regularization: f64,
}

impl Default for BoxQpSettings {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            gradient_tolerance: 1e-10,
            min_relative_improvement: 1e-12,
            line_search_factor: 0.5,
            armijo: 0.1,
            min_step: 1e-20,
            regularization: 1e-10,
        }
    }
}

/// Projected-Newton box-QP solver with reusable workspace (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct BoxQp {
    /// Algorithm knobs; may be changed between solves.
    pub settings: BoxQpSettings,
    grad: Vec<f64>,
    dir: Vec<f64>,
    cand: Vec<f64>,
    step: Vec<f64>,
    hd: Vec<f64>,
    clamped: Vec<bool>,
    free: Vec<usize>,
    /// `nf × nf` row-major; the lower triangle holds `L` after a successful factorisation.
    chol: Vec<f64>,
    inv_diag: Vec<f64>,
    rhs: Vec<f64>,
}

/// Cap on backtracking steps, independent of `line_search_factor`/`min_step`.
const MAX_LINE_SEARCH: u32 = 80;
/// `dᵀHd / |∇fᵀd|` below this on an unblocked regularised step means unbounded below.
const UNBOUNDED_CURVATURE: f64 = 1e-6;

impl BoxQp {
    /// Solver with default settings and empty workspace (sized on the first solve).
    pub fn new() -> Self {
        Self::default()
    }

    /// Solver with the given settings.
    pub fn with_settings(settings: BoxQpSettings) -> Self {
        Self { settings, ..Self::default() }
    }

    /// Solver with workspace preallocated for `n` variables.
    pub fn with_capacity(n: usize) -> Self {
        let mut s = Self::default();
        s.reserve(n);
        s
    }

    fn reserve(&mut self, n: usize) {
        if self.grad.len() >= n {
            return;
        }
        for v in [&mut self.grad, &mut self.dir, &mut self.cand, &mut self.step, &mut self.hd] {
            v.resize(n, 0.0);
        }
        self.inv_diag.resize(n, 0.0);
        self.rhs.resize(n, 0.0);
        self.clamped.resize(n, false);
        self.free.reserve(n.saturating_sub(self.free.len()));
        self.chol.resize(n * n, 0.0);
    }

    /// Gathers `H_FF + shift·I` and factors it in place. `Err((k, pivot))` on pivot `k ≤ thr`.
    fn factor(&mut self, h: &[f64], n: usize, shift: f64, thr: f64) -> Result<(), (usize, f64)> {
        let nf = self.free.len();
        let chol = &mut self.chol[..nf * nf];
        for (a, &fa) in self.free.iter().enumerate() {
            // Row a of the lower triangle = upper part of column fa of H (free[] is sorted).
            let col = &h[fa * n..=fa * n + fa];
            let row = &mut chol[a * nf..=a * nf + a];
            for (r, &fb) in row.iter_mut().zip(&self.free[..=a]) {
                *r = col[fb];
            }
            row[a] += shift;
        }
        // Cholesky–Banachiewicz: row by row, contiguous dot products.
        for i in 0..nf {
            let (done, rest) = chol.split_at_mut(i * nf);
            let row_i = &mut rest[..=i];
            for j in 0..i {
                let s = row_i[j] - dot(&row_i[..j], &done[j * nf..j * nf + j]);
                row_i[j] = s * self.inv_diag[j];
            }
            let s = row_i[i] - dot(&row_i[..i], &row_i[..i]);
            if !(s > thr) {
                return Err((i, s));
            }
            let d = s.sqrt();
            row_i[i] = d;
            self.inv_diag[i] = 1.0 / d;
        }
        Ok(())
    }

    /// `dir_F = −H_FF⁻¹ ∇f_F`, `dir_C = 0`, using the current factor.
    fn newton_direction(&mut self) {
        let nf = self.free.len();
        let chol = &self.chol[..nf * nf];
        let y = &mut self.rhs[..nf];
        for (a, &fa) in self.free.iter().enumerate() {
            y[a] = (self.grad[fa] - dot(&chol[a * nf..a * nf + a], &y[..a])) * self.inv_diag[a];
        }
        for a in (0..nf).rev() {
            let z = y[a] * self.inv_diag[a];
            y[a] = z;
            for (yb, l) in y[..a].iter_mut().zip(&chol[a * nf..a * nf + a]) {
                *yb -= l * z;
            }
        }
        self.dir.iter_mut().for_each(|d| *d = 0.0);
        for (a, &fa) in self.free.iter().enumerate() {
            self.dir[fa] = -y[a];
        }
    }
}

impl QpSolver for BoxQp {
    fn name(&self) -> &'static str {
        "boxqp"
    }

    fn solve(&mut self, problem: &QpProblem<'_>, x: &mut DVector<f64>) -> Result<QpStats, QpError> {
        let n = problem.validate()?;
        if x.len() != n {
            // No usable warm start: start from the origin (projected below).
            *x = DVector::zeros(n);
        }
        self.reserve(n);
        let st = &self.settings;
        let (max_iter, armijo, min_step, reg) =
            (st.max_iterations, st.armijo, st.min_step, st.regularization);
        let min_rel = st.min_relative_improvement;
        let beta = if st.line_search_factor > 0.0 && st.line_search_factor < 1.0 {
            st.line_search_factor
        } else {
            0.5
        };
        let h = problem.h.as_slice();
        let (g, lb, ub) = (problem.g.as_slice(), problem.lb.as_slice(), problem.ub.as_slice());
        let x = x.as_mut_slice();
        let gtol = st.gradient_tolerance * (1.0 + g.iter().fold(0.0_f64, |m, v| m.max(v.abs())));

        for i in 0..n {
            let xi = if x[i].is_finite() { x[i] } else { 0.0 };
            x[i] = xi.max(lb[i]).min(ub[i]);
        }
        symv_upper(h, n, x, &mut self.grad[..n]);
        for (gr, gi) in self.grad[..n].iter_mut().zip(g) {
            *gr += gi;
        }
        let mut f = 0.5 * x.iter().zip(&self.grad[..n]).zip(g).map(|((a, b), c)| a * (b + c)).sum::<f64>();

        let mut factored = false;
        let mut regularised = false;
        let mut singular = (0, 0.0);
        let mut status = QpStatus::MaxIterations;
        let mut iterations = 0;
        for iter in 0..=max_iter {
            iterations = iter;
            // Clamped / free sets and projected-gradient norm.
            let mut changed = !factored;
            let mut pg = 0.0_f64;
            self.free.clear();
            for i in 0..n {
                let gi = self.grad[i];
                let c = lb[i] == ub[i] || (x[i] <= lb[i] && gi > 0.0) || (x[i] >= ub[i] && gi < 0.0);
                changed |= c != self.clamped[i];
                self.clamped[i] = c;
                if !c {
                    self.free.push(i);
                    pg = pg.max(gi.abs());
                }
            }
            if pg <= gtol {
                status = QpStatus::Solved;
                break;
            }
            if iter == max_iter {
                break;
            }
            if changed {
                let scale = self.free.iter().fold(0.0_f64, |m, &i| m.max(h[i * n + i]));
                let scale = if scale > 0.0 { scale } else { 1.0 };
                regularised = false;
                if let Err((k, v)) = self.factor(h, n, 0.0, reg * scale) {
                    singular = (self.free[k], v);
                    let shift = reg * scale;
                    if self.factor(h, n, shift, 0.5 * shift).is_err() {
                        return Err(QpError::NotPositiveDefinite { pivot: singular.0, value: singular.1 });
                    }
                    regularised = true;
                }
                factored = true;
            }
            self.newton_direction();
            let slope: f64 = self.free.iter().map(|&i| self.grad[i] * self.dir[i]).sum();
            if !(slope < 0.0) {
                status = QpStatus::Solved;
                break;
            }

            // Projected Armijo line search.
            let mut t = 1.0;
            let mut accepted = None;
            for _ in 0..MAX_LINE_SEARCH {
                let mut clipped = false;
                for i in 0..n {
                    if self.clamped[i] {
                        self.cand[i] = x[i];
                        self.step[i] = 0.0;
                    } else {
                        let raw = x[i] + t * self.dir[i];
                        let c = raw.max(lb[i]).min(ub[i]);
                        clipped |= c != raw;
                        self.cand[i] = c;
                        self.step[i] = c - x[i];
                    }
                }
                symv_upper(h, n, &self.step[..n], &mut self.hd[..n]);
                let lin = dot(&self.grad[..n], &self.step[..n]);
                let curv = dot(&self.step[..n], &self.hd[..n]);
                if regularised && t == 1.0 && !clipped && curv < UNBOUNDED_CURVATURE * lin.abs() {
                    return Err(QpError::NotPositiveDefinite { pivot: singular.0, value: singular.1 });
                }
                let df = lin + 0.5 * curv;
                if df <= armijo * t * slope {
                    accepted = Some(df);
                    break;
                }
                t *= beta;
                if t < min_step {
                    break;
                }
            }
            let Some(df) = accepted else {
                status = QpStatus::Solved; // no numerical decrease possible
                break;
            };
            for i in 0..n {
                x[i] = self.cand[i];
                self.grad[i] += self.hd[i];
            }
            let f_old = f;
            f += df;
            if -df <= min_rel * f_old.abs() {
                iterations = iter + 1;
                status = QpStatus::Solved;
                break;
            }
        }
        let objective = 0.5 * x.iter().zip(&self.grad[..n]).zip(g).map(|((a, b), c)| a * (b + c)).sum::<f64>();
        Ok(QpStats { status, iterations, objective })
    }
}

/// Dot product with four independent accumulators (vectorises without reassociation).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let mut tail = 0.0;
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        tail += x * y;
    }
    let mut acc = [0.0; 4];
    for (x, y) in ca.zip(cb) {
        acc[0] += x[0] * y[0];
        acc[1] += x[1] * y[1];
        acc[2] += x[2] * y[2];
        acc[3] += x[3] * y[3];
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// `out = H v` for symmetric `H` (column-major `n × n`), reading only the upper triangle.
fn symv_upper(h: &[f64], n: usize, v: &[f64], out: &mut [f64]) {
    out.iter_mut().for_each(|o| *o = 0.0);
    for j in 0..n {
        let col = &h[j * n..j * n + j];
        let vj = v[j];
        if vj != 0.0 {
            for (o, c) in out[..j].iter_mut().zip(col) {
                *o += c * vj;
            }
        }
        out[j] += dot(col, &v[..j]) + h[j * n + j] * vj;
    }
}
