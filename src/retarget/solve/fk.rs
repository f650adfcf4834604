//! The robot's forward kinematics, specialised: an MJCF robot's joints are a free joint and
//! hinges, each motion its coordinate itself (`f(q) = q − q₀`, `f' = 1`), every scale 1 and every
//! joint frame on the child a pure translation, so the general [`cpu::forward`] (functions of
//! coordinates, scales, child-offset rotations) does more than it needs. A model that is not
//! of that form keeps [`cpu::forward`]. Both give the same poses up to rounding.

use crate::kinematics::cpu::{self, Workspace};
use crate::model::{Function, Model, MotionKind};
use nalgebra::{Matrix3, Vector3};

/// One motion of a [`Fast`] body: its axis in the joint's moving frame, the coordinate, `q₀`,
/// and for an axis along `±e_k` the index `k` and sign (the rotation then touches two columns).
#[derive(Clone, Debug)]
struct FastMotion {
    rotation: bool,
    axis: Vector3<f64>,
    coordinate: usize,
    offset: f64,
    principal: Option<(usize, f64)>,
}

/// A body of a [`Fast`] model: parent, joint frame on the parent (rotation, `None` when the
/// identity, and origin), its motions (indices into the model's) and joint frame on the child
/// (origin).
#[derive(Clone, Debug)]
struct FastBody {
    parent: Option<usize>,
    rot: Option<Matrix3<f64>>,
    pos: Vector3<f64>,
    motions: std::ops::Range<usize>,
    anchor: Vector3<f64>,
}

/// The model in the specialised form.
#[derive(Clone, Debug)]
pub(super) struct Fast {
    bodies: Vec<FastBody>,
    motions: Vec<FastMotion>,
}

impl Fast {
    /// The model in the specialised form, or `None` when it is not of it.
    pub(super) fn new(model: &Model) -> Option<Fast> {
        let mut motions = Vec::with_capacity(model.motions.len());
        for m in &model.motions {
            let offset = match (&m.func, m.coordinate) {
                (Function::Linear { slope, intercept }, Some(_)) if *slope == 1.0 => -*intercept,
                _ => return None,
            };
            if m.parent_scale_weights.is_some() {
                return None;
            }
            let principal = (0..3).find(|&k| m.axis[k].abs() == 1.0).map(|k| (k, m.axis[k]));
            let principal = principal.filter(|&(k, _)| (0..3).all(|i| i == k || m.axis[i] == 0.0));
            let (rotation, axis) = (m.kind == MotionKind::Rotation, m.axis);
            motions.push(FastMotion { rotation, axis, coordinate: m.coordinate?, offset, principal });
        }
        let mut bodies = Vec::with_capacity(model.nb());
        for b in &model.bodies {
            let (po, co) = (&b.joint.parent_offset, &b.joint.child_offset);
            if co.rotation.angle() != 0.0 {
                return None;
            }
            let r = *po.rotation.to_rotation_matrix().matrix();
            bodies.push(FastBody {
                parent: b.parent,
                rot: (r != Matrix3::identity()).then_some(r),
                pos: po.translation.vector,
                motions: b.joint.motions.clone(),
                anchor: co.translation.vector,
            });
        }
        Some(Fast { bodies, motions })
    }

    /// Body poses of `q` into `ws`, and per motion its world axis and a world point on it (m)
    /// into `axes`, `origins` (its rate `f'` is 1).
    pub(super) fn forward(
        &self,
        q: &[f64],
        ws: &mut Workspace,
        axes: &mut [Vector3<f64>],
        origins: &mut [Vector3<f64>],
    ) {
        for (b, body) in self.bodies.iter().enumerate() {
            let (rp, tp) = match body.parent {
                Some(p) => (ws.body_rot[p], ws.body_pos[p]),
                None => (Matrix3::identity(), Vector3::zeros()),
            };
            let mut r = match &body.rot {
                Some(r0) => rp * r0,
                None => rp,
            };
            let mut t = tp + rp * body.pos;
            for k in body.motions.clone() {
                let m = &self.motions[k];
                let val = q[m.coordinate] - m.offset;
                let axis = r * m.axis;
                (axes[k], origins[k]) = (axis, t);
                if !m.rotation {
                    t += axis * val;
                } else if let Some((i, sign)) = m.principal {
                    turn_about(&mut r, i, sign * val);
                } else {
                    r *= crate::model::math::rotation(&m.axis, val);
                }
            }
            ws.body_pos[b] = t - r * body.anchor;
            ws.body_rot[b] = r;
        }
    }
}

/// `r ← r R_i(angle)`: a turn about the frame's own axis `e_i` moves the other two columns.
#[inline]
fn turn_about(r: &mut Matrix3<f64>, i: usize, angle: f64) {
    if angle == 0.0 {
        return;
    }
    let (s, c) = crate::model::math::sin_cos(angle);
    let (a, b) = ((i + 1) % 3, (i + 2) % 3);
    let (ca, cb) = (r.column(a).into_owned(), r.column(b).into_owned());
    r.set_column(a, &(ca * c + cb * s));
    r.set_column(b, &(cb * c - ca * s));
}

/// [`cpu::forward`] with the motions copied out, for a model [`Fast`] does not take.
pub(super) fn general(
    model: &Model,
    y: &[f64],
    ws: &mut Workspace,
    axes: &mut [Vector3<f64>],
    origins: &mut [Vector3<f64>],
    rates: &mut [f64],
) {
    cpu::forward(model, y, ws);
    for k in 0..model.motions.len() {
        (axes[k], origins[k], rates[k]) = ws.motion(k);
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{g1, posture};
    use super::super::{SolveSettings, Solver};
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn the_g1_takes_the_specialised_forward_kinematics_and_it_agrees_with_the_general_one() {
        let (robot, plan) = g1();
        let mut s = Solver::new(&robot, &plan, SolveSettings::default());
        assert!(s.fast.is_some(), "the G1 is free joint and hinges");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let mut ws = Workspace::new(&robot.model);
        let mut y = Vec::new();
        for _ in 0..5 {
            let q = posture(&robot, &mut rng);
            s.forward(&q);
            robot.state(&q, &mut y);
            crate::kinematics::cpu::forward(&robot.model, &y, &mut ws);
            for b in 0..robot.model.nb() {
                assert!((s.ws.body_pos[b] - ws.body_pos[b]).amax() < 1e-15, "body {b}");
                assert!((s.ws.body_rot[b] - ws.body_rot[b]).amax() < 1e-15, "body {b}");
            }
            for k in 0..robot.model.motions.len() {
                let ((a, o, r), (a2, o2, r2)) = (s.motion(k), ws.motion(k));
                assert!((a - a2).amax() < 1e-15 && (o - o2).amax() < 1e-15 && r == r2, "motion {k}");
            }
        }
    }
}
