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
//! 5. projected search along the path `x(t) = P(x + t d)`, `t ∈ (0, 1]`: start from its exact
//!    minimiser `t*` (`f` is piecewise quadratic in `t`; scan the breakpoints where variables
//!    reach bounds, `O(n)` each), backtrack `t ← β t` until `f(x(t)) − f(x) ≤ σ ∇fᵀ(x(t) − x)`.
//!    MuJoCo backtracks from `t = 1` instead, which crawls towards a single bound when the
//!    Newton step leaves the box far behind (ill-conditioned or regularised `H_FF`); on random
//!    well-conditioned problems the two need about the same number of iterations.
//!
//! Variables within `10⁻¹⁴` (relative) of a bound are snapped onto it before step 2. Stops on the
//! projected-gradient test (`Solved`), a full step (`t = 1`) decreasing `f` by less than
//! `min_relative_improvement·|f|`, a search that cannot decrease `f` (`Solved` if the projected
//! gradient is below `√gradient_tolerance·(1 + ‖g‖∞)`, else `MaxIterations`), or the iteration
//! cap (`MaxIterations`). A warm start whose objective overflows is replaced by `P(0)`.
//!
//! Singular `H_FF` (PSD `H`): a pivot `≤ ε s` (`ε = regularization`, `s` = largest free diagonal
//! entry, or 1) triggers one refactorisation of `H_FF + ε s I`; a pivot `≤ ½ ε s` there means
//! `H_FF` is indefinite → [`QpError::NotPositiveDefinite`]. A regularised step that no bound
//! blocks and along which `f` is nearly linear (`dᵀHd < 10⁻⁶ |∇fᵀd|`) means `f` is unbounded
//! below on the box → also `NotPositiveDefinite`, naming the singular pivot.
//!
//! Only the upper triangle of `H` is read (and, with [`BoxQp::symmetric`], the lower one, in
//! place of it, for the factorisation). Workspace grows to the largest `n` seen; no
//! allocation afterwards.

mod dense;

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
    /// Stop when a full Newton step decreases `f` by less than this times `|f|`. Default 1e-12.
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
    /// The caller fills both triangles of `H` (symmetric): the factorisation then copies `H_FF`
    /// from its contiguous lower columns instead of gathering the upper rows. Default false.
    pub symmetric: bool,
    grad: Vec<f64>,
    dir: Vec<f64>,
    cand: Vec<f64>,
    step: Vec<f64>,
    hd: Vec<f64>,
    clamped: Vec<bool>,
    free: Vec<usize>,
    /// Breakpoints `(t, variable)` of the projected path.
    breaks: Vec<(f64, usize)>,
    /// `nf × nf` column-major; the lower triangle holds `L` after a successful factorisation.
    chol: Vec<f64>,
    inv_diag: Vec<f64>,
    rhs: Vec<f64>,
}

