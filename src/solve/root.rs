//! Placing the root body of a frame without a previous solution: a rigid (Kabsch) fit of the
//! model markers to the observed ones, and the root coordinates fitted to that placement from
//! several headings ([`place_root`]); the cold start ([`super::init`]) and the pre-solve's sweeps
//! ([`super::presolve`]) both begin here.

use super::trqp::FrameSolver;
use crate::kinematics::assembly::FrameProblem;
use crate::model::math::wrap_angle;
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
