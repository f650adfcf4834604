//! Subject calibration: one morphology per subject from several frames at once.
//!
//! Unknowns: the shared scale proxies `s` and one set of pose proxies `q_k` per frame `k`.
//! Each frame contributes its Gauss–Newton blocks `[A_k B_k; B_kᵀ C_k]` (pose/scale); the
//! damped step eliminates the poses through the Schur complement
//! ```text
//! (C + Σ C_k − Σ B_kᵀ A_k⁻¹ B_k) Δs = −g_s − Σ (g_s,k − B_kᵀ A_k⁻¹ g_q,k)
//! Δq_k = −A_k⁻¹ (g_q,k + B_k Δs)
//! ```
//! (`A_k`, `C` damped Levenberg–Marquardt style). The scale step solves that reduced quadratic
//! as a QP under the scale ranges and the profile's constraints on scale proxies (e.g. left/right
//! symmetry); the poses follow by back-substitution, clipped to their ranges (a pose at an end of
//! its range that the gradient pushes beyond is held for the step). A step is accepted when the
//! total objective decreases; a stage stops on the objective's relative progress
//! (`calibration_rel_tol`). A weak prior pulls unobservable scales toward 1.
//!
//! Cost: eliminating the poses leaves a dense system over `z` (scales and offsets, `nz` ≈ 175),
//! where eliminating the offsets (3 × 3 blocks) would leave one over every frame's pose; it is
//! formed from each frame's `UᵀU` (`super::schur`: frames linearised by the frame solver's
//! per-body Gauss–Newton, poses ordered leaves first so that the zeros of `U` are skipped,
//! frames in parallel in fixed pieces), the linearisation kept across rejected steps
//! (docs/CALIBRATION.md, "Which unknowns to eliminate").

use super::calibration::Calibration;
use super::init::multi_start;
use super::joint::{JointOutcome, JointProblem, JointState};
use super::prior::{GlobalTerm, Globals};
use super::qp::{BoxQp, ClarabelQp, LinearConstraints, QpProblem, QpSolver};
use super::schur::JointScratch;
use super::trqp::FrameSolver;
use crate::kinematics::assembly::{EvalWorkspace, Evaluator, FrameProblem};
use crate::model::fixed;
use crate::model::proxy::ProxyKind;
use crate::model::proxy::ProxyMap;
use crate::model::Model;
use nalgebra::{DMatrix, DVector, Vector3};