/// Cap on backtracking steps, independent of `line_search_factor`/`min_step`.
const MAX_LINE_SEARCH: u32 = 80;
/// Relative distance to a bound below which a variable is moved onto it.
const SNAP: f64 = 1e-14;
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
        self.free.clear();
        self.free.reserve(n);
        self.breaks.clear();
        self.breaks.reserve(n);
        self.chol.resize(n * n, 0.0);
    }

    /// Gathers `H_FF + shift·I` and factors it in place. `Err((k, pivot))` on pivot `k ≤ thr`.
    fn factor(&mut self, h: &[f64], n: usize, shift: f64, thr: f64) -> Result<(), (usize, f64)> {
        let nf = self.free.len();
        let chol = &mut self.chol[..nf * nf];
        for (a, &fa) in self.free.iter().enumerate() {
            let col = &mut chol[a * nf + a..(a + 1) * nf];
            if !self.symmetric {
                // L-column a, rows b ≥ a: H[fa, fb] read from the upper triangle (fa ≤ fb).
                for (c, &fb) in col.iter_mut().zip(&self.free[a..]) {
                    *c = h[fb * n + fa];
                }
            } else if self.free[nf - 1] - fa == nf - 1 - a {
                // The free variables from fa on are a run: H's column fa below the diagonal.
                col.copy_from_slice(&h[fa * n + fa..fa * n + fa + nf - a]);
            } else {
                for (c, &fb) in col.iter_mut().zip(&self.free[a..]) {
                    *c = h[fa * n + fb];
                }
            }
            col[0] += shift;
        }
        dense::cholesky(chol, &mut self.inv_diag, nf, thr)
    }

    /// Sets `grad = H x + g` and returns `f(x) = ½ xᵀ(grad + g)` (non-finite if `grad` is).
    fn gradient(&mut self, h: &[f64], g: &[f64], x: &[f64]) -> f64 {
        let n = g.len();
        if x.iter().all(|&v| v == 0.0) {
            // H 0 is +0 in every entry (H is finite): what the product gives, without it.
            self.grad[..n].fill(0.0);
        } else {
            dense::symv_upper(h, n, x, &mut self.grad[..n]);
        }
        for (gr, gi) in self.grad[..n].iter_mut().zip(g) {
            *gr += gi;
        }
        objective(x, &self.grad[..n], g)
    }

    /// `dir_F = −H_FF⁻¹ ∇f_F`, `dir_C = 0`, using the current factor.
    fn newton_direction(&mut self) {
        let nf = self.free.len();
        let chol = &self.chol[..nf * nf];
        let y = &mut self.rhs[..nf];
        for (ya, &fa) in y.iter_mut().zip(&self.free) {
            *ya = self.grad[fa];
        }
        dense::cholesky_solve(chol, &self.inv_diag[..nf], y);
        self.dir.iter_mut().for_each(|d| *d = 0.0);
        for (&ya, &fa) in y.iter().zip(&self.free) {
            self.dir[fa] = -ya;
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
        let (h, g) = (problem.h.as_slice(), problem.g.as_slice());
        let (lb, ub) = (problem.lb.as_slice(), problem.ub.as_slice());
        let x = x.as_mut_slice();
        let (max_iter, min_rel) = (self.settings.max_iterations, self.settings.min_relative_improvement);
        let g_scale = 1.0 + g.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let tol = self.settings.gradient_tolerance;
        let (gtol, stall_tol) = (tol * g_scale, tol.sqrt() * g_scale);

        for i in 0..n {
            x[i] = if x[i].is_finite() { x[i] } else { 0.0 }.max(lb[i]).min(ub[i]);
        }
        let mut f = self.gradient(h, g, x);
        if !f.is_finite() {
            // The warm start overflows f: restart from the projection of the origin.
            for i in 0..n {
                x[i] = 0.0_f64.max(lb[i]).min(ub[i]);
            }
            f = self.gradient(h, g, x);
            if !f.is_finite() {
                return Err(QpError::NonFinite { what: "objective", index: 0 });
            }
        }

        let mut factored = false;
        let mut singular = None;
        let mut status = QpStatus::MaxIterations;
        let mut iterations = 0;
        for iter in 0..=max_iter {
            iterations = iter;
            let (pg, changed) = self.active_set(x, lb, ub);
            if pg <= gtol {
                status = QpStatus::Solved;
                break;
            }
            if iter == max_iter {
                break;
            }
            if changed || !factored {
                singular = self.factor_free(h, n)?;
                factored = true;
            }
            self.newton_direction();
            let slope: f64 = self.free.iter().map(|&i| self.grad[i] * self.dir[i]).sum();
            if slope.is_nan() {
                return Err(QpError::NonFinite { what: "newton direction", index: 0 });
            }
            if slope >= 0.0 {
                status = QpStatus::Solved; // gradient at rounding level
                break;
            }
            let Some((t, df)) = self.line_search(h, x, lb, ub, singular)? else {
                // No numerical decrease possible: converged to working precision if the
                // projected gradient is small on a looser scale, stuck otherwise.
                if pg <= stall_tol {
                    status = QpStatus::Solved;
                }
                break;
            };
            x.copy_from_slice(&self.cand[..n]);
            for (gr, hd) in self.grad[..n].iter_mut().zip(&self.hd[..n]) {
                *gr += hd;
            }
            let f_old = f;
            f += df;
            if t == 1.0 && -df <= min_rel * f_old.abs() {
                iterations = iter + 1;
                status = QpStatus::Solved;
                break;
            }
        }
        Ok(QpStats { status, iterations, objective: objective(x, &self.grad[..n], g) })
    }
}

