//! Functional hip centres applied (`functional_hips = "apply"`, `docs/CALIBRATION.md`): the hips
//! of the subject's model move to where the calibrated subject's thigh markers turn about, and the
//! subject is calibrated again with them, until a pass moves neither hip by more than
//! [`joint_centres::APPLY_TOL_MM`] or the accumulated move leaves [`joint_centres::APPLY_MAX_MM`].

use crate::pipeline::calibration::joint_centres;
use crate::pipeline::context::Context;
use crate::pipeline::input::trial::TrialError;
use crate::solve::calibration::StageCost;
use crate::solve::Calibration;
use nalgebra::Vector3;

/// From `first`, the subject's calibration on `ctx`'s model (started at `started`): the
/// calibration with the hips moved to their fixed point (its `joint_moves` say where), `first`
/// when nothing moves, or `first` with a warning when the move would leave the bound.
/// `pass_with` calibrates the subject on a given context.
pub fn apply(
    ctx: &Context,
    first: Calibration,
    started: std::time::Instant,
    pass_with: impl Fn(&Context) -> Result<Calibration, TrialError>,
) -> Result<Calibration, TrialError> {
    let s = &ctx.settings;
    // A fixed point: the hips move until the functional centres the calibrated subject's
    // landmarks give agree with them (each pass sees only part of the remaining offset, as the
    // poses partly absorb a misplaced hip).
    let mut stages = first.stages.clone();
    let mut moved = ctx.clone();
    let mut cal = first.clone();
    let mut moves: Vec<crate::solve::prior::JointMove> = Vec::new();
    let mut refused = None;
    for pass in 1..=joint_centres::APPLY_MAX_PASSES {
        let step = joint_centres::hip_moves(
            &moved.model,
            &moved.proxy,
            &cal.proxies,
            &cal.landmark_centres,
            s.functional_hips_symmetric,
        );
        let largest = step.iter().map(|m| Vector3::from(m.moved_mm).norm()).fold(0.0, f64::max);
        if step.is_empty() || largest < joint_centres::APPLY_TOL_MM {
            break;
        }
        for m in step {
            match moves.iter_mut().find(|k| k.body == m.body) {
                Some(k) => k.location_m = m.location_m,
                None => moves.push(m),
            }
        }
        // Beyond the plausible bound the fits are not taken: the first calibration stands.
        total_moves(ctx, &cal.proxies, &mut moves);
        let bound = joint_centres::APPLY_MAX_MM;
        if let Some(m) = moves.iter().find(|m| Vector3::from(m.moved_mm).norm() > bound) {
            refused = Some(format!(
                "functional hips not applied: {} would move {:.1} mm after {} pass(es), beyond {bound} mm (the thigh markers do not turn about one point of the pelvis)",
                m.joint,
                Vector3::from(m.moved_mm).norm(),
                pass - 1
            ));
            break;
        }
        moved = ctx.with_joint_moves(&moves);
        cal = pass_with(&moved)?;
        stages
            .extend(cal.stages.iter().map(|st| StageCost { stage: format!("hips_{pass}:{}", st.stage), ..st.clone() }));
    }
    let seconds = started.elapsed().as_secs_f64();
    if let Some(why) = refused {
        let mut first = first;
        first.registration_report.warnings.push(why);
        return Ok(Calibration { stages, seconds, ..first });
    }
    if moves.is_empty() {
        return Ok(Calibration { stages, seconds, ..first });
    }
    total_moves(ctx, &cal.proxies, &mut moves);
    for mv in &mut moves {
        mv.residual_mm = cal.landmark_centres.iter().find(|c| c.body == mv.body).map(|c| c.distance_mm);
    }
    cal.joint_moves = moves;
    Ok(Calibration { stages, seconds, ..cal })
}

/// Sets each move's `moved_mm`: its joint's new location against `ctx`'s model's, at the scales
/// of `proxies`, in the parent's frame.
fn total_moves(ctx: &Context, proxies: &[f64], moves: &mut [crate::solve::prior::JointMove]) {
    let y = ctx.proxy.state(proxies);
    for mv in moves {
        let Some(b) = ctx.model.body_index(&mv.body) else { continue };
        let p = ctx.model.bodies[b].parent.unwrap_or(b);
        let scale = Vector3::from_fn(|a, _| y[ctx.model.scale_index(p, a)]);
        let d = (Vector3::from(mv.location_m) - ctx.model.bodies[b].joint.parent_offset.translation.vector)
            .component_mul(&scale);
        mv.moved_mm = (d * 1e3).into();
    }
}