impl JointProblem<'_> {
    pub(super) fn model_with(&self, offsets: &[Vector3<f64>]) -> Model {
        let mut m = self.model.clone();
        for (mk, o) in m.markers.iter_mut().zip(offsets) {
            mk.offset = *o;
        }
        m
    }

    /// Offset columns in `z` of the registered markers observed in some frame.
    fn offset_columns(&self, ns: usize) -> Vec<Option<usize>> {
        let mut next = ns;
        (0..self.model.markers.len())
            .map(|m| {
                let seen = self
                    .frames
                    .iter()
                    .zip(self.weights)
                    .any(|(f, w)| w[m] > 0.0 && f[3 * m..3 * m + 3].iter().all(|v| !v.is_nan()));
                (self.registered[m] && seen).then(|| {
                    next += 3;
                    next - 3
                })
            })
            .collect()
    }

    /// Total objective and mean RMSE at `state`.
    fn total(&self, state: &JointState, scale: &[usize], cols: &[Option<usize>]) -> (f64, f64) {
        let model = self.model_with(&state.offsets);
        let eval = Evaluator::new(&model, self.proxy);
        let mut ws = EvalWorkspace::new(&model, self.proxy);
        let (mut e, mut rmse, mut counted) = (0.0, 0.0, 0);
        for (k, ((obs, p), w)) in self.frames.iter().zip(&state.poses).zip(self.weights).enumerate() {
            let fp = FrameProblem {
                observed: obs,
                marker_weights: w,
                tracking_ref: self.tracking_refs[k],
                tracking_weights: self.tracking_weights[k],
            };
            let (ek, sq, used) = eval.energy(p, &fp, &mut ws);
            e += ek;
            if used > 0 {
                rmse += (sq / used as f64).sqrt();
                counted += 1;
            }
        }
        let g = Globals { p: &state.poses[0], scale, offsets: &state.offsets, offset_col: cols };
        e += self.terms.iter().map(|t| t.add(&g, None)).sum::<f64>();
        (e, if counted > 0 { rmse / counted as f64 } else { f64::NAN })
    }

    /// Levenberg–Marquardt on all unknowns, the poses eliminated by their Schur complement.
    pub fn solve(&self, state: &mut JointState) -> JointOutcome {
        JointScratch::with(|scratch| self.solve_in(state, scratch))
    }

    /// [`JointProblem::solve`] in `scratch`'s buffers.
    fn solve_in(&self, state: &mut JointState, scratch: &mut JointScratch) -> JointOutcome {
        let s = self.settings;
        let (scale, pose) = self.scale_indices();
        let ns = scale.len();
        let cols = self.offset_columns(ns);
        let nz = ns + 3 * cols.iter().filter(|c| c.is_some()).count();
        let (lo, hi): (Vec<f64>, Vec<f64>) = self.proxy.proxies.iter().map(|p| p.range).unzip();
        let (mut energy, mut rmse) = self.total(state, &scale, &cols);
        let mut lambda = 1e-4;
        // Nielsen's damping update: λ follows the gain ratio of each kept step; `nu` grows on
        // consecutive rejections.
        let mut nu = 2.0;
        let mut iterations = 0;
        let mut rejected = 0;
        // The cap counts kept steps (a run of rejected ones ends when the damping passes 1e8).
        let gain_ratio = s.calibration_gain_ratio;
        // The linearisation at the current state, kept across rejected steps.
        let JointScratch { linear, elim } = scratch;
        let mut fresh = false;
        let mut boxqp = BoxQp::new();
        // The relative progress of the step before, when its model predicted it (else 0).
        let mut rel_before = 0.0f64;
        while iterations - rejected < s.calibration_max_iterations && !self.frames.is_empty() {
            iterations += 1;
            if !fresh {
                self.linearize(state, (&scale, &pose), &cols, nz, linear);
                fresh = true;
            }
            let lin = &*linear;
            self.eliminate(lin, lambda, elim);
            let schur = &mut elim.schur;
            let neg_gz = &lin.neg_gz;
            // `rhs` is −g_z plus the poses' elimination, Σ Uᵀw.
            let rhs = neg_gz + &elim.reduced;
            let damping_z = DVector::from_fn(nz, |d, _| lambda * schur[(d, d)].max(s.damping_floor));
            for d in 0..nz {
                schur[(d, d)] += damping_z[d];
            }
            // Bounds: scale ranges, offsets within the bound around their reference.
            let p_now = &state.poses[0];
            let mut lb = DVector::zeros(nz);
            let mut ub = DVector::zeros(nz);
            for (i, &k) in scale.iter().enumerate() {
                lb[i] = lo[k] - p_now[k];
                ub[i] = hi[k] - p_now[k];
            }
            for (m, c) in cols.iter().enumerate() {
                let Some(c) = *c else { continue };
                for a in 0..3 {
                    let d = state.offsets[m][a] - self.reference[m][a];
                    lb[c + a] = -self.bound_m - d;
                    ub[c + a] = self.bound_m - d;
                }
            }
            let neg_rhs = -&rhs;
            let problem = QpProblem { h: schur, g: &neg_rhs, lb: &lb, ub: &ub };
            let mut dz = DVector::zeros(nz);
            let solved = match scale_constraints(self.proxy, &scale, p_now) {
                Some(mut c) => {
                    // Pad the constraint rows with zero columns for the offsets.
                    let mut a = DMatrix::zeros(c.a.nrows(), nz);
                    a.columns_mut(0, ns).copy_from(&c.a);
                    c.a = a;
                    let mut qp = ClarabelQp::new(Default::default());
                    qp.set_constraints(Some(c));
                    qp.solve(&problem, &mut dz)
                }
                None => boxqp.solve(&problem, &mut dz),
            };
            if solved.is_err() {
                break;
            }
            let mut next = state.clone();
            for (m, c) in cols.iter().enumerate() {
                if let Some(c) = *c {
                    for a in 0..3 {
                        let v = next.offsets[m][a] + dz[c + a];
                        let r = self.reference[m][a];
                        next.offsets[m][a] = v.clamp(r - self.bound_m, r + self.bound_m);
                    }
                }
            }
            // Decrease the damped model predicts, ½ (δᵀ λD δ − gᵀδ) over poses and z.
            let mut predicted = 0.5 * (dz.dot(&damping_z.component_mul(&dz)) + neg_gz.dot(&dz));
            let ds = dz.rows(0, ns).into_owned();
            for ((p, fb), f) in next.poses.iter_mut().zip(&elim.blocks).zip(&lin.frames) {
                for (i, &k) in scale.iter().enumerate() {
                    p[k] = (p[k] + ds[i]).clamp(lo[k], hi[k]);
                }
                if !fb.ok {
                    continue;
                }
                let mut dq = &fb.w + fixed::mul_v(&fb.u, &dz);
                fb.l.tr_solve_lower_triangular_unchecked_mut(&mut dq);
                dq.neg_mut();
                predicted += 0.5 * (dq.dot(&fb.damping.component_mul(&dq)) - f.gq.dot(&dq));
                for (i, &k) in pose.iter().enumerate() {
                    p[k] = (p[k] + dq[i]).clamp(lo[k], hi[k]);
                }
            }
            let (e1, r1) = self.total(&next, &scale, &cols);
            if e1 < energy {
                let rel = (energy - e1) / energy.max(f64::MIN_POSITIVE);
                let energy_before = energy;
                *state = next;
                fresh = false;
                energy = e1;
                rmse = r1;
                if gain_ratio {
                    let rho = if predicted > 0.0 { (energy_before - e1) / predicted } else { 1.0 };
                    lambda = (lambda * (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0)).max(1e-9);
                    nu = 2.0;
                } else {
                    lambda = (lambda / 3.0).max(1e-9);
                }
                // Converged: the objective stopped falling, or the subject stopped moving (scale
                // factors and offsets changed by less than 1e-5, i.e. 10 µm on a metre).
                if rel < s.calibration_rel_tol || dz.amax() < 1e-5 {
                    break;
                }
                // Or what is left to gain is below the tolerance: after two steps in a row that
                // each gained what their model predicted (within 10 %), progress falling by
                // `r = rel / rel_before` per step leaves about `rel · r / (1 − r)` (docs/CALIBRATION.md,
                // "The solver").
                let as_predicted = predicted > 0.0 && ((energy_before - e1) / predicted - 1.0).abs() <= 0.1;
                if as_predicted && rel_before > 0.0 {
                    let r = rel / rel_before;
                    if r < 1.0 && rel * r / (1.0 - r) < s.calibration_rel_tol {
                        break;
                    }
                }
                rel_before = if as_predicted { rel } else { 0.0 };
            } else if predicted < s.calibration_rel_tol * energy || dz.amax() < 1e-4 {
                // Rejected, and the model itself sees less to gain than the tolerance, or the step
                // moves no scale factor or offset by 1e-4 (0.1 mm on a metre, below any marker
                // noise): stop here rather than damp toward a step too small to matter.
                rejected += 1;
                break;
            } else {
                rejected += 1;
                rel_before = 0.0;
                if gain_ratio {
                    lambda *= nu;
                    nu *= 2.0;
                } else {
                    lambda *= 4.0;
                }
                if lambda > 1e8 {
                    break;
                }
            }
        }
        JointOutcome { iterations: iterations - rejected, rejected, energy, rmse_m: rmse }
    }
}