impl BoxQp {
    /// Recomputes the clamped and free sets at `x` (snapping `x` onto bounds closer than
    /// `SNAP` relative); returns the projected-gradient norm
    /// `max_{i∈F} |∇f_i|` and whether the clamped set changed.
    fn active_set(&mut self, x: &mut [f64], lb: &[f64], ub: &[f64]) -> (f64, bool) {
        let mut changed = false;
        let mut pg = 0.0_f64;
        self.free.clear();
        for i in 0..x.len() {
            // Snap to a bound within rounding distance, so that it can be clamped exactly.
            if lb[i].is_finite() && x[i] - lb[i] <= SNAP * lb[i].abs().max(1.0) {
                x[i] = lb[i];
            } else if ub[i].is_finite() && ub[i] - x[i] <= SNAP * ub[i].abs().max(1.0) {
                x[i] = ub[i];
            }
            let gi = self.grad[i];
            let c = lb[i] == ub[i] || (x[i] <= lb[i] && gi > 0.0) || (x[i] >= ub[i] && gi < 0.0);
            changed |= c != self.clamped[i];
            self.clamped[i] = c;
            if !c {
                self.free.push(i);
                pg = pg.max(gi.abs());
            }
        }
        (pg, changed)
    }

    /// Factors `H_FF`, retrying once with the regularisation shift. Returns the singular pivot
    /// `(variable, value)` when the shift was needed.
    fn factor_free(&mut self, h: &[f64], n: usize) -> Result<Option<(usize, f64)>, QpError> {
        let scale = self.free.iter().fold(0.0_f64, |m, &i| m.max(h[i * n + i]));
        let shift = self.settings.regularization * if scale > 0.0 { scale } else { 1.0 };
        let Err((k, value)) = self.factor(h, n, 0.0, shift) else {
            return Ok(None);
        };
        let pivot = self.free[k];
        match self.factor(h, n, shift, 0.5 * shift) {
            Ok(()) => Ok(Some((pivot, value))),
            Err(_) => Err(QpError::NotPositiveDefinite { pivot, value }),
        }
    }

    /// Minimiser `t* ∈ (0, 1]` of `f` along the projected path `x(t) = P(x + t·dir)` (the first
    /// local minimiser of this piecewise quadratic): breakpoints are visited in order, fixing
    /// each variable as it reaches its bound and updating `f'`, `f''` in `O(n)` per breakpoint.
    /// Uses `cand` (gradient along the path), `step` (path direction `p`) and `hd` (`H p`); the
    /// flag tells whether `t*` lies before the first breakpoint, `hd` then still holding `H dir`.
    fn path_minimiser(&mut self, h: &[f64], x: &[f64], lb: &[f64], ub: &[f64]) -> (f64, bool) {
        let n = x.len();
        self.breaks.clear();
        for &i in &self.free {
            let d = self.dir[i];
            let tau = if d > 0.0 { (ub[i] - x[i]) / d } else { (lb[i] - x[i]) / d };
            if d != 0.0 && tau < 1.0 {
                self.breaks.push((tau.max(0.0), i));
            }
        }
        self.breaks.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let (r, p, hp) = (&mut self.cand[..n], &mut self.step[..n], &mut self.hd[..n]);
        r.copy_from_slice(&self.grad[..n]);
        p.copy_from_slice(&self.dir[..n]);
        dense::symv_upper(h, n, p, hp);
        let (mut fp, mut fpp, mut t) = (dense::dot(r, p), dense::dot(p, hp), 0.0);
        for k in 0..=self.breaks.len() {
            let t_end = self.breaks.get(k).map_or(1.0, |b| b.0);
            if fp >= 0.0 {
                return (t, k == 0);
            }
            if fpp > 0.0 && t - fp / fpp <= t_end {
                return (t - fp / fpp, k == 0);
            }
            let Some(&(_, b)) = self.breaks.get(k) else {
                return (1.0, k == 0);
            };
            // Advance to the breakpoint, then fix variable b there.
            let dt = t_end - t;
            for (ri, hpi) in r.iter_mut().zip(hp.iter()) {
                *ri += dt * hpi;
            }
            (fp, t) = (fp + dt * fpp, t_end);
            let pb = p[b];
            fpp += pb * (pb * h[b * n + b] - 2.0 * hp[b]);
            fp -= pb * r[b];
            p[b] = 0.0;
            for (i, hpi) in hp.iter_mut().enumerate() {
                // H[i, b] from the upper triangle.
                *hpi -= pb * if i <= b { h[b * n + i] } else { h[i * n + b] };
            }
        }
        (t, false)
    }

