//! Calibrating a subject from its files' frames: choosing the frames, the priors, and the
//! stages of the joint solve ([`crate::solve::calibrate`]).
//!
//! With marker registration (the default for a generic model):
//! 1. poses are tracked through each trial with the anatomical markers (multi-start for the
//!    first frame), and frames spread over all trials are chosen;
//! 2. scales and poses are solved jointly on the anatomical markers, offsets held;
//! 3. tracking markers' offsets start where those poses saw them (clamped to their bound);
//! 4. scales, poses and every marker's offset are solved jointly on all markers, the offsets
//!    regularised toward the model's (anatomical strongly, tracking weakly).
//!
//! Without registration, step 2 runs on all markers; an OpenSim `MarkerPlacer` (or
//! `--place-markers`) then moves the unfixed markers as OpenSim does.

use crate::io::MarkerTrial;
use crate::kinematics::assembly::FrameProblem;
use crate::model::proxy::ProxyKind;
use crate::model::MarkerClass;
use crate::pipeline::calibration::frames::{choose, TrialScan};
use crate::pipeline::calibration::priors::{prior_report, priors, units_check};
use crate::pipeline::context::Context;
use crate::pipeline::input::frames::TrialFrames;
use crate::pipeline::input::trial::{match_markers, no_match, observation_row, TrialError};
use crate::solve::calibrate::{finish, initial_state_weighted, Tracker};
use crate::solve::joint::JointProblem;
use crate::solve::placement::place_markers;
use crate::solve::prior::StaticPosture;
use crate::solve::FunctionalHips;
use crate::solve::StageCost;
use crate::solve::{make_qp, Calibration, FrameSolver};
use nalgebra::Vector3;

/// Frames between tracked frames: `step_s` at `rate_hz`, at least 1 (every frame when the rate
/// is unknown or `step_s` is 0).
fn track_step(step_s: f64, rate_hz: f64) -> usize {
    let k = (step_s * rate_hz).floor();
    if k.is_finite() && k >= 1.0 {
        (k as usize).min(1000)
    } else {
        1
    }
}

/// Calibrates one subject's morphology (and, with registration, its markers' offsets) from
/// frames pooled over `trials`: a static trial when the context says it calibrates on one
/// (`static_calibration`), else the motion trials themselves.
pub fn calibrate_subject(ctx: &Context, trials: &[(&str, &MarkerTrial)]) -> Result<Calibration, TrialError> {
    if ctx.static_calibration {
        calibrate_subject_with(ctx, trials, &[])
    } else {
        calibrate_subject_with(ctx, &[], trials)
    }
}

/// Which weights a calibration frame uses.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Static,
    Motion,
}

/// Calibrates one subject from its static trials and its motion trials together: one
/// morphology that fits both (`calibration_frames` from the static trials with their weights,
/// `calibration_frames_motion` spread over the motion trials with the motion weights). Marker
/// placement (OpenSim's MarkerPlacer) places on the static frames when there are any.
///
/// With `functional_hips = "apply"` and registration, the hips whose functional centres are well
/// determined ([`crate::pipeline::calibration::joint_centres::hip_moves`]) move there and the subject is calibrated again
/// with them (every stage: the frames' poses, scales and registered offsets all depend on where
/// the hips are); the calibration says where they moved (`joint_moves`), and the subject's model
/// ([`Context::pinned_to`]) has them there.
pub fn calibrate_subject_with<T: TrialFrames + ?Sized>(
    ctx: &Context,
    statics: &[(&str, &T)],
    motions: &[(&str, &T)],
) -> Result<Calibration, TrialError> {
    let started = std::time::Instant::now();
    let s = &ctx.settings;
    let first = calibrate_pass(ctx, statics, motions)?;
    if s.functional_hips != FunctionalHips::Apply || !s.registration || s.marker_placement {
        return Ok(first);
    }
    crate::pipeline::calibration::functional_hips::apply(ctx, first, started, |c: &Context| {
        calibrate_pass(c, statics, motions)
    })
}

