//! Helper joints: skin blended between a body and its descendant turns through intermediate
//! frames instead of being averaged between the two ends (docs/guide/rendering-and-synthetic-video.md,
//! "How the skin bends").
//!
//! Linear-blend skinning averages a vertex's positions under its bodies' transforms. Between a
//! pelvis and a thigh flexed 90° that average lies on the chord of the arc the vertex should
//! follow: the hip's skin collapses toward the joint (a half-and-half vertex ends at cos 45° =
//! 0.71 of its distance). Here each pair `(a, d)` of a body and its descendant that share
//! vertices gets [`STEPS`]` − 1` helper joints at fractions `k / STEPS` of `d`'s rotation
//! relative to `a` (since the bind pose), turning about the joint centre (the origin of the
//! body below `a` on the way to `d`). A vertex carried by `a` and descendants `d` of it (each
//! `a` its nearest ancestor among the vertex's bodies), with `t` their share of the weight
//! ([`split`]), is blended between the two neighbouring frames of each chain
//! `a, h_1, …, h_{STEPS−1}, d` that bracket `t` (linear blending over a quarter of the angle:
//! a chord at 11° of a 45° step keeps 99.5 % of the radius). It is still linear-blend
//! skinning over more joints, so glTF viewers show the same mesh ([`crate::render::scene`]
//! exports the helpers as animated joints).
//!
//! Helper `h` of pair `(a, d)` at fraction `f`, in the output frame, maps a point of body `a`
//! (unit-scale coordinates `u`, [`super::Influence::local`]) to
//! `c_a + Q^f (R_a u + p_a − c_a) + f (c_d − c_a)`, where `(R_a, p_a)` is `a`'s skinning map,
//! `Q = Q_d Q_aᵀ` with `Q_b = R_b R_b,bindᵀ` (rotations only), `c_a` is the joint centre as
//! carried by `a` and `c_d` the joint centre's actual position (the two differ where the joint
//! also translates, as OpenSim's knees do; the last term closes that gap at `f = 1`).

use super::influence::Influence;
use crate::model::Model;
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};

/// Frames per blended pair: `STEPS − 1` helpers between the two bodies.
pub const STEPS: usize = 4;

/// One helper joint.
#[derive(Clone, Debug, PartialEq)]
pub struct Helper {
    /// The ancestor body `a` (its skinning map carries the vertex) and the descendant `d`.
    pub parent: usize,
    pub child: usize,
    /// The body whose origin is the joint centre (the child of `a` on the way to `d`).
    pub centre: usize,
    /// The joint centre in `a`'s frame at unit scale (m), at the bind state.
    pub centre_local: Vector3<f64>,
    /// Fraction of `d`'s relative rotation this helper turns by (`k / STEPS`).
    pub fraction: f64,
}

/// One influence over joints (bodies `0..nb`, then helper `k` as joint `nb + k`): its weight,
/// and which of the vertex's body influences holds its local point (a helper uses its parent's).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointInfluence {
    pub joint: u16,
    pub weight: f32,
    pub from: u8,
}

/// The helpers of a binding and every vertex's influences over joints.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Helpers {
    pub helpers: Vec<Helper>,
    /// Per vertex, up to four, largest first (unused: weight 0).
    pub joints: Vec<[JointInfluence; 4]>,
}

/// If `a` is a proper ancestor of `d`, the child of `a` on the way to `d`.
fn below(model: &Model, a: usize, d: usize) -> Option<usize> {
    let mut c = d;
    while let Some(p) = model.bodies[c].parent {
        if p == a {
            return Some(c);
        }
        c = p;
    }
    None
}

