//! Joint centres from the motion, as a check of the calibrated model: for each hip (a joint of the
//! root body to a femur or thigh), the point about which the child body's markers turn, found by a sphere fit of
//! their positions in the root's frame over the calibration frames (one centre, a radius per
//! marker: `‖x − c‖² = ρ_m²`, linear in `c` and `ρ_m² − ‖c‖²`), against the model's joint centre
//! at the calibrated scales. The joint calibration already places the hips where the markers turn
//! about them; a functional centre far from the model's says that the model cannot (a pelvis
//! scaled wrongly, a mislabelled thigh marker) and is reported.
//!
//! With `functional_hips = "apply"` ([`hip_moves`]), a well-determined fit moves the subject's
//! hip joint there: the joint's location in the pelvis frame (its parent offset, which scales
//! with the pelvis) gains the offset divided by the pelvis's scale factors, so that at the
//! calibrated scales the joint lies on the functional centre.

use crate::kinematics::cpu::{forward, Workspace};
use crate::model::proxy::ProxyMap;
use crate::model::Model;
use crate::solve::prior::{FunctionalCentre, JointMove};
use nalgebra::{DMatrix, DVector, Vector3};

/// Below this range of motion of the child relative to the root (deg), a sphere fit is not
/// determined and none is reported.
pub const MIN_ROM_DEG: f64 = 20.0;
/// A functional centre further than this from the model's (mm) is a warning.
pub const WARN_MM: f64 = 30.0;
/// `functional_hips = "apply"` moves a hip only to a centre at most this far from the model's
/// (mm): hip centres of regression methods and functional ones differ by 10–20 mm (Davis against
/// a sphere fit); beyond 30 mm the fit, not the model, is the likelier culprit (a thigh marker
/// that slid, too little motion in one plane) and it is reported, not applied.
pub const APPLY_MAX_MM: f64 = 30.0;
/// Most calibration passes `apply` makes while moving the hips toward their fixed point.
pub const APPLY_MAX_PASSES: usize = 4;
/// `apply` stops moving the hips when a pass would move neither by more than this (mm).
pub const APPLY_TOL_MM: f64 = 1.0;
/// Fewest marker positions a fit needs before `apply` trusts it (three thigh markers in 34
/// frames).
pub const APPLY_MIN_SAMPLES: usize = 100;

/// The functional centres of the root body's joints over `frames` (observed markers per frame,
/// `3·marker + axis`, NaN gaps) at the proxies `poses` of each frame.
pub fn functional_centres(
    model: &Model,
    proxy: &ProxyMap,
    frames: &[&[f64]],
    poses: &[Vec<f64>],
) -> Vec<FunctionalCentre> {
    let Some(root) = model.bodies.iter().position(|b| b.parent.is_none()) else { return Vec::new() };
    // The hips: the root's joints to a femur or thigh (the trunk bends along its spine, not
    // about one point, and is left out).
    let hip = |b: usize| {
        let (body, joint) =
            (model.bodies[b].name.to_ascii_lowercase(), model.bodies[b].joint.name.to_ascii_lowercase());
        body.contains("femur") || body.contains("thigh") || joint.contains("hip")
    };
    let children: Vec<usize> =
        (0..model.bodies.len()).filter(|&b| model.bodies[b].parent == Some(root) && hip(b)).collect();
    let mut ws = Workspace::new(model);
    // Per child: its markers' positions in the root frame, the model's centre, the child's
    // orientation relative to the root, per frame.
    let mut samples: Vec<Vec<(usize, Vector3<f64>)>> = vec![Vec::new(); children.len()];
    let mut model_centre: Vec<Option<Vector3<f64>>> = vec![None; children.len()];
    let mut orientations: Vec<Vec<nalgebra::Matrix3<f64>>> = vec![Vec::new(); children.len()];
    for (obs, p) in frames.iter().zip(poses) {
        let y = proxy.state(p);
        forward(model, &y, &mut ws);
        let (r, t) = (ws.body_rot[root], ws.body_pos[root]);
        for (i, &c) in children.iter().enumerate() {
            model_centre[i].get_or_insert_with(|| r.transpose() * (joint_centre(model, &y, &ws, c) - t));
            orientations[i].push(r.transpose() * ws.body_rot[c]);
            for m in (0..model.markers.len()).filter(|&m| model.markers[m].body == c) {
                let x = Vector3::new(obs[3 * m], obs[3 * m + 1], obs[3 * m + 2]);
                if x.iter().all(|v| v.is_finite()) {
                    samples[i].push((m, r.transpose() * (x - t)));
                }
            }
        }
    }
    let mut out = Vec::new();
    for (i, &c) in children.iter().enumerate() {
        let rom = range_of_motion_deg(&orientations[i]);
        let (Some(centre), true) = (model_centre[i], rom >= MIN_ROM_DEG) else { continue };
        let Some(fit) = sphere_centre(&samples[i]) else { continue };
        out.push(FunctionalCentre {
            body: model.bodies[c].name.clone(),
            distance_mm: (fit - centre).norm() * 1e3,
            offset_mm: ((fit - centre) * 1e3).into(),
            range_of_motion_deg: rom,
            samples: samples[i].len(),
        });
    }
    out
}

