//! The per-frame trust-region QP (METHOD.md, "One frame"):
//! ```text
//! H = J_mᵀ W_m J_m + J_Φᵀ W_t J_Φ + W_damp,   g = J_mᵀ W_m r_m + J_Φᵀ W_t e_t
//! Δp* = argmin ½ Δpᵀ H Δp + gᵀ Δp   s.t.  l_b ≤ Δp ≤ u_b
//! Δf_pred = −gᵀΔp* − ½ Δp*ᵀ H Δp*,   Δf_act = Ẽ(p) − [Ẽ(p+Δp*) + ½ Δp*ᵀ W_damp Δp*]
//! ρ = Δf_act / (Δf_pred + ε_ρ);  accept iff Δf_act > 0
//! ```
//! `W_damp = λ·diag(max(H_kk, floor))` (Marquardt scaling). ρ > 0.75 lowers λ threefold (and
//! regrows a halved step box), ρ < 0.25 doubles it; a rejected step quadruples λ and halves the
//! step box. The bounds are the step box intersected with the proxy ranges. Convergence tests
//! (relative decrease, step size, model error) are not trusted after a step the box cut.

use super::qp::{LinearConstraints, QpProblem, QpSolver};
use super::settings::SolverSettings;
use crate::kinematics::assembly::{EvalWorkspace, Evaluator, FrameProblem, GaussNewton};
use crate::kinematics::backend::{EnergyEval, GnView, HessianView};
use crate::model::proxy::ProxyKind;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// How a frame's solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameStatus {
    /// A termination test (residual, relative decrease, step size) was met.
    Converged,
    /// The iteration cap was reached; the best accepted iterate is returned.
    MaxIterations,
    /// Fewer observed markers than `min_markers`: not solved (the caller bridges it).
    TooFewMarkers,
    /// The QP failed; the best accepted iterate is returned.
    QpFailed,
    /// Every step was rejected up to the largest damping; the best accepted iterate is returned.
    Stalled,
}

/// Statistics of one frame's solve.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct FrameStats {
    /// Trust-region iterations (QP solves).
    pub iterations: u32,
    /// Accepted steps.
    pub accepted: u32,
    /// Final objective `E`.
    pub energy: f64,
    /// Final marker RMSE (m).
    pub rmse_m: f64,
    /// Observed markers used.
    pub markers_used: usize,
    pub status: FrameStatus,
}

/// Solves frames one at a time; holds all scratch, so one per thread.
pub struct FrameSolver<'e> {
    pub eval: &'e Evaluator<'e>,
    pub settings: SolverSettings,
    qp: Box<dyn QpSolver>,
    pub ws: EvalWorkspace,
    /// `H + W_damp` of the current step (off-diagonal: `H` as loaded at the linearisation).
    h: DMatrix<f64>,
    /// The undamped diagonal of `H` at the last linearisation.
    h_diag: DVector<f64>,
    damp: DVector<f64>,
    lb: DVector<f64>,
    ub: DVector<f64>,
    dp: DVector<f64>,
    trial: Vec<f64>,
    step_box: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// Proxies the solver may move; the others keep their value (all true by default).
    pub free: Vec<bool>,
    /// Multiplies the step box (1 by default; the cold start widens it to travel far).
    pub step_multiplier: f64,
    /// The Gauss–Newton model at the current iterate, as the state machine reads it.
    pub gn: GaussNewton,
}

/// What a frame's trust-region iteration needs next (see [`FrameSolver::begin`]).
#[derive(Clone, Copy, Debug)]
pub enum Next {
    /// `(H, g, E)` at the current `p` into [`FrameSolver::gn`], then [`FrameSolver::linearized`].
    Linearize,
    /// `E` at [`FrameSolver::trial`], then [`FrameSolver::evaluated`].
    Energy,
    /// The frame is solved.
    Done(FrameStats),
}

/// The iteration state of one frame between evaluations.
#[derive(Clone, Copy, Debug)]
pub struct FrameIteration {
    pub stats: FrameStats,
    started: bool,
    lambda: f64,
    shrink: f64,
    shrink_used: f64,
    pred: f64,
    damp_pen: f64,
    step_max: f64,
}

