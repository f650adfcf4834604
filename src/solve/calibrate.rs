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
//! symmetry); the poses follow by back-substitution, clipped to their ranges. A step is accepted
//! when the total objective decreases. A weak prior pulls unobservable scales toward 1.

use super::init::cold_start;
use super::qp::{BoxQp, ClarabelQp, LinearConstraints, QpProblem, QpSolver};
use super::trqp::FrameSolver;
use crate::kinematics::assembly::FrameProblem;
use crate::model::proxy::ProxyKind;
use crate::model::proxy::ProxyMap;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// What calibration found.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Calibration {
    /// Full proxy vector whose scale entries are the subject's morphology (pose entries: the
    /// last calibration frame's pose).
    pub proxies: Vec<f64>,
    /// Frames used.
    pub frames: usize,
    /// Outer iterations run.
    pub iterations: u32,
    /// Mean marker RMSE over the calibration frames (m).
    pub rmse_m: f64,
    /// Final proxies of every calibration frame (shared scales, own pose).
    #[serde(skip)]
    pub frame_proxies: Vec<Vec<f64>>,
    /// Every model marker's unit-scale offset (body frame, m) after marker placement; `None`
    /// when placement did not run.
    #[serde(skip)]
    pub marker_offsets: Option<Vec<nalgebra::Vector3<f64>>>,
}