/// Where body `c`'s joint turns it (world frame): its origin plus its child offset, at the last
/// [`forward`]'s state `y`.
fn joint_centre(model: &Model, y: &[f64], ws: &Workspace, c: usize) -> Vector3<f64> {
    let s = Vector3::from_fn(|a, _| y[model.scale_index(c, a)]);
    ws.body_pos[c] + ws.body_rot[c] * s.component_mul(&model.bodies[c].joint.child_offset.translation.vector)
}

/// The hip moves that `functional_hips = "apply"` makes from `centres` (found on `model` at the
/// calibrated `proxies`). A centre counts when it is fitted over at least [`MIN_ROM_DEG`] of
/// motion from at least [`APPLY_MIN_SAMPLES`] marker positions. With `symmetric` and both hips
/// counted, each hip moves by the mean of its own offset and the other's mirrored across the
/// pelvis's mid-plane (the plane halfway between the model's hip centres): an error of the
/// pelvis's solved orientation (a list or a turn of a degree or two) shifts the two fits in
/// opposite directions, so only their symmetric part is the subject's. The caller bounds the
/// moves ([`APPLY_MAX_MM`]) and fills `residual_mm`.
pub fn hip_moves(
    model: &Model,
    proxy: &ProxyMap,
    proxies: &[f64],
    centres: &[FunctionalCentre],
    symmetric: bool,
) -> Vec<JointMove> {
    let y = proxy.state(proxies);
    let counted: Vec<(usize, Vector3<f64>)> = centres
        .iter()
        .filter(|c| c.range_of_motion_deg >= MIN_ROM_DEG && c.samples >= APPLY_MIN_SAMPLES)
        .filter(|c| c.offset_mm.iter().all(|v| v.is_finite()))
        .filter_map(|c| Some((model.body_index(&c.body)?, Vector3::from(c.offset_mm) * 1e-3)))
        .filter(|(b, _)| model.bodies[*b].parent.is_some())
        .collect();
    // Each hip's location in the parent's frame at the calibrated scales.
    let parent_scale = |b: usize| {
        let p = model.bodies[b].parent.unwrap_or(b);
        Vector3::from_fn(|a, _| y[model.scale_index(p, a)])
    };
    let at_scale = |b: usize| parent_scale(b).component_mul(&model.bodies[b].joint.parent_offset.translation.vector);
    let offsets: Vec<(usize, Vector3<f64>)> = match counted.as_slice() {
        [(a, da), (b, db)] if symmetric => {
            let u = (at_scale(*a) - at_scale(*b)).try_normalize(1e-9);
            match u {
                Some(u) => {
                    let mirror = |v: &Vector3<f64>| v - 2.0 * v.dot(&u) * u;
                    let sa = (da + mirror(db)) / 2.0;
                    vec![(*a, sa), (*b, mirror(&sa))]
                }
                None => counted.clone(),
            }
        }
        _ => counted.clone(),
    };
    offsets
        .into_iter()
        .map(|(b, d)| {
            let joint = &model.bodies[b].joint;
            let location = joint.parent_offset.translation.vector + d.component_div(&parent_scale(b));
            JointMove {
                body: model.bodies[b].name.clone(),
                joint: joint.name.clone(),
                location_m: location.into(),
                moved_mm: (d * 1e3).into(),
                residual_mm: None,
            }
        })
        .collect()
}