/// One calibration of the subject on `ctx`'s model (see [`calibrate_subject_with`]).
fn calibrate_pass<T: TrialFrames + ?Sized>(
    ctx: &Context,
    statics: &[(&str, &T)],
    motions: &[(&str, &T)],
) -> Result<Calibration, TrialError> {
    let started = std::time::Instant::now();
    let settings = &ctx.settings;
    ctx.subject.validate()?;
    let nm = ctx.model.markers.len();
    let stride = 3 * nm;
    let eval = ctx.evaluator();
    let placing = settings.marker_placement;
    let registering = settings.registration && !placing;
    let classes = ctx.marker_classes();
    let any_fixed = ctx.model.markers.iter().any(|m| m.fixed);
    let anatomical = classes.iter().filter(|c| **c == MarkerClass::Anatomical).count();
    // Weights of the first stage: with placement, markers flagged fixed alone inform the
    // scales (when the model flags any); with registration, anatomical markers alone (when
    // there are enough of them).
    let first = |all: &[f64]| -> Vec<f64> {
        ctx.model
            .markers
            .iter()
            .zip(all)
            .zip(&classes)
            .map(|((m, &w), c)| {
                if (placing && any_fixed && !m.fixed) || (registering && anatomical >= 6 && *c == MarkerClass::Tracking)
                {
                    0.0
                } else {
                    w
                }
            })
            .collect()
    };
    let all_w = |k: Kind| if k == Kind::Static { &ctx.calibration_weights } else { &ctx.marker_weights };
    let first_static = first(all_w(Kind::Static));
    let first_motion = first(all_w(Kind::Motion));
    let first_w = |k: Kind| if k == Kind::Static { &first_static } else { &first_motion };
    let (coord_ref, coord_w) = ctx.coordinate_tracking();
    // Static frames: the coordinate targets plus the known standing posture.
    let mut posture = StaticPosture::neutral(
        &ctx.model,
        settings.static_posture_sd_deg.to_radians(),
        settings.prior_noise_sd_m,
        &ctx.static_posture_values,
    );
    if settings.static_arms == crate::solve::StaticArms::Neutral {
        let sd = settings.static_posture_sd_deg.to_radians();
        posture.hold_arms(&ctx.model, sd, settings.prior_noise_sd_m, &ctx.static_posture_values);
    }
    let (static_ref, static_w) = posture.fold(&coord_ref, &coord_w);
    let tracking_of = |k: Kind| match k {
        Kind::Static => (static_ref.as_slice(), static_w.as_slice()),
        Kind::Motion => (coord_ref.as_slice(), coord_w.as_slice()),
    };
    let mut solver = FrameSolver::new(&eval, settings.clone(), make_qp(settings.qp));
    let np = ctx.proxy.np();
    let scale: Vec<usize> = (0..np).filter(|&k| ctx.proxy.proxies[k].kind == ProxyKind::Scale).collect();
    let pri = priors(ctx, &scale, settings.prior_noise_sd_m, 0)?;
    let mut p0 = ctx.proxy.default_proxies();
    for &k in &scale {
        let (lo, hi) = ctx.proxy.proxies[k].range;
        p0[k] = pri.ratio.clamp(lo, hi);
    }
    let mut stages: Vec<StageCost> = Vec::new();
    let track_started = std::time::Instant::now();
    let mut tracked = 0u32;
    let mut pooled: Vec<f64> = Vec::new();
    let mut starts: Vec<Vec<f64>> = Vec::new();
    let mut kinds: Vec<Kind> = Vec::new();
    // Each calibration frame's trial (index in statics, then motions).
    let mut trial_of: Vec<usize> = Vec::new();
    let inputs: Vec<(&(&str, &T), Kind)> =
        statics.iter().map(|t| (t, Kind::Static)).chain(motions.iter().map(|t| (t, Kind::Motion))).collect();
    // First pass, trial by trial: the markers matched, observed markers per frame, the frames
    // the units check looks at (every (n / 20)th) and the candidate calibration frames.
    let mut scans: Vec<(Vec<Option<usize>>, TrialScan)> = Vec::with_capacity(inputs.len());
    for &((name, t), kind) in &inputs {
        let header = t.header();
        let map = match_markers(ctx, name, header)?.columns;
        if map.iter().all(Option::is_none) {
            return Err(no_match(ctx, name, header));
        }
        let read = |why: String| TrialError::Read { trial: name.to_string(), why };
        let step = track_step(settings.calibration_track_step_s, header.rate_hz);
        let rows = settings.calibration_coverage_m > 0.0;
        let (scan, sample) = TrialScan::of(*t, &map, first_w(kind), step, settings.min_markers, rows).map_err(read)?;
        units_check(ctx, name, &sample, stride, all_w(kind), &p0)?;
        scans.push((map, scan));
    }
    // Each group's frames (statics, motions): spread over time, or over the range of poses
    // (`calibration_coverage_m`).
    let mut chosen: Vec<Vec<usize>> = Vec::with_capacity(inputs.len());
    for kind in [Kind::Static, Kind::Motion] {
        let group: Vec<&TrialScan> =
            inputs.iter().zip(&scans).filter(|((_, k), _)| *k == kind).map(|(_, (_, s))| s).collect();
        let wanted =
            if kind == Kind::Static { settings.calibration_frames } else { settings.calibration_frames_motion };
        chosen.extend(choose(&group, first_w(kind), settings.min_markers, wanted, settings.calibration_coverage_m));
    }
    for (input, ((((name, t), kind), (map, scan)), chosen)) in inputs.iter().zip(&scans).zip(&chosen).enumerate() {
        let Some(&last) = chosen.last() else { continue };
        let kind = *kind;
        let read = |why: String| TrialError::Read { trial: name.to_string(), why };
        // Track from the first usable frame to the last chosen one so that every chosen frame
        // starts from a pose continuous with the motion (a cold start far into a motion can land
        // in a wrong local minimum): every frame `calibration_track_step_s` apart (at least every
        // frame; the chosen ones always), each warm-started from the one before. A static trial
        // does not move: its chosen frames alone, each from the one before.
        let counts = &scan.counts;
        let (begin, step) = match kind {
            Kind::Static => (chosen[0], usize::MAX),
            _ => (
                (0..=last).find(|&f| counts[f] >= settings.min_markers).unwrap_or(0),
                track_step(settings.calibration_track_step_s, t.header().rate_hz),
            ),
        };
        let w1 = first_w(kind);
        let (tracking_ref, tracking_weights) = tracking_of(kind);
        let template = FrameProblem { observed: &[], marker_weights: w1, tracking_ref, tracking_weights };
        let mut tracker = Tracker::new(&mut solver, &p0);
        let mut next = chosen.iter().copied().peekable();
        // A trial held whole is read in place (its window of every frame is not a copy) and only
        // the tracked frames' observations are gathered; one read from its file, a window at a
        // time up to its last chosen frame.
        let whole = t.window_frames() == usize::MAX;
        let mut row = vec![f64::NAN; stride];
        let mut a = begin;
        while a <= last {
            let (w0, b) =
                if whole { (0, last + 1) } else { (a, a.saturating_add(t.window_frames().max(1)).min(last + 1)) };
            let w = t.window(w0..if whole { t.header().n_frames() } else { b }).map_err(read)?;
            for f in a..b {
                let is_chosen = next.peek() == Some(&f);
                if !is_chosen && (f - begin) % step != 0 {
                    continue;
                }
                observation_row(&w, map, f - w0, &mut row);
                // Frames between calibration frames only carry the pose forward: a few
                // iterations (`calibration_track_iterations`) rather than convergence.
                let cap = settings.calibration_track_iterations;
                let iterations = if is_chosen || cap == 0 { settings.max_iterations } else { cap };
                let p = tracker.step_limited(&mut solver, &row, &template, iterations);
                tracked += 1;
                if is_chosen {
                    next.next();
                    pooled.extend_from_slice(&row);
                    starts.push(p.to_vec());
                    kinds.push(kind);
                    trial_of.push(input);
                }
            }
            a = b;
        }
        tracker.end(&mut solver);
    }
    if pooled.is_empty() {
        let trial = statics.iter().chain(motions).map(|(n, _)| *n).collect::<Vec<_>>().join(", ");
        return Err(TrialError::NothingToCalibrate { trial, min: settings.min_markers });
    }
    let slices: Vec<&[f64]> = pooled.chunks(stride).collect();
    stages.push(StageCost::new("track", slices.len(), tracked, 0, track_started));
    let pri = priors(ctx, &scale, settings.prior_noise_sd_m, slices.len())?;
    let w_first: Vec<&[f64]> = kinds.iter().map(|&k| first_w(k).as_slice()).collect();
    let w_all: Vec<&[f64]> = kinds.iter().map(|&k| all_w(k).as_slice()).collect();
    let template = FrameProblem {
        observed: &[],
        marker_weights: &first_motion,
        tracking_ref: &coord_ref,
        tracking_weights: &coord_w,
    };
    let generic: Vec<Vector3<f64>> = ctx.model.markers.iter().map(|m| m.offset).collect();
    let none = vec![false; nm];
    // Stage 1: scales and poses on the first-stage markers.
    let t = std::time::Instant::now();
    let mut state = initial_state_weighted(&mut solver, &slices, &w_first, &template, &p0, &starts);
    stages.push(StageCost::new("initial", slices.len(), slices.len() as u32, 0, t));
    let t = std::time::Instant::now();
    let terms = pri.all();
    let refs: Vec<&[f64]> = kinds.iter().map(|&k| tracking_of(k).0).collect();
    let tracking_w: Vec<&[f64]> = kinds.iter().map(|&k| tracking_of(k).1).collect();
    let stage1 = JointProblem {
        model: &ctx.model,
        proxy: &ctx.proxy,
        settings,
        frames: &slices,
        weights: &w_first,
        tracking_refs: &refs,
        tracking_weights: &tracking_w,
        registered: &none,
        reference: &generic,
        bound_m: 0.0,
        terms: &terms,
    };
    let mut out = stage1.solve(&mut state);
    stages.push(StageCost::new("scales", slices.len(), out.iterations, out.rejected, t));
    let mut iterations = out.iterations;
    // Empirical Bayes: the scale priors are weighed against the marker error the data show
    // (stage 1's RMSE, within [0.5, 30] mm: half a millimetre is about what optical motion
    // capture resolves) rather than a fixed one: clean data (a static trial, noise of a
    // millimetre) outweigh the survey, noisy motion data lean on it more.
    let noise = if out.rmse_m.is_finite() { out.rmse_m.clamp(0.0005, 0.03) } else { settings.prior_noise_sd_m };
    let pri = priors(ctx, &scale, noise, slices.len())?;
    let terms = pri.all();
    // A static trial's feet rest on the floor: from here on its frames' feet are pulled toward
    // level in the poses stage 1 found (docs/CALIBRATION.md, "Feet flat").
    let statics_at: Vec<usize> = (0..kinds.len()).filter(|&i| kinds[i] == Kind::Static).collect();
    let static_poses: Vec<Vec<f64>> = statics_at.iter().map(|&i| state.poses[i].clone()).collect();
    let feet = crate::pipeline::calibration::feet_flat::feet_level(ctx, &posture, &static_poses);
    let (flat_ref, flat_w) = match &feet {
        Some(f) => f.posture.fold(&coord_ref, &coord_w),
        None => (static_ref.clone(), static_w.clone()),
    };
    let refs: Vec<&[f64]> =
        kinds.iter().map(|&k| if k == Kind::Static { flat_ref.as_slice() } else { tracking_of(k).0 }).collect();
    let tracking_w: Vec<&[f64]> =
        kinds.iter().map(|&k| if k == Kind::Static { flat_w.as_slice() } else { tracking_of(k).1 }).collect();
    let stage1 = JointProblem { terms: &terms, tracking_refs: &refs, tracking_weights: &tracking_w, ..stage1 };
    if !registering {
        let t = std::time::Instant::now();
        out = stage1.solve(&mut state);
        stages.push(StageCost::new("scales_reweighed", slices.len(), out.iterations, out.rejected, t));
        iterations += out.iterations;
    }
    let mut offsets = None;
    let mut registered = 0;
    // Frames that placement and registration initialise offsets from: the static ones if any.
    let place_on: Vec<usize> = match kinds.contains(&Kind::Static) {
        true => (0..kinds.len()).filter(|&i| kinds[i] == Kind::Static).collect(),
        false => (0..kinds.len()).collect(),
    };
    let place_frames: Vec<&[f64]> = place_on.iter().map(|&i| slices[i]).collect();
    let place_poses: Vec<Vec<f64>> = place_on.iter().map(|&i| state.poses[i].clone()).collect();
    // The hips' functional centres in the pelvis frame the landmarks give at the model's
    // offsets, before registration can move the pelvis's markers to absorb a misplaced hip.
    let landmark_centres = if settings.functional_hips == FunctionalHips::Apply {
        crate::pipeline::calibration::joint_centres::functional_centres(&ctx.model, &ctx.proxy, &slices, &state.poses)
    } else {
        Vec::new()
    };
    // Markers some calibration frame observes with a weight: those registration can move.
    let seen: Vec<bool> = (0..nm)
        .map(|m| slices.iter().zip(&w_all).any(|(f, w)| w[m] > 0.0 && f[3 * m..3 * m + 3].iter().all(|v| !v.is_nan())))
        .collect();
    let t = std::time::Instant::now();
    if registering {
        // Stage 2: tracking markers start where the stage-1 poses saw them.
        let tracking: Vec<bool> = classes.iter().map(|c| *c == MarkerClass::Tracking).collect();
        let placed = place_markers(&ctx.model, &ctx.proxy, &place_frames, &place_poses, &tracking);
        let b = settings.registration_bound_m;
        for (m, p) in placed.iter().enumerate() {
            if let Some(p) = p {
                state.offsets[m] = p.zip_map(&generic[m], |v, g| v.clamp(g - b, g + b));
            }
        }
        let (offset_prior, anchor) = crate::pipeline::calibration::registration::registration_priors(
            ctx,
            &classes,
            &generic,
            settings.prior_noise_sd_m,
            slices.len(),
            &seen,
        );
        let mut all_terms = terms.clone();
        all_terms.push(&offset_prior);
        all_terms.push(&anchor);
        let reg = seen.clone();
        let stage2 = JointProblem { weights: &w_all, registered: &reg, bound_m: b, terms: &all_terms, ..stage1 };
        out = stage2.solve(&mut state);
        stages.push(StageCost::new("registration", slices.len(), out.iterations, out.rejected, t));
        iterations += out.iterations;
        registered = reg.iter().filter(|r| **r).count();
        if let Some(f) = &feet {
            crate::pipeline::calibration::feet_flat::place_feet_level(
                ctx,
                f,
                &classes,
                &seen,
                &statics_at,
                &slices,
                &mut state,
            );
        }
        offsets = Some(state.offsets.clone());
    } else if placing {
        let movable: Vec<bool> = ctx.model.markers.iter().map(|m| !m.fixed).collect();
        let placed = place_markers(&ctx.model, &ctx.proxy, &place_frames, &place_poses, &movable);
        offsets = Some(placed.iter().zip(&ctx.model.markers).map(|(p, m)| p.unwrap_or(m.offset)).collect());
        stages.push(StageCost::new("placement", place_frames.len(), 0, 0, t));
    }
    let t = std::time::Instant::now();
    out.iterations = iterations;
    let mut cal = finish(state, out, &p0, &ctx.proxy, offsets, registered, started);
    cal.static_frames = kinds.iter().filter(|k| **k == Kind::Static).count();
    cal.posture = crate::pipeline::calibration::posture::static_posture(ctx, &cal.frame_proxies[..cal.static_frames]);
    cal.registration_report = crate::pipeline::calibration::registration::registration_report(ctx, &cal);
    if let Some(f) = &feet {
        cal.posture.feet = f.report(&ctx.model);
        cal.registration_report.warnings.extend(f.warnings.iter().cloned());
    }
    cal.landmark_centres = landmark_centres;
    if settings.functional_hips != FunctionalHips::Off {
        cal.functional_centres = crate::pipeline::calibration::joint_centres::functional_centres(
            &ctx.model,
            &ctx.proxy,
            &slices,
            &cal.frame_proxies,
        );
    }
    // How each motion trial's calibration frames fit the calibrated subject, against its siblings.
    let mut model = ctx.model.clone();
    if let Some(o) = &cal.marker_offsets {
        model.markers.iter_mut().zip(o).for_each(|(m, o)| m.offset = *o);
    }
    let fit = crate::kinematics::assembly::Evaluator::new(&model, &ctx.proxy);
    let mut ws = crate::kinematics::assembly::EvalWorkspace::new(&model, &ctx.proxy);
    let mut per_trial: Vec<Vec<f64>> = vec![Vec::new(); statics.len() + motions.len()];
    for (k, (frame, p)) in slices.iter().zip(&cal.frame_proxies).enumerate() {
        let fp = FrameProblem { observed: frame, marker_weights: w_all[k], tracking_ref: &[], tracking_weights: &[] };
        let (_, sq, used) = fit.energy(p, &fp, &mut ws);
        if used > 0 {
            per_trial[trial_of[k]].push((sq / used as f64).sqrt());
        }
    }
    let motion_fits: Vec<(&str, Vec<f64>)> =
        motions.iter().zip(per_trial.into_iter().skip(statics.len())).map(|((n, _), r)| (*n, r)).collect();
    cal.trial_misfits = crate::pipeline::calibration::subject_check::misfits(&motion_fits);
    let report = prior_report(ctx, &pri, &scale, &cal);
    if let Some(h) = report.stature_m.filter(|h| !(0.5..=2.6).contains(h)) {
        let trial = statics.iter().chain(motions).map(|(n, _)| *n).collect::<Vec<_>>().join(", ");
        return Err(TrialError::Implausible {
            trial,
            message: format!(
                "the calibrated subject is {h:.2} m tall, outside any human range: check the marker data's units (--units) and up axis (--up), and that the model fits the marker set"
            ),
        });
    }
    stages.push(StageCost::new("report", slices.len(), 0, 0, t));
    Ok(Calibration { seconds: started.elapsed().as_secs_f64(), prior: report, stages, ..cal })
}

#[cfg(test)]
mod tests {
    use super::track_step;

    #[test]
    fn tracking_steps_by_time_and_never_skips_at_low_rates() {
        assert_eq!(track_step(0.03, 100.0), 3);
        assert_eq!(track_step(0.03, 60.0), 1);
        assert_eq!(track_step(0.03, 240.0), 7);
        assert_eq!(track_step(0.0, 100.0), 1);
        assert_eq!(track_step(0.03, f64::NAN), 1);
    }
}