/// Calibrates the scale proxies (offsets fixed) on `frames` (observed marker arrays,
/// `3·marker + axis`, NaN gaps). `frame_template` supplies weights and tracking arrays (its
/// `observed` is ignored). `starts` gives each frame's initial proxies (see [`track`]); their
/// scale entries are replaced by `p0`'s. `terms` are the subject-level priors.
pub fn calibrate(
    solver: &mut FrameSolver<'_>,
    frames: &[&[f64]],
    frame_template: &FrameProblem<'_>,
    p0: &[f64],
    starts: &[Vec<f64>],
    terms: &[&dyn GlobalTerm],
) -> Calibration {
    let eval = solver.eval;
    let proxy = eval.proxy;
    let model = eval.model;
    let started = std::time::Instant::now();
    let mut state = initial_state(solver, frames, frame_template, p0, starts);
    let offsets: Vec<Vector3<f64>> = model.markers.iter().map(|m| m.offset).collect();
    let registered = vec![false; model.markers.len()];
    let weights = vec![frame_template.marker_weights; frames.len()];
    let refs = vec![frame_template.tracking_ref; frames.len()];
    let tracking_weights = vec![frame_template.tracking_weights; frames.len()];
    let problem = JointProblem {
        model,
        proxy,
        settings: &solver.settings,
        frames,
        weights: &weights,
        tracking_refs: &refs,
        tracking_weights: &tracking_weights,
        registered: &registered,
        reference: &offsets,
        bound_m: 0.0,
        terms,
    };
    let out = problem.solve(&mut state);
    finish(state, out, p0, proxy, None, 0, started)
}