/// The largest rotation between any orientation and their first (deg).
fn range_of_motion_deg(r: &[nalgebra::Matrix3<f64>]) -> f64 {
    let Some(first) = r.first() else { return 0.0 };
    r.iter()
        .map(|m| {
            let c = ((first.transpose() * m).trace() - 1.0) / 2.0;
            crate::model::math::acos(c.clamp(-1.0, 1.0)).to_degrees()
        })
        .fold(0.0, f64::max)
}

/// The least-squares centre of spheres through each marker's points (one radius per marker);
/// `None` when the points do not determine it.
fn sphere_centre(samples: &[(usize, Vector3<f64>)]) -> Option<Vector3<f64>> {
    let mut markers: Vec<usize> = samples.iter().map(|s| s.0).collect();
    markers.sort_unstable();
    markers.dedup();
    let n = 3 + markers.len();
    if samples.len() < n + 3 {
        return None;
    }
    // ‖x‖² = 2 cᵀx + k_m: unknowns (c, k_1 … k_M).
    let mut a = DMatrix::zeros(samples.len(), n);
    let mut b = DVector::zeros(samples.len());
    for (row, (m, x)) in samples.iter().enumerate() {
        for k in 0..3 {
            a[(row, k)] = 2.0 * x[k];
        }
        a[(row, 3 + markers.binary_search(m).ok()?)] = 1.0;
        b[row] = x.norm_squared();
    }
    let sol = a.svd(true, true).solve(&b, 1e-9).ok()?;
    Some(Vector3::new(sol[0], sol[1], sol[2])).filter(|c| c.iter().all(|v| v.is_finite()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_turning_about_a_centre_give_that_centre() {
        let c = Vector3::new(0.1, -0.08, 0.02);
        let mut s = Vec::new();
        for (m, r) in [(0usize, 0.2), (1, 0.35)] {
            for k in 0..40 {
                let (a, b) = (k as f64 * 0.11, k as f64 * 0.07 + 0.3 * m as f64);
                s.push((m, c + r * Vector3::new(a.sin() * b.cos(), a.sin() * b.sin(), -a.cos())));
            }
        }
        let fit = sphere_centre(&s).expect("determined");
        assert!((fit - c).norm() < 1e-9, "{fit:?}");
    }

    #[test]
    fn symmetric_hip_moves_keep_what_both_fits_share_and_drop_what_a_pelvis_list_would_make() {
        let ctx = crate::pipeline::Context::shipped().expect("shipped");
        let fit = |body: &str, offset_mm: [f64; 3]| FunctionalCentre {
            body: body.into(),
            distance_mm: Vector3::from(offset_mm).norm(),
            offset_mm,
            range_of_motion_deg: 40.0,
            samples: 300,
        };
        // The shipped pelvis: x forward, y left, z up; the right fit 20 mm up, the left 10 mm down.
        let centres = [fit("femur_r", [10.0, -5.0, 20.0]), fit("femur_l", [10.0, 5.0, -10.0])];
        let p = ctx.proxy.default_proxies();
        let moves = hip_moves(&ctx.model, &ctx.proxy, &p, &centres, true);
        let got: Vec<Vector3<f64>> = moves.iter().map(|m| Vector3::from(m.moved_mm)).collect();
        assert!((got[0] - Vector3::new(10.0, -5.0, 5.0)).norm() < 1e-9, "{got:?}");
        assert!((got[1] - Vector3::new(10.0, 5.0, 5.0)).norm() < 1e-9, "{got:?}");
        let b = ctx.model.body_index("femur_r").unwrap();
        let moved = crate::pipeline::context::with_joint_moves(&ctx.model, &moves);
        let t = moved.bodies[b].joint.parent_offset.translation.vector
            - ctx.model.bodies[b].joint.parent_offset.translation.vector;
        assert!((t * 1e3 - got[0]).norm() < 1e-9, "unit scale: the location moves by the offset");
        // Per hip: each its own; too little motion: none.
        assert_eq!(hip_moves(&ctx.model, &ctx.proxy, &p, &centres, false)[0].moved_mm, [10.0, -5.0, 20.0]);
        let still = [FunctionalCentre { range_of_motion_deg: 5.0, ..centres[0].clone() }];
        assert!(hip_moves(&ctx.model, &ctx.proxy, &p, &still, true).is_empty());
    }
}