impl<'e> FrameSolver<'e> {
    pub fn new(eval: &'e Evaluator<'e>, settings: SolverSettings, qp: Box<dyn QpSolver>) -> FrameSolver<'e> {
        let np = eval.proxy.np();
        let step_box = eval
            .proxy
            .proxies
            .iter()
            .map(|p| match p.kind {
                ProxyKind::Rotation => settings.step_rotation_rad,
                ProxyKind::Translation => settings.step_translation_m,
                ProxyKind::Scale => settings.step_scale,
            })
            .collect();
        FrameSolver {
            eval,
            qp,
            ws: EvalWorkspace::new(eval.model, eval.proxy),
            h: DMatrix::zeros(np, np),
            h_diag: DVector::zeros(np),
            damp: DVector::zeros(np),
            lb: DVector::zeros(np),
            ub: DVector::zeros(np),
            dp: DVector::zeros(np),
            trial: vec![0.0; np],
            step_box,
            lo: eval.proxy.proxies.iter().map(|p| p.range.0).collect(),
            hi: eval.proxy.proxies.iter().map(|p| p.range.1).collect(),
            free: vec![true; np],
            step_multiplier: 1.0,
            gn: EvalWorkspace::new(eval.model, eval.proxy).gn,
            settings,
        }
    }

    /// Name of the QP backend in use.
    pub fn qp_name(&self) -> &'static str {
        self.qp.name()
    }

    /// Narrows the range of every rotational proxy `k` to `centre[k] ± radius[k]` (rad), within
    /// its own range, until [`FrameSolver::reset_ranges`]: a step bounded from the course of the
    /// motion (the continuity of `pipeline::running::continuity`).
    pub fn bound_rotations(&mut self, centre: &[f64], radius: &[f64]) {
        for (k, px) in self.eval.proxy.proxies.iter().enumerate() {
            if px.kind == ProxyKind::Rotation && radius[k].is_finite() {
                let (lo, hi) = ((centre[k] - radius[k]).max(px.range.0), (centre[k] + radius[k]).min(px.range.1));
                if lo <= hi {
                    (self.lo[k], self.hi[k]) = (lo, hi);
                }
            }
        }
    }

    /// The proxy ranges back to the model's.
    pub fn reset_ranges(&mut self) {
        for (k, px) in self.eval.proxy.proxies.iter().enumerate() {
            (self.lo[k], self.hi[k]) = px.range;
        }
    }

    /// Clamps `p` into the proxy ranges.
    pub fn clamp(&self, p: &mut [f64]) {
        for (k, v) in p.iter_mut().enumerate() {
            *v = v.clamp(self.lo[k], self.hi[k]);
        }
    }

    /// Minimises the frame objective starting from `p` (the warm start), in place: the state
    /// machine of [`FrameSolver::begin`] driven with this solver's own CPU evaluations.
    pub fn solve(&mut self, frame: &FrameProblem<'_>, p: &mut [f64]) -> FrameStats {
        let mut it = self.begin(p);
        let mut next = Next::Linearize;
        loop {
            next = match next {
                Next::Linearize => {
                    self.eval.linearize(p, frame, &mut self.ws);
                    std::mem::swap(&mut self.gn, &mut self.ws.gn);
                    self.linearized(&mut it, p)
                }
                Next::Energy => {
                    let (energy, marker_sq_sum, markers_used) = self.eval.energy(&self.trial, frame, &mut self.ws);
                    self.evaluated(&mut it, p, EnergyEval { energy, marker_sq_sum, markers_used })
                }
                Next::Done(stats) => {
                    if stats.accepted == 0 || p.iter().zip(&self.trial).any(|(a, b)| a != b) {
                        // Leave the workspace's kinematics at the returned p.
                        self.eval.energy(p, frame, &mut self.ws);
                    }
                    // Keep `ws.gn` the model at the last linearisation, as callers may read it.
                    std::mem::swap(&mut self.gn, &mut self.ws.gn);
                    return stats;
                }
            };
        }
    }

    /// Starts a frame at the warm start `p` (clamped into the proxy ranges, in place). The caller
    /// then evaluates `(H, g, E)` at `p` into [`FrameSolver::gn`] and calls
    /// [`FrameSolver::linearized`]; after that it follows the returned [`Next`]: evaluate `E` at
    /// [`FrameSolver::trial`] and call [`FrameSolver::evaluated`], or linearise again at `p`, until
    /// `Done`. Driven this way it takes exactly the steps of [`FrameSolver::solve`].
    pub fn begin(&mut self, p: &mut [f64]) -> FrameIteration {
        self.clamp(p);
        FrameIteration {
            stats: FrameStats {
                iterations: 0,
                accepted: 0,
                energy: f64::NAN,
                rmse_m: f64::NAN,
                markers_used: 0,
                status: FrameStatus::MaxIterations,
            },
            started: false,
            lambda: self.settings.damping_init,
            shrink: 1.0,
            shrink_used: 1.0,
            pred: 0.0,
            damp_pen: 0.0,
            step_max: 0.0,
        }
    }

    /// Continues after `self.gn` was set to the Gauss–Newton model at `p`.
    pub fn linearized(&mut self, it: &mut FrameIteration, p: &[f64]) -> Next {
        if let Some(done) = self.first_checks(it) {
            return done;
        }
        load_h(&HessianView::Full(&self.gn.h), &mut self.h, &mut self.h_diag);
        self.step(it, p)
    }

    /// As [`FrameSolver::linearized`], with the model read from `view` where a backend left it
    /// (`g` and the statistics are copied into [`FrameSolver::gn`]; `H` goes straight into the
    /// step's matrix and `gn.h` is left as it was).
    pub fn linearized_view(&mut self, it: &mut FrameIteration, p: &[f64], view: &GnView<'_>) -> Next {
        let gn = &mut self.gn;
        gn.energy = view.energy;
        gn.marker_sq_sum = view.marker_sq_sum;
        gn.markers_used = view.markers_used;
        view.g.copy_to(gn.g.as_mut_slice());
        if let Some(done) = self.first_checks(it) {
            return done;
        }
        load_h(&view.h, &mut self.h, &mut self.h_diag);
        self.step(it, p)
    }

    /// The tests made once per frame, at its first linearisation.
    fn first_checks(&mut self, it: &mut FrameIteration) -> Option<Next> {
        if !it.started {
            it.started = true;
            let s = &self.settings;
            it.stats.energy = self.gn.energy;
            it.stats.rmse_m = self.gn.rmse();
            it.stats.markers_used = self.gn.markers_used;
            if it.stats.markers_used < s.min_markers {
                it.stats.status = FrameStatus::TooFewMarkers;
                return Some(Next::Done(it.stats));
            }
            if it.stats.rmse_m < s.residual_tol_m {
                it.stats.status = FrameStatus::Converged;
                return Some(Next::Done(it.stats));
            }
        }
        None
    }

    /// Solves the step QP at `p` with `self.gn` and sets [`FrameSolver::trial`].
    fn step(&mut self, it: &mut FrameIteration, p: &[f64]) -> Next {
        let s = &self.settings;
        if it.stats.iterations >= s.max_iterations {
            return Next::Done(it.stats);
        }
        it.stats.iterations += 1;
        let gn = &self.gn;
        let np = p.len();
        it.shrink_used = it.shrink;
        // Off the diagonal `self.h` holds H as loaded; the diagonal is re-damped each step.
        for k in 0..np {
            let d = it.lambda * self.h_diag[k].max(s.damping_floor);
            self.damp[k] = d;
            self.h[(k, k)] = self.h_diag[k] + d;
            let b = if self.free[k] { self.step_box[k] * it.shrink * self.step_multiplier } else { 0.0 };
            self.lb[k] = (-b).max(self.lo[k] - p[k]);
            self.ub[k] = b.min(self.hi[k] - p[k]);
        }
        self.dp.fill(0.0);
        if !self.eval.proxy.constraints.is_empty() {
            let c = step_constraints(self.eval.proxy, p);
            if self.qp.set_linear_constraints(Some(c)).is_err() {
                it.stats.status = FrameStatus::QpFailed;
                return Next::Done(it.stats);
            }
        }
        let problem = QpProblem { h: &self.h, g: &gn.g, lb: &self.lb, ub: &self.ub };
        if self.qp.solve(&problem, &mut self.dp).is_err() {
            it.stats.status = FrameStatus::QpFailed;
            return Next::Done(it.stats);
        }
        let g_dp = gn.g.dot(&self.dp);
        let hdp = quad_form(&self.h, &self.dp);
        it.pred = -g_dp - 0.5 * hdp;
        it.damp_pen = 0.5 * (0..np).map(|k| self.damp[k] * self.dp[k] * self.dp[k]).sum::<f64>();
        it.step_max = self.dp.amax();
        for k in 0..np {
            self.trial[k] = p[k] + self.dp[k];
        }
        Next::Energy
    }

    /// Continues with the objective `e` at [`FrameSolver::trial`]: accepts the step into `p` or
    /// rejects it. `self.gn` must still hold the model at `p`.
    pub fn evaluated(&mut self, it: &mut FrameIteration, p: &mut [f64], e: EnergyEval) -> Next {
        let s = &self.settings;
        let np = p.len();
        let e0 = self.gn.energy;
        let (e1, sq, used) = (e.energy, e.marker_sq_sum, e.markers_used);
        let act = e0 - (e1 + it.damp_pen);
        let rho = act / (it.pred + s.rho_eps);
        if act > 0.0 {
            it.stats.accepted += 1;
            p.copy_from_slice(&self.trial);
            it.stats.energy = e1;
            it.stats.rmse_m = if used > 0 { (sq / used as f64).sqrt() } else { f64::NAN };
            it.stats.markers_used = used;
            if rho > 0.75 {
                it.lambda = (it.lambda / 3.0).max(s.damping_min);
                it.shrink = (it.shrink * 2.0).min(1.0);
            } else if rho < 0.25 {
                it.lambda = (it.lambda * 2.0).min(s.damping_max);
            }
            // A step that the step box cut says nothing about convergence: the optimum may lie
            // further out (a subject that moved far during a gap), so only the residual test
            // may stop then.
            let box_cut = (0..np).any(|k| {
                let b = self.step_box[k] * it.shrink_used * self.step_multiplier;
                self.free[k] && self.dp[k].abs() >= b * (1.0 - 1e-9)
            });
            let rel = (e0 - e1) / e0.max(f64::MIN_POSITIVE);
            // The model's error over the step, |Δf_act − Δf_pred|, estimates what another
            // iteration could still gain (both include the damping penalty, which cancels).
            let model_error = (act - it.pred).abs() / e1.max(f64::MIN_POSITIVE);
            let exact_model = s.model_error_tol > 0.0 && model_error < s.model_error_tol && it.lambda <= s.damping_init;
            let converged = !box_cut && (rel < s.rel_decrease_tol || it.step_max < s.step_tol || exact_model);
            if it.stats.rmse_m < s.residual_tol_m || converged {
                it.stats.status = FrameStatus::Converged;
                return Next::Done(it.stats);
            }
            if it.stats.iterations >= s.max_iterations {
                return Next::Done(it.stats);
            }
            Next::Linearize
        } else {
            if it.step_max < s.step_tol {
                it.stats.status = FrameStatus::Converged;
                return Next::Done(it.stats);
            }
            if it.lambda >= s.damping_max {
                it.stats.status = FrameStatus::Stalled;
                return Next::Done(it.stats);
            }
            it.lambda = (it.lambda * 4.0).min(s.damping_max);
            it.shrink *= 0.5;
            // `self.gn` still holds H and g at p; only the trial point moves.
            self.step(it, p)
        }
    }

    /// The trial point `p + Δp` of the last step.
    pub fn trial(&self) -> &[f64] {
        &self.trial
    }
}