/// Each frame's pose fitted at the scales of `p0` from its start (pose proxies only).
pub fn initial_state(
    solver: &mut FrameSolver<'_>,
    frames: &[&[f64]],
    frame_template: &FrameProblem<'_>,
    p0: &[f64],
    starts: &[Vec<f64>],
) -> JointState {
    let weights = vec![frame_template.marker_weights; frames.len()];
    initial_state_weighted(solver, frames, &weights, frame_template, p0, starts)
}

/// [`initial_state`] with each frame's own marker weights.
pub fn initial_state_weighted(
    solver: &mut FrameSolver<'_>,
    frames: &[&[f64]],
    weights: &[&[f64]],
    frame_template: &FrameProblem<'_>,
    p0: &[f64],
    starts: &[Vec<f64>],
) -> JointState {
    let proxy = solver.eval.proxy;
    let np = proxy.np();
    let mut poses = Vec::with_capacity(frames.len());
    for ((obs, start), w) in frames.iter().zip(starts).zip(weights) {
        let fp = FrameProblem { observed: obs, marker_weights: w, ..*frame_template };
        let mut p = start.clone();
        for k in 0..np {
            if proxy.proxies[k].kind == ProxyKind::Scale {
                p[k] = p0[k];
            }
        }
        let saved =
            std::mem::replace(&mut solver.free, (0..np).map(|k| proxy.proxies[k].kind != ProxyKind::Scale).collect());
        solver.solve(&fp, &mut p);
        solver.free = saved;
        poses.push(p);
    }
    JointState { poses, offsets: solver.eval.model.markers.iter().map(|m| m.offset).collect() }
}

/// The calibration result of a solved joint state.
pub fn finish(
    state: JointState,
    out: JointOutcome,
    p0: &[f64],
    _proxy: &ProxyMap,
    offsets: Option<Vec<Vector3<f64>>>,
    registered: usize,
    started: std::time::Instant,
) -> Calibration {
    let proxies = state.poses.last().cloned().unwrap_or_else(|| p0.to_vec());
    Calibration {
        proxies,
        frames: state.poses.len(),
        iterations: out.iterations,
        rmse_m: out.rmse_m,
        registered,
        seconds: started.elapsed().as_secs_f64(),
        prior: Default::default(),
        frame_proxies: state.poses,
        marker_offsets: offsets,
        static_frames: 0,
        posture: Default::default(),
        registration_report: Default::default(),
        functional_centres: Vec::new(),
        joint_moves: Vec::new(),
        landmark_centres: Vec::new(),
        trial_misfits: Vec::new(),
        stages: Vec::new(),
    }
}