/// Splits every vertex carried by a body `a` and some of its descendants over the pairs'
/// helper chains. With `W` the descendants' total weight, every pair `(a, d)` is at the same
/// `t = W / (w_a + W)` and gets the share `w_d / W` of `a`'s weight, so a vertex between a
/// pelvis and both thighs (the crotch) turns with both the same way, and the skin stays
/// continuous where one thigh's share overtakes the other's. `body_rot`, `body_pos` and `y`
/// are the bind state's (model frame).
pub fn split(
    model: &Model,
    influences: &[[Influence; 4]],
    body_rot: &[Matrix3<f64>],
    body_pos: &[Vector3<f64>],
    y: &[f64],
) -> Helpers {
    let mut helpers: Vec<Helper> = Vec::new();
    let mut joints = Vec::with_capacity(influences.len());
    for inf in influences {
        let used = inf.iter().take_while(|x| x.weight > 0.0).count();
        // Each influence's nearest ancestor among the others; the anchor is the influence
        // that, with the influences it is nearest to, carries the most weight.
        let nearest = |k: usize| -> Option<usize> {
            let mut c = model.bodies[inf[k].body as usize].parent;
            while let Some(p) = c {
                if let Some(i) = (0..used).find(|&i| inf[i].body as usize == p) {
                    return Some(i);
                }
                c = model.bodies[p].parent;
            }
            None
        };
        let near: Vec<Option<usize>> = (0..used).map(nearest).collect();
        let mut anchor: Option<(usize, f32)> = None;
        for i in 0..used {
            let below_w: f32 = (0..used).filter(|&k| near[k] == Some(i)).map(|k| inf[k].weight).sum();
            let carried = below_w + inf[i].weight;
            if below_w > 0.0 && anchor.is_none_or(|(j, w)| carried > w + inf[j].weight) {
                anchor = Some((i, below_w));
            }
        }
        let mut out: Vec<JointInfluence> = Vec::with_capacity(8);
        match anchor {
            None => out.extend((0..used).map(|k| JointInfluence {
                joint: inf[k].body,
                weight: inf[k].weight,
                from: k as u8,
            })),
            Some((ia, total)) => {
                let a = inf[ia].body as usize;
                let wa = inf[ia].weight;
                let t = total as f64 / (wa + total) as f64;
                let seg = ((t * STEPS as f64).floor() as usize).min(STEPS - 1);
                let along = (t * STEPS as f64 - seg as f64) as f32;
                for k in 0..used {
                    let d = inf[k].body as usize;
                    let Some(c) = below(model, a, d).filter(|_| near[k] == Some(ia)) else {
                        if k != ia {
                            out.push(JointInfluence { joint: inf[k].body, weight: inf[k].weight, from: k as u8 });
                        }
                        continue;
                    };
                    let first = chain(model, &mut helpers, a, d, c, body_rot, body_pos, y);
                    let joint = |s: usize| -> (u16, u8) {
                        match s {
                            0 => (a as u16, ia as u8),
                            s if s == STEPS => (d as u16, k as u8),
                            s => ((model.nb() + first + s - 1) as u16, ia as u8),
                        }
                    };
                    let w = inf[k].weight + wa * inf[k].weight / total;
                    for (s, share) in [(seg, 1.0 - along), (seg + 1, along)] {
                        let (joint, from) = joint(s);
                        match out.iter_mut().find(|x| x.joint == joint) {
                            Some(x) => x.weight += w * share,
                            None => out.push(JointInfluence { joint, weight: w * share, from }),
                        }
                    }
                }
            }
        }
        // largest first (ties: lower joint), at most four, weights summing to one
        out.retain(|x| x.weight > 0.0);
        out.sort_by(|p, q| q.weight.total_cmp(&p.weight).then(p.joint.cmp(&q.joint)));
        out.truncate(4);
        let sum: f32 = out.iter().map(|x| x.weight).sum();
        let mut four = [JointInfluence::default(); 4];
        for (slot, x) in four.iter_mut().zip(&out) {
            *slot = JointInfluence { weight: x.weight / sum, ..*x };
        }
        joints.push(four);
    }
    Helpers { helpers, joints }
}

