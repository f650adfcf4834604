//! Binding the body mesh to a model, first pass: the model posed (its coordinates) and sized
//! (its body scales) so that its joint centres sit on the mesh's joint cubes, in the mesh's
//! A-pose. The body frames at that state are the bind frames of linear-blend skinning.
//!
//! Each pair in [`BIND_TARGETS`] puts a model body's origin (the centre of the joint that
//! attaches it to its parent: every body of `models/fullbody.xml` has its origin there) on the
//! centre of one joint cube, or the mean of several. The fit is a damped Gauss–Newton
//! (Levenberg–Marquardt, forward-difference Jacobian) over every unlocked coordinate (kept in
//! its range) and every scale factor (in [0.5, 2]), with a weak pull toward the default
//! coordinates and unit scales to settle what the pairs leave free (axial rotations, the foot
//! and hand scales).
//!
//! What binding a shaped mesh to a solved subject still needs (issue 33):
//! - bind matrices per segment: `(R_b, t_b)` of [`Binding`]; a vertex `v` skinned to `b` moves
//!   with `R_b(t) R_bᵀ (v − t_b) + t_b(t)`, blended by its weights;
//! - the subject's size: the solved scales differ from the bind scales. Either shape the mesh
//!   to the subject first (a [`super::Phenotype`] whose bound scales match the solved ones,
//!   e.g. `height` from the stature, then the rest by a small fit) and rebind, or scale each
//!   segment's local vertices by the ratio of scales (which tears at the joints);
//! - skin for bodies the folding leaves empty: `talus` (no skin: it moves with `calcn`'s
//!   parent chain only) and `lumbar1`–`lumbar5` (the rig's spine04–spine02 are folded into
//!   `torso`; a model with lumbar joints bends its belly only if those weights are split
//!   across the lumbar bodies), and a name map for models whose bodies differ (Rajagopal's
//!   `torso` carries the head);
//! - the forearm: `radius` takes the rig's distal forearm bone, so pronation twists the
//!   wrist end only; the bind pose's pronation comes from the fit's regularisation, not from
//!   the mesh (the pairs do not fix it).

use super::{BodyAsset, BodyShape};
use crate::kinematics::cpu::{forward, Workspace};
use crate::model::{CoordinateKind, Model};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// Model body ↔ joint cube(s) whose centre (or the mean of the centres) its origin goes to,
/// with a weight. The spine pairs are approximate levels (L5/S1, L3, T12/L1) and weigh less;
/// on the reference shape the shipped model's limb joints land within 5 mm of their cubes, the
/// neck within 7 mm, and the spine levels within 3, 8 and 28 mm (the lumbar joints' ranges and
/// lengths do not follow the mesh's spine curve).
pub const BIND_TARGETS: &[(&str, &[&str], f64)] = &[
    ("pelvis", &["joint-r-upper-leg", "joint-l-upper-leg"], 1.0),
    ("femur_r", &["joint-r-upper-leg"], 1.0),
    ("femur_l", &["joint-l-upper-leg"], 1.0),
    ("tibia_r", &["joint-r-knee"], 1.0),
    ("tibia_l", &["joint-l-knee"], 1.0),
    ("talus_r", &["joint-r-ankle"], 1.0),
    ("talus_l", &["joint-l-ankle"], 1.0),
    ("toes_r", &["joint-r-foot-1"], 1.0),
    ("toes_l", &["joint-l-foot-1"], 1.0),
    ("lumbar5", &["joint-spine-4"], 0.3),
    ("lumbar3", &["joint-spine-3"], 0.3),
    ("torso", &["joint-spine-2"], 0.3),
    ("head", &["joint-neck"], 1.0),
    ("humerus_r", &["joint-r-shoulder"], 1.0),
    ("humerus_l", &["joint-l-shoulder"], 1.0),
    ("ulna_r", &["joint-r-elbow"], 1.0),
    ("ulna_l", &["joint-l-elbow"], 1.0),
    ("hand_r", &["joint-r-hand"], 1.0),
    ("hand_l", &["joint-l-hand"], 1.0),
];

/// Pull toward the default coordinates (per radian or metre) and unit scales, relative to the
/// pair residuals in metres.
const PRIOR_COORDINATE: f64 = 0.01;
const PRIOR_SCALE: f64 = 0.02;

/// Errors binding the body mesh to a model.
#[derive(Debug, thiserror::Error)]
pub enum BindError {
    #[error("the model has none of the bodies the binding pairs with joint cubes")]
    NoPairs,
    #[error("the body asset has no joint cube '{0}'")]
    MissingJoint(String),
}

/// The model's state in the mesh's bind pose and its body frames there.
#[derive(Clone, Debug)]
pub struct Binding {
    /// State `y = [q; s]` of the model.
    pub y: Vec<f64>,
    /// Body orientations and origins at `y` (world = the asset's frame), per model body.
    pub body_rot: Vec<Matrix3<f64>>,
    pub body_pos: Vec<Vector3<f64>>,
    /// Per pair of [`BIND_TARGETS`] the model has: body name and distance (m) from its origin
    /// to its target at `y`.
    pub errors: Vec<(String, f64)>,
    pub iterations: usize,
}

impl Binding {
    /// Largest pair distance (m).
    pub fn max_error(&self) -> f64 {
        self.errors.iter().map(|e| e.1).fold(0.0, f64::max)
    }
}