/// The profile's constraints that involve scale proxies only, as constraints on a step of the
/// scale vector (indexed like `scale`) from `p`; `None` when there are none.
fn scale_constraints(proxy: &ProxyMap, scale: &[usize], p: &[f64]) -> Option<LinearConstraints> {
    let rows: Vec<_> =
        proxy.constraints.iter().filter(|c| c.coefficients.iter().all(|(k, _)| scale.contains(k))).collect();
    if rows.is_empty() {
        return None;
    }
    let m = rows.len();
    let mut c = LinearConstraints { a: DMatrix::zeros(m, scale.len()), lo: DVector::zeros(m), hi: DVector::zeros(m) };
    for (i, pc) in rows.iter().enumerate() {
        for &(k, coef) in &pc.coefficients {
            if let Some(col) = scale.iter().position(|&s| s == k) {
                c.a[(i, col)] += coef;
            }
        }
        let v = pc.value(p);
        c.lo[i] = pc.lo - v;
        c.hi[i] = pc.hi - v;
    }
    Some(c)
}

/// Pose-only tracking through `frames` in order at the scale of `p0`, warm-started from frame to
/// frame (the first frame, and any after a gap, cold-started): returns the proxies at each frame.
/// This is how calibration frames far apart in a motion get good initial poses.
pub fn track(
    solver: &mut FrameSolver<'_>,
    frames: &[&[f64]],
    frame_template: &FrameProblem<'_>,
    p0: &[f64],
) -> Vec<Vec<f64>> {
    let mut t = Tracker::new(solver, p0);
    let out = frames.iter().map(|obs| t.step(solver, obs, frame_template).to_vec()).collect();
    t.end(solver);
    out
}

/// [`track`] a frame at a time: poses of consecutive frames, each warm-started from the one
/// before (several starts after a frame with too few markers). Between [`Tracker::new`] and
/// [`Tracker::end`] the solver moves the pose proxies only.
pub struct Tracker {
    p: Vec<f64>,
    p0: Vec<f64>,
    warm: bool,
    saved: Vec<bool>,
}

impl Tracker {
    /// Starts tracking from `p0` (which also fixes the scales).
    pub fn new(solver: &mut FrameSolver<'_>, p0: &[f64]) -> Tracker {
        let proxy = solver.eval.proxy;
        let saved =
            std::mem::replace(&mut solver.free, proxy.proxies.iter().map(|p| p.kind != ProxyKind::Scale).collect());
        Tracker { p: p0.to_vec(), p0: p0.to_vec(), warm: false, saved }
    }

    /// The pose of the next frame, observed as `obs`.
    pub fn step(&mut self, solver: &mut FrameSolver<'_>, obs: &[f64], frame_template: &FrameProblem<'_>) -> &[f64] {
        let fp = FrameProblem { observed: obs, ..*frame_template };
        let st = if self.warm {
            solver.solve(&fp, &mut self.p)
        } else {
            // Several starts for a frame without a previous solution (neutral pose with root
            // placement and sweeps, root placement alone): a crossed or flipped first frame
            // would carry its basin through the whole track.
            self.p.copy_from_slice(&self.p0);
            multi_start(solver, &fp, &mut self.p, &self.p0)
        };
        self.warm = st.status != super::FrameStatus::TooFewMarkers;
        &self.p
    }

    /// [`Tracker::step`] with at most `iterations` trust-region iterations when warm-started
    /// (a frame that only carries the pose forward to the next); a cold start (several starts)
    /// is solved in full.
    pub fn step_limited(
        &mut self,
        solver: &mut FrameSolver<'_>,
        obs: &[f64],
        frame_template: &FrameProblem<'_>,
        iterations: u32,
    ) -> &[f64] {
        let full = solver.settings.max_iterations;
        if self.warm {
            solver.settings.max_iterations = iterations.min(full);
        }
        self.step(solver, obs, frame_template);
        solver.settings.max_iterations = full;
        &self.p
    }

    /// Gives the solver back its free proxies.
    pub fn end(self, solver: &mut FrameSolver<'_>) {
        solver.free = self.saved;
    }
}