/// The index of pair `(a, d)`'s first helper, its chain made if new.
#[allow(clippy::too_many_arguments)]
fn chain(
    model: &Model,
    helpers: &mut Vec<Helper>,
    a: usize,
    d: usize,
    c: usize,
    body_rot: &[Matrix3<f64>],
    body_pos: &[Vector3<f64>],
    y: &[f64],
) -> usize {
    if let Some(k) = helpers.iter().position(|h| h.parent == a && h.child == d) {
        return k;
    }
    let s = model.scale_index(a, 0);
    let scale = Vector3::new(y[s], y[s + 1], y[s + 2]);
    let centre_local = (body_rot[a].transpose() * (body_pos[c] - body_pos[a])).component_div(&scale);
    for k in 1..STEPS {
        helpers.push(Helper { parent: a, child: d, centre: c, centre_local, fraction: k as f64 / STEPS as f64 });
    }
    helpers.len() - (STEPS - 1)
}

/// `q^f` for a unit quaternion (the shorter way round), with the project's portable
/// transcendental functions.
fn power(q: &UnitQuaternion<f64>, f: f64) -> UnitQuaternion<f64> {
    let q = if q.w < 0.0 { -q.into_inner() } else { q.into_inner() };
    let n = q.imag().norm();
    if n < 1e-300 {
        return UnitQuaternion::identity();
    }
    let half = crate::model::math::atan2(n, q.w);
    let (s, c) = crate::model::math::sin_cos(f * half);
    let v = q.imag() * (s / n);
    UnitQuaternion::new_unchecked(Quaternion::new(c, v.x, v.y, v.z))
}

/// Fills `rot[nb + k]`, `pos[nb + k]` (each helper's map from its parent's unit-scale
/// coordinates to the output frame) and `turn[nb + k]` (its rotation) from the bodies' maps
/// `rot[..nb]`, `pos[..nb]` and rotations `turn[..nb]` (no scale); `bind_rot` are the bodies'
/// rotations at the bind state, in the same frame.
pub fn frames(
    helpers: &[Helper],
    bind_rot: &[Matrix3<f64>],
    rot: &mut [Matrix3<f64>],
    pos: &mut [Vector3<f64>],
    turn: &mut [Matrix3<f64>],
) {
    let nb = bind_rot.len();
    let mut last: Option<(usize, usize, UnitQuaternion<f64>)> = None;
    for (k, h) in helpers.iter().enumerate() {
        let (a, d) = (h.parent, h.child);
        let q = match last {
            Some((pa, pd, q)) if pa == a && pd == d => q,
            _ => {
                let rel = turn[d] * bind_rot[d].transpose() * bind_rot[a] * turn[a].transpose();
                let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rel));
                last = Some((a, d, q));
                q
            }
        };
        let qf = power(&q, h.fraction).to_rotation_matrix().into_inner();
        let ca = rot[a] * h.centre_local + pos[a];
        let cd = pos[h.centre];
        rot[nb + k] = qf * rot[a];
        turn[nb + k] = qf * turn[a];
        pos[nb + k] = ca + qf * (pos[a] - ca) + (cd - ca) * h.fraction;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quaternion_power_turns_by_that_fraction_of_the_angle() {
        let axis = nalgebra::Unit::new_normalize(Vector3::new(0.3, -0.5, 0.8));
        let q = UnitQuaternion::from_axis_angle(&axis, 1.2);
        let h = power(&q, 0.25);
        assert!((h.angle() - 0.3).abs() < 1e-12);
        assert!((h.axis().unwrap().into_inner() - axis.into_inner()).norm() < 1e-12);
        // the shorter way: q and −q are the same rotation
        let neg = UnitQuaternion::new_unchecked(-q.into_inner());
        assert!(power(&neg, 0.5).angle_to(&power(&q, 0.5)) < 1e-12);
        assert_eq!(power(&UnitQuaternion::identity(), 0.5), UnitQuaternion::identity());
    }
}