/// Fits `model` (pose and scales) to the joint cubes of `shape`.
pub fn bind(model: &Model, asset: &BodyAsset, shape: &BodyShape) -> Result<Binding, BindError> {
    let mut pairs = Vec::new();
    for (body, cubes, w) in BIND_TARGETS {
        let Some(b) = model.body_index(body) else { continue };
        let mut t = Vector3::zeros();
        for c in cubes.iter() {
            let j = asset.joint_index(c).ok_or_else(|| BindError::MissingJoint(c.to_string()))?;
            t += shape.joints[j];
        }
        pairs.push((b, t / cubes.len() as f64, *w));
    }
    if pairs.is_empty() {
        return Err(BindError::NoPairs);
    }
    let nq = model.nq();
    let y0 = model.default_state();
    // free variables and their bounds
    let mut free: Vec<(usize, f64, f64, f64)> = Vec::new(); // (index in y, lo, hi, prior weight)
    for (i, c) in model.coordinates.iter().enumerate() {
        if !c.locked {
            let prior = match c.kind {
                CoordinateKind::Translational => 0.0,
                _ => PRIOR_COORDINATE,
            };
            free.push((i, c.range.0, c.range.1, prior));
        }
    }
    for i in nq..model.ny() {
        free.push((i, 0.5, 2.0, PRIOR_SCALE));
    }
    let mut ws = Workspace::new(model);
    let mut residual = |y: &[f64]| -> DVector<f64> {
        forward(model, y, &mut ws);
        let mut r = DVector::zeros(3 * pairs.len() + free.len());
        for (k, (b, t, w)) in pairs.iter().enumerate() {
            let d = (ws.body_pos[*b] - t) * *w;
            r.fixed_rows_mut::<3>(3 * k).copy_from(&d);
        }
        for (k, &(i, _, _, p)) in free.iter().enumerate() {
            r[3 * pairs.len() + k] = p * (y[i] - y0[i]);
        }
        r
    };
    let clamp = |y: &mut [f64]| {
        for &(i, lo, hi, _) in &free {
            y[i] = y[i].clamp(lo, hi);
        }
    };

    let mut y = y0.clone();
    let mut r = residual(&y);
    let mut cost = r.norm_squared();
    let mut mu = 1e-3;
    let n = free.len();
    let mut iterations = 0;
    for it in 0..200 {
        iterations = it + 1;
        let mut jac = DMatrix::zeros(r.len(), n);
        for (k, &(i, _, _, _)) in free.iter().enumerate() {
            let h = 1e-6;
            let mut yh = y.clone();
            yh[i] += h;
            let col = (residual(&yh) - &r) / h;
            jac.set_column(k, &col);
        }
        let jt = jac.transpose();
        let hess = &jt * &jac;
        let grad = &jt * &r;
        let mut accepted = false;
        while mu < 1e10 {
            let mut a = hess.clone();
            for k in 0..n {
                a[(k, k)] += mu * (1.0 + hess[(k, k)]);
            }
            let Some(chol) = a.cholesky() else {
                mu *= 10.0;
                continue;
            };
            let step = chol.solve(&grad);
            let mut yn = y.clone();
            for (k, &(i, _, _, _)) in free.iter().enumerate() {
                yn[i] -= step[k];
            }
            clamp(&mut yn);
            let rn = residual(&yn);
            let cn = rn.norm_squared();
            if cn < cost {
                let gain = cost - cn;
                y = yn;
                r = rn;
                cost = cn;
                mu = (mu / 3.0).max(1e-9);
                accepted = true;
                if gain < 1e-14 * cost.max(1e-12) {
                    accepted = false; // converged
                }
                break;
            }
            mu *= 4.0;
        }
        if !accepted {
            break;
        }
    }
    forward(model, &y, &mut ws);
    let errors = pairs.iter().map(|(b, t, _)| (model.bodies[*b].name.clone(), (ws.body_pos[*b] - t).norm())).collect();
    Ok(Binding { y, body_rot: ws.body_rot.clone(), body_pos: ws.body_pos.clone(), errors, iterations })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::context::Context;

    #[test]
    fn shipped_model_binds_to_the_reference_mesh() {
        let asset = BodyAsset::shipped().unwrap();
        let model = Context::shipped().unwrap().model;
        let b = bind(&model, &asset, &asset.rest).unwrap();
        let q = |name: &str| b.y[model.coordinate_index(name).unwrap()];
        eprintln!("iterations {}, errors (mm):", b.iterations);
        for (n, e) in &b.errors {
            eprintln!("  {n:10} {:6.1}", 1e3 * e);
        }
        for c in ["arm_add_r", "arm_add_l", "arm_flex_r", "elbow_flex_r", "hip_adduction_r", "knee_angle_r"] {
            eprintln!("  {c:16} {:7.1} deg", q(c).to_degrees());
        }
        let s = |body: &str| {
            let i = model.scale_index(model.body_index(body).unwrap(), 0);
            [b.y[i], b.y[i + 1], b.y[i + 2]]
        };
        eprintln!("  scales femur_r {:?} humerus_r {:?} pelvis {:?}", s("femur_r"), s("humerus_r"), s("pelvis"));
        assert_eq!(b.errors.len(), BIND_TARGETS.len());
        // the limb joints land on their cubes
        for (n, e) in &b.errors {
            let tol = if ["lumbar5", "lumbar3", "torso"].contains(&n.as_str()) { 0.04 } else { 0.01 };
            assert!(*e < tol, "{n}: {e}");
        }
        // A-pose: both upper arms abducted well away from the sides, the legs apart
        assert!(q("arm_add_r") < -0.4 && q("arm_add_l") < -0.4, "{} {}", q("arm_add_r"), q("arm_add_l"));
        assert!(q("hip_adduction_r") < 0.0 && q("hip_adduction_l") < 0.0);
    }
}
