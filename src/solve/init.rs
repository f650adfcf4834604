//! Cold start of a frame without a previous solution: place the root body by a rigid (Kabsch)
//! fit of the default-pose model markers to the observed ones, then fit the root coordinates to
//! that placement from several headings and keep the best.

use super::presolve::Presolver;
use super::root::place_root;
use super::trqp::FrameSolver;
use crate::kinematics::assembly::FrameProblem;
use crate::model::proxy::ProxyKind;

/// Initial proxies for `frame`, starting from `p` (whose scale part is kept): the root is
/// placed rigidly on the observed markers ([`place_root`]), then root-to-leaf sweeps fit each
/// joint to the markers of its subtree ([`Presolver::cold`]). Builds its scratch: callers that
/// start many frames keep one and call [`cold_start_with`].
pub fn cold_start(solver: &mut FrameSolver<'_>, frame: &FrameProblem<'_>, p: &mut [f64]) {
    let mut cold = Presolver::cold(solver.eval, &solver.settings);
    cold_start_with(&mut cold, solver, frame, p);
}

/// [`cold_start`] with the sweeps' scratch `cold` ([`Presolver::cold`] of the solver's evaluator).
pub fn cold_start_with(cold: &mut Presolver, solver: &mut FrameSolver<'_>, frame: &FrameProblem<'_>, p: &mut [f64]) {
    place_root(solver, frame, p);
    sweeps(cold, solver, frame, p);
}

/// The cold start's sweeps from `p` (root placed): local fits of each joint's proxies to its
/// markers ([`Presolver::cold`]), on the joint's columns only. A profile whose linear constraints
/// bind pose proxies keeps the constrained frame solver for them ([`sweep`], twice): the local fits
/// know only the proxy ranges.
fn sweeps(cold: &mut Presolver, solver: &mut FrameSolver<'_>, frame: &FrameProblem<'_>, p: &mut [f64]) {
    let proxy = solver.eval.proxy;
    let pose_constrained = proxy
        .constraints
        .iter()
        .any(|c| c.coefficients.iter().any(|&(k, _)| proxy.proxies[k].kind != ProxyKind::Scale));
    if pose_constrained {
        for _ in 0..2 {
            sweep(solver, frame, p);
        }
    } else {
        cold.sweep(solver.eval, frame, p);
    }
}

/// One root-to-leaf Gauss–Seidel sweep of local fits (METHOD.md's pre-solve) with the frame
/// solver (its constraints held): for each joint in topological order, its pose proxies are
/// fitted to the markers of its subtree, everything else held. Proxies driving several joints (a
/// coupled spine) are fitted at their first joint. Each fit evaluates the whole model: the cold
/// start uses it only under pose constraints ([`Presolver::cold`] otherwise).
pub fn sweep(solver: &mut FrameSolver<'_>, frame: &FrameProblem<'_>, p: &mut [f64]) {
    let eval = solver.eval;
    let model = eval.model;
    let proxy = eval.proxy;
    let saved_free = std::mem::take(&mut solver.free);
    let mut done = vec![false; p.len()];
    let mut weights = vec![0.0; model.markers.len()];
    for (b, body) in model.bodies.iter().enumerate() {
        if body.parent.is_none() {
            continue;
        }
        let mut free = vec![false; p.len()];
        let mut any = false;
        for mo in &model.motions[body.joint.motions.clone()] {
            if let Some(c) = mo.coordinate {
                for t in proxy.y_terms[c].clone() {
                    let k = proxy.terms[t].proxy;
                    if !done[k] && proxy.proxies[k].kind != crate::model::proxy::ProxyKind::Scale {
                        free[k] = true;
                        done[k] = true;
                        any = true;
                    }
                }
            }
        }
        if !any {
            continue;
        }
        // First the body's own markers (when they can orient it), then its whole subtree: a
        // distal segment at a neutral pose would otherwise pull an axial rotation the wrong way.
        solver.free = free;
        let min_markers = std::mem::replace(&mut solver.settings.min_markers, 1);
        for subtree in [false, true] {
            let mut observed = 0;
            for (m, mk) in model.markers.iter().enumerate() {
                let counts = if subtree { model.is_ancestor(b, mk.body) } else { mk.body == b };
                weights[m] = if counts { frame.marker_weights[m] } else { 0.0 };
                if weights[m] > 0.0 && !frame.observed[3 * m].is_nan() {
                    observed += 1;
                }
            }
            if observed < if subtree { 1 } else { 2 } {
                continue;
            }
            let local = FrameProblem { marker_weights: &weights, ..*frame };
            solver.solve(&local, p);
        }
        solver.settings.min_markers = min_markers;
    }
    solver.free = saved_free;
}

/// Solves a frame without a previous solution from several starts and keeps the lowest energy:
/// the neutral pose with root placement and sweeps ([`cold_start`]), the neutral pose with the
/// root placed only, and the calibration pose with the root placed. Distal chains with few markers
/// (forearm pronation against humeral rotation) have local minima that a single start can land in,
/// and a walk tracked from a wrong first frame stays in the wrong basin (two starts when the pose
/// given is the calibration pose: the last two would be one). Builds the sweeps'
/// scratch: see [`multi_start_with`].
pub fn multi_start(
    solver: &mut FrameSolver<'_>,
    frame: &FrameProblem<'_>,
    p: &mut [f64],
    calibrated: &[f64],
) -> super::FrameStats {
    let mut cold = Presolver::cold(solver.eval, &solver.settings);
    multi_start_with(&mut cold, solver, frame, p, calibrated)
}

/// [`multi_start`] with the sweeps' scratch `cold` ([`Presolver::cold`] of the solver's
/// evaluator). The first two starts share one root placement.
pub fn multi_start_with(
    cold: &mut Presolver,
    solver: &mut FrameSolver<'_>,
    frame: &FrameProblem<'_>,
    p: &mut [f64],
    calibrated: &[f64],
) -> super::FrameStats {
    let mut placed = p.to_vec();
    solver.clamp(&mut placed);
    place_root(solver, frame, &mut placed);
    let mut best: Option<(super::FrameStats, Vec<f64>)> = None;
    for start in 0..3 {
        // From `calibrated` itself (a tracker's first frame), the third start is the second.
        if start == 2 && p == calibrated {
            break;
        }
        let mut trial = if start == 2 { calibrated.to_vec() } else { placed.clone() };
        match start {
            0 => sweeps(cold, solver, frame, &mut trial),
            1 => {}
            _ => {
                solver.clamp(&mut trial);
                place_root(solver, frame, &mut trial);
            }
        }
        let stats = solver.solve(frame, &mut trial);
        if stats.status == super::FrameStatus::TooFewMarkers {
            p.copy_from_slice(&trial);
            return stats;
        }
        if best.as_ref().is_none_or(|(b, _)| stats.energy < b.energy) {
            best = Some((stats, trial));
        }
    }
    let (stats, q) = best.expect("three starts");
    p.copy_from_slice(&q);
    stats
}
