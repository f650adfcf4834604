//! Cold start of a frame without a previous solution: place the root body by a rigid (Kabsch)
//! fit of the default-pose model markers to the observed ones, then fit the root coordinates to
//! that placement from several headings and keep the best.

use super::presolve::Presolver;
use super::trqp::FrameSolver;
use crate::kinematics::assembly::FrameProblem;
use crate::model::proxy::ProxyKind;
use nalgebra::{Matrix3, Vector3, SVD};

/// Proxies driving the coordinates of root joints (bodies hanging from ground).
pub fn root_proxies(solver: &FrameSolver<'_>) -> Vec<usize> {
    let model = solver.eval.model;
    let proxy = solver.eval.proxy;
    let mut out = Vec::new();
    for b in model.bodies.iter().filter(|b| b.parent.is_none()) {
        for mo in &model.motions[b.joint.motions.clone()] {
            if let Some(c) = mo.coordinate {
                out.extend(proxy.y_terms[c].clone().map(|t| proxy.terms[t].proxy));
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Best rigid transform `(R, t)` with `b ≈ R a + t` (least squares, proper rotation).
pub fn kabsch(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    if a.len() < 3 || a.len() != b.len() {
        return None;
    }
    let n = a.len() as f64;
    let ca = a.iter().sum::<Vector3<f64>>() / n;
    let cb = b.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    for (x, y) in a.iter().zip(b) {
        cov += (y - cb) * (x - ca).transpose();
    }
    let svd = SVD::new(cov, true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let d = (u * vt).determinant().signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
    Some((r, cb - r * ca))
}

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

/// Places the root body by a rigid fit of the model markers at `p` to the observed ones.
pub fn place_root(solver: &mut FrameSolver<'_>, frame: &FrameProblem<'_>, p: &mut [f64]) {
    let eval = solver.eval;
    let model = eval.model;
    // Model markers at p, paired with observations.
    eval.energy(p, frame, &mut solver.ws);
    let roots: Vec<usize> = (0..model.nb()).filter(|&b| model.bodies[b].parent.is_none()).collect();
    let observed = |m: usize| {
        let o = &frame.observed[3 * m..3 * m + 3];
        (frame.marker_weights[m] > 0.0 && o.iter().all(|v| !v.is_nan())).then(|| Vector3::new(o[0], o[1], o[2]))
    };
    let pairs = |root_only: bool| -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        (0..model.markers.len())
            .filter(|&m| !root_only || roots.contains(&model.markers[m].body))
            .filter_map(|m| observed(m).map(|o| (solver.ws.kin.marker(m), o)))
            .unzip()
    };
    let (mut a, mut b) = pairs(true);
    if a.len() < 3 {
        (a, b) = pairs(false);
    }
    let Some((r, t)) = kabsch(&a, &b) else { return };
    // Targets: every model marker moved rigidly; fit the root proxies to them.
    let targets: Vec<f64> = (0..model.markers.len())
        .flat_map(|m| {
            let v = r * solver.ws.kin.marker(m) + t;
            [v.x, v.y, v.z]
        })
        .collect();
    let weights: Vec<f64> = model.markers.iter().map(|mk| if roots.contains(&mk.body) { 1.0 } else { 0.1 }).collect();
    let target_frame = FrameProblem { observed: &targets, marker_weights: &weights, ..*frame };
    let root = root_proxies(solver);
    let saved_free = std::mem::replace(&mut solver.free, vec![false; p.len()]);
    for &k in &root {
        solver.free[k] = true;
    }
    // The subject may be metres away from the origin: no step box for this exact rigid fit.
    let saved_multiplier = std::mem::replace(&mut solver.step_multiplier, 1e6);
    // The targets are reachable exactly, so a start that fits them is the answer. Headings for
    // the first root rotation proxy: as it is, then spread around the circle, to escape flipped
    // local minima of the Euler decomposition.
    let first_rot =
        root.iter().copied().find(|&k| eval.proxy.proxies[k].kind == crate::model::proxy::ProxyKind::Rotation);
    let mut best: Option<(f64, Vec<f64>)> = None;
    let starts = if first_rot.is_some() { 9 } else { 1 };
    for i in 0..starts {
        let mut trial = p.to_vec();
        if let (Some(k), true) = (first_rot, i > 0) {
            trial[k] += std::f64::consts::TAU * i as f64 / starts as f64;
            trial[k] = wrap_angle(trial[k]);
        }
        let stats = solver.solve(&target_frame, &mut trial);
        let done = stats.rmse_m < 1e-3;
        if best.as_ref().is_none_or(|(e, _)| stats.energy < *e) {
            best = Some((stats.energy, trial));
        }
        if done {
            break;
        }
    }
    solver.free = saved_free;
    solver.step_multiplier = saved_multiplier;
    if let Some((_, q)) = best {
        p.copy_from_slice(&q);
    }
    // Unbounded root angles: the representative in (−π, π].
    for &k in &root {
        let px = &eval.proxy.proxies[k];
        if px.kind == crate::model::proxy::ProxyKind::Rotation
            && px.range.0 <= -std::f64::consts::TAU
            && px.range.1 >= std::f64::consts::TAU
        {
            p[k] = wrap_angle(p[k]);
        }
    }
}

/// The angle equal to `a` modulo 2π in (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w == -std::f64::consts::PI {
        std::f64::consts::PI
    } else {
        w
    }
}
