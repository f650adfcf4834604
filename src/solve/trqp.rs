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
use crate::kinematics::assembly::{EvalWorkspace, Evaluator, FrameProblem};
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
    h: DMatrix<f64>,
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
            settings,
        }
    }

    /// Name of the QP backend in use.
    pub fn qp_name(&self) -> &'static str {
        self.qp.name()
    }

    /// Clamps `p` into the proxy ranges.
    pub fn clamp(&self, p: &mut [f64]) {
        for (k, v) in p.iter_mut().enumerate() {
            *v = v.clamp(self.lo[k], self.hi[k]);
        }
    }

    /// Minimises the frame objective starting from `p` (the warm start), in place.
    pub fn solve(&mut self, frame: &FrameProblem<'_>, p: &mut [f64]) -> FrameStats {
        let s = &self.settings;
        self.clamp(p);
        self.eval.linearize(p, frame, &mut self.ws);
        let mut stats = FrameStats {
            iterations: 0,
            accepted: 0,
            energy: self.ws.gn.energy,
            rmse_m: self.ws.gn.rmse(),
            markers_used: self.ws.gn.markers_used,
            status: FrameStatus::MaxIterations,
        };
        if stats.markers_used < s.min_markers {
            stats.status = FrameStatus::TooFewMarkers;
            return stats;
        }
        if stats.rmse_m < s.residual_tol_m {
            stats.status = FrameStatus::Converged;
            return stats;
        }
        let mut lambda = s.damping_init;
        let mut shrink = 1.0;
        let np = p.len();
        while stats.iterations < s.max_iterations {
            stats.iterations += 1;
            let gn = &self.ws.gn;
            let shrink_used = shrink;
            self.h.copy_from(&gn.h);
            for k in 0..np {
                let d = lambda * gn.h[(k, k)].max(s.damping_floor);
                self.damp[k] = d;
                self.h[(k, k)] += d;
                let b = if self.free[k] { self.step_box[k] * shrink * self.step_multiplier } else { 0.0 };
                self.lb[k] = (-b).max(self.lo[k] - p[k]);
                self.ub[k] = b.min(self.hi[k] - p[k]);
            }
            self.dp.fill(0.0);
            if !self.eval.proxy.constraints.is_empty() {
                let c = step_constraints(self.eval.proxy, p);
                if self.qp.set_linear_constraints(Some(c)).is_err() {
                    stats.status = FrameStatus::QpFailed;
                    break;
                }
            }
            let problem = QpProblem { h: &self.h, g: &gn.g, lb: &self.lb, ub: &self.ub };
            if self.qp.solve(&problem, &mut self.dp).is_err() {
                stats.status = FrameStatus::QpFailed;
                break;
            }
            let g_dp = gn.g.dot(&self.dp);
            let hdp = quad_form(&self.h, &self.dp);
            let pred = -g_dp - 0.5 * hdp;
            let damp_pen: f64 = 0.5 * (0..np).map(|k| self.damp[k] * self.dp[k] * self.dp[k]).sum::<f64>();
            let step_max = self.dp.amax();
            for k in 0..np {
                self.trial[k] = p[k] + self.dp[k];
            }
            let e0 = gn.energy;
            let (e1, sq, used) = self.eval.energy(&self.trial, frame, &mut self.ws);
            let act = e0 - (e1 + damp_pen);
            let rho = act / (pred + s.rho_eps);
            if act > 0.0 {
                stats.accepted += 1;
                p.copy_from_slice(&self.trial);
                stats.energy = e1;
                stats.rmse_m = if used > 0 { (sq / used as f64).sqrt() } else { f64::NAN };
                stats.markers_used = used;
                if rho > 0.75 {
                    lambda = (lambda / 3.0).max(s.damping_min);
                    shrink = (shrink * 2.0).min(1.0);
                } else if rho < 0.25 {
                    lambda = (lambda * 2.0).min(s.damping_max);
                }
                // A step that the step box cut says nothing about convergence: the optimum may lie
                // further out (a subject that moved far during a gap), so only the residual test
                // may stop then.
                let box_cut = (0..np).any(|k| {
                    let b = self.step_box[k] * shrink_used * self.step_multiplier;
                    self.free[k] && self.dp[k].abs() >= b * (1.0 - 1e-9)
                });
                let rel = (e0 - e1) / e0.max(f64::MIN_POSITIVE);
                // The model's error over the step, |Δf_act − Δf_pred|, estimates what another
                // iteration could still gain (both include the damping penalty, which cancels).
                let model_error = (act - pred).abs() / e1.max(f64::MIN_POSITIVE);
                let exact_model =
                    s.model_error_tol > 0.0 && model_error < s.model_error_tol && lambda <= s.damping_init;
                let converged = !box_cut && (rel < s.rel_decrease_tol || step_max < s.step_tol || exact_model);
                if stats.rmse_m < s.residual_tol_m || converged {
                    stats.status = FrameStatus::Converged;
                    break;
                }
                self.eval.linearize(p, frame, &mut self.ws);
            } else {
                if step_max < s.step_tol {
                    stats.status = FrameStatus::Converged;
                    break;
                }
                if lambda >= s.damping_max {
                    stats.status = FrameStatus::Stalled;
                    break;
                }
                lambda = (lambda * 4.0).min(s.damping_max);
                shrink *= 0.5;
                // `ws.gn` still holds H and g at p; only the kinematics moved to the trial point.
            }
        }
        if stats.accepted == 0 || p.iter().zip(&self.trial).any(|(a, b)| a != b) {
            // Leave the workspace's kinematics at the returned p.
            self.eval.energy(p, frame, &mut self.ws);
        }
        stats
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