/// Calibrates the scale proxies on `frames` (observed marker arrays, `3·marker + axis`, NaN gaps).
/// `frame_template` supplies weights and tracking arrays (its `observed` is ignored). `starts`
/// gives each frame's initial proxies (see [`track`]); their scale entries are replaced by `p0`'s.
pub fn calibrate(
    solver: &mut FrameSolver<'_>,
    frames: &[&[f64]],
    frame_template: &FrameProblem<'_>,
    p0: &[f64],
    starts: &[Vec<f64>],
) -> Calibration {
    let eval = solver.eval;
    let proxy = eval.proxy;
    let np = proxy.np();
    let scale: Vec<usize> = (0..np).filter(|&k| proxy.proxies[k].kind == ProxyKind::Scale).collect();
    let pose: Vec<usize> = (0..np).filter(|&k| proxy.proxies[k].kind != ProxyKind::Scale).collect();
    let (ns, nq) = (scale.len(), pose.len());
    let s = solver.settings.clone();
    let prior = s.calibration_scale_prior;

    // Per-frame poses at the starting scale.
    let mut poses: Vec<Vec<f64>> = Vec::with_capacity(frames.len());
    for (obs, start) in frames.iter().zip(starts) {
        let fp = FrameProblem { observed: obs, ..*frame_template };
        let mut p = start.clone();
        for &k in &scale {
            p[k] = p0[k];
        }
        let saved =
            std::mem::replace(&mut solver.free, (0..np).map(|k| proxy.proxies[k].kind != ProxyKind::Scale).collect());
        solver.solve(&fp, &mut p);
        solver.free = saved;
        poses.push(p);
    }
    let mut shared: Vec<f64> = scale.iter().map(|&k| p0[k]).collect();
    let total = |solver: &mut FrameSolver<'_>, poses: &[Vec<f64>], shared: &[f64]| -> (f64, f64) {
        let mut e = 0.0;
        let mut rmse = 0.0;
        let mut counted = 0;
        for (obs, p) in frames.iter().zip(poses) {
            let mut p = p.clone();
            for (i, &k) in scale.iter().enumerate() {
                p[k] = shared[i];
            }
            let fp = FrameProblem { observed: obs, ..*frame_template };
            let (ek, sq, used) = eval.energy(&p, &fp, &mut solver.ws);
            e += ek;
            if used > 0 {
                rmse += (sq / used as f64).sqrt();
                counted += 1;
            }
        }
        e += 0.5 * prior * shared.iter().map(|v| (v - 1.0).powi(2)).sum::<f64>();
        (e, if counted > 0 { rmse / counted as f64 } else { f64::NAN })
    };
    let (mut energy, mut rmse) = total(solver, &poses, &shared);
    let mut lambda = 1e-4;
    let mut iterations = 0;
    let (lo, hi): (Vec<f64>, Vec<f64>) = proxy.proxies.iter().map(|p| p.range).unzip();
    while iterations < s.calibration_max_iterations && !frames.is_empty() {
        iterations += 1;
        // Assemble the Schur complement.
        let mut schur = DMatrix::<f64>::zeros(ns, ns);
        let mut rhs = DVector::<f64>::zeros(ns);
        let mut blocks = Vec::with_capacity(frames.len());
        for i in 0..ns {
            schur[(i, i)] += prior;
            rhs[i] -= prior * (shared[i] - 1.0);
        }
        for (obs, p) in frames.iter().zip(&poses) {
            let mut p = p.clone();
            for (i, &k) in scale.iter().enumerate() {
                p[k] = shared[i];
            }
            let fp = FrameProblem { observed: obs, ..*frame_template };
            eval.linearize(&p, &fp, &mut solver.ws);
            let gn = &solver.ws.gn;
            let mut a = gn.h.select_rows(&pose).select_columns(&pose);
            for d in 0..nq {
                a[(d, d)] += lambda * a[(d, d)].max(s.damping_floor);
            }
            let b = gn.h.select_rows(&pose).select_columns(&scale);
            let c = gn.h.select_rows(&scale).select_columns(&scale);
            let gq = gn.g.select_rows(&pose);
            let gs = gn.g.select_rows(&scale);
            // A frame whose pose block cannot be factored keeps its pose this iteration and
            // contributes its scale block alone.
            let Some(chol) = a.cholesky() else {
                schur += c;
                rhs -= gs;
                blocks.push(None);
                continue;
            };
            let ainv_b = chol.solve(&b);
            let ainv_g = chol.solve(&gq);
            schur += c - b.transpose() * &ainv_b;
            rhs -= gs - b.transpose() * &ainv_g;
            blocks.push(Some((ainv_b, ainv_g)));
        }
        for d in 0..ns {
            schur[(d, d)] += lambda * schur[(d, d)].max(s.damping_floor);
        }
        // The poses eliminated, the scale step is a small QP: the scale ranges as bounds, the
        // profile's constraints on scale proxies as general constraints.
        let lb = DVector::from_iterator(ns, scale.iter().enumerate().map(|(i, &k)| lo[k] - shared[i]));
        let ub = DVector::from_iterator(ns, scale.iter().enumerate().map(|(i, &k)| hi[k] - shared[i]));
        let neg_rhs = -&rhs;
        let problem = QpProblem { h: &schur, g: &neg_rhs, lb: &lb, ub: &ub };
        let mut ds = DVector::zeros(ns);
        let mut current = p0.to_vec();
        for (i, &k) in scale.iter().enumerate() {
            current[k] = shared[i];
        }
        let solved = match scale_constraints(proxy, &scale, &current) {
            Some(c) => {
                let mut qp = ClarabelQp::new(Default::default());
                qp.set_constraints(Some(c));
                qp.solve(&problem, &mut ds)
            }
            None => BoxQp::new().solve(&problem, &mut ds),
        };
        if solved.is_err() {
            break;
        }
        let mut new_shared = shared.clone();
        for (i, &k) in scale.iter().enumerate() {
            new_shared[i] = (shared[i] + ds[i]).clamp(lo[k], hi[k]);
        }
        let mut new_poses = poses.clone();
        for (p, block) in new_poses.iter_mut().zip(&blocks) {
            let Some((ainv_b, ainv_g)) = block else { continue };
            let dq = -(ainv_g + ainv_b * &ds);
            for (i, &k) in pose.iter().enumerate() {
                p[k] = (p[k] + dq[i]).clamp(lo[k], hi[k]);
            }
        }
        let (e1, r1) = total(solver, &new_poses, &new_shared);
        if e1 < energy {
            let rel = (energy - e1) / energy.max(f64::MIN_POSITIVE);
            poses = new_poses;
            shared = new_shared;
            energy = e1;
            rmse = r1;
            lambda = (lambda / 3.0).max(1e-9);
            if rel < 1e-9 {
                break;
            }
        } else {
            lambda *= 4.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    for p in &mut poses {
        for (i, &k) in scale.iter().enumerate() {
            p[k] = shared[i];
        }
    }
    let mut proxies = poses.last().cloned().unwrap_or_else(|| p0.to_vec());
    for (i, &k) in scale.iter().enumerate() {
        proxies[k] = shared[i];
    }
    Calibration { proxies, frames: frames.len(), iterations, rmse_m: rmse, frame_proxies: poses, marker_offsets: None }
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
    let proxy = solver.eval.proxy;
    let saved = std::mem::replace(&mut solver.free, proxy.proxies.iter().map(|p| p.kind != ProxyKind::Scale).collect());
    let mut out = Vec::with_capacity(frames.len());
    let mut p = p0.to_vec();
    let mut warm = false;
    for obs in frames {
        let fp = FrameProblem { observed: obs, ..*frame_template };
        if !warm {
            p = p0.to_vec();
            cold_start(solver, &fp, &mut p);
        }
        let st = solver.solve(&fp, &mut p);
        warm = st.status != super::FrameStatus::TooFewMarkers;
        out.push(p.clone());
    }
    solver.free = saved;
    out
}