/// The profile's constraints `lo ≤ a·p ≤ hi` as constraints on a step from `p`.
pub fn step_constraints(proxy: &crate::model::proxy::ProxyMap, p: &[f64]) -> LinearConstraints {
    let m = proxy.constraints.len();
    let mut c = LinearConstraints { a: DMatrix::zeros(m, proxy.np()), lo: DVector::zeros(m), hi: DVector::zeros(m) };
    for (i, pc) in proxy.constraints.iter().enumerate() {
        for &(k, coef) in &pc.coefficients {
            c.a[(i, k)] += coef;
        }
        let v = pc.value(p);
        c.lo[i] = pc.lo - v;
        c.hi[i] = pc.hi - v;
    }
    c
}

/// `H` into the step matrix `h` (both triangles) and its diagonal into `diag`, for the steps of
/// one linearisation.
fn load_h(src: &HessianView<'_>, h: &mut DMatrix<f64>, diag: &mut DVector<f64>) {
    src.write_full(h);
    for k in 0..diag.len() {
        diag[k] = h[(k, k)];
    }
}

/// `xᵀ H x` without allocating.
fn quad_form(h: &DMatrix<f64>, x: &DVector<f64>) -> f64 {
    let n = x.len();
    (0..n).map(|c| x[c] * (0..n).map(|r| h[(r, c)] * x[r]).sum::<f64>()).sum()
}

impl std::fmt::Debug for FrameSolver<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameSolver").field("qp", &self.qp.name()).field("settings", &self.settings).finish()
    }
}