    /// Step along the projected path: the exact path minimiser `t*`, then `β t*, β² t*, …` until
    /// `Δf ≤ σ ∇fᵀ(x(t) − x) < 0`. On success returns `(t, Δf)` with the new point in `cand`
    /// and `H (cand − x)` in `hd`; `None` if no step decreases `f`. `singular` (from
    /// [`Self::factor_free`]) enables the unboundedness test of the module docs.
    fn line_search(
        &mut self,
        h: &[f64],
        x: &[f64],
        lb: &[f64],
        ub: &[f64],
        singular: Option<(usize, f64)>,
    ) -> Result<Option<(f64, f64)>, QpError> {
        let n = x.len();
        let st = &self.settings;
        let beta = if st.line_search_factor > 0.0 && st.line_search_factor < 1.0 { st.line_search_factor } else { 0.5 };
        let (armijo, min_step) = (st.armijo, st.min_step);
        let (mut t, mut have_hd) = self.path_minimiser(h, x, lb, ub);
        for _ in 0..MAX_LINE_SEARCH {
            if t.is_nan() || t <= min_step {
                break;
            }
            let mut clipped = false;
            for i in 0..n {
                let raw = if self.clamped[i] { x[i] } else { x[i] + t * self.dir[i] };
                let c = raw.max(lb[i]).min(ub[i]);
                clipped |= c != raw;
                self.cand[i] = c;
                self.step[i] = c - x[i];
            }
            if have_hd && !clipped {
                // step = t·dir before the first breakpoint: reuse H dir.
                self.hd[..n].iter_mut().for_each(|v| *v *= t);
            } else {
                dense::symv_upper(h, n, &self.step[..n], &mut self.hd[..n]);
            }
            have_hd = false;
            let lin = dense::dot(&self.grad[..n], &self.step[..n]);
            let curv = dense::dot(&self.step[..n], &self.hd[..n]);
            if let Some((pivot, value)) = singular {
                if t == 1.0 && !clipped && curv < UNBOUNDED_CURVATURE * lin.abs() {
                    return Err(QpError::NotPositiveDefinite { pivot, value });
                }
            }
            let df = lin + 0.5 * curv;
            if lin < 0.0 && df <= armijo * lin {
                return Ok(Some((t, df)));
            }
            t *= beta;
        }
        Ok(None)
    }
}

/// `f = ½ xᵀ H x + gᵀ x = ½ xᵀ (grad + g)` given `grad = H x + g`; non-finite if any term is.
fn objective(x: &[f64], grad: &[f64], g: &[f64]) -> f64 {
    let finite = grad.iter().all(|v| v.is_finite());
    if finite {
        0.5 * x.iter().zip(grad).zip(g).map(|((a, b), c)| a * (b + c)).sum::<f64>()
    } else {
        f64::NAN
    }
}
