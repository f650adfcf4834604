//! Functional hip centres (`functional_hips = "apply"`): a subject whose hips sit away from the
//! model's gets them moved where the motion shows them, and its angles follow.

use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::pipeline::{calibrate_subject, solve_trial, Context};
use smocap::solve::prior::JointMove;
use smocap::solve::FunctionalHips;

/// The shipped model with both hips `forward_m` further forward in the pelvis (unit scale).
fn hips_moved_forward(ctx: &Context, forward_m: f64) -> Context {
    let moves: Vec<JointMove> = ["femur_r", "femur_l"]
        .iter()
        .map(|b| {
            let joint = &ctx.model.bodies[ctx.model.body_index(b).expect("femur")].joint;
            let mut t = joint.parent_offset.translation.vector;
            t.x += forward_m;
            JointMove {
                body: b.to_string(),
                joint: joint.name.clone(),
                location_m: t.into(),
                moved_mm: [forward_m * 1e3, 0.0, 0.0],
                residual_mm: None,
            }
        })
        .collect();
    ctx.with_joint_moves(&moves)
}

/// RMSE (deg) of the hip flexions of `ctx`'s solve of `s` against its truth.
fn hip_flexion_rmse_deg(
    ctx: &Context,
    s: &smocap::kinematics::synth::Synthetic,
    cal: &smocap::solve::Calibration,
) -> f64 {
    let r = solve_trial(ctx, "walk", &s.trial, cal, 2).expect("solves");
    let joints: Vec<usize> =
        ["hip_flexion_r", "hip_flexion_l"].iter().map(|c| ctx.model.coordinate_index(c).expect("hip")).collect();
    let (mut sq, mut n) = (0.0, 0usize);
    for (p, t) in r.proxies.iter().zip(&s.truth.proxies) {
        let (y, yt) = (ctx.proxy.state(p), ctx.proxy.state(t));
        for &j in &joints {
            sq += (y[j] - yt[j]).to_degrees().powi(2);
            n += 1;
        }
    }
    (sq / n as f64).sqrt()
}

#[test]
fn hips_15_mm_forward_of_the_models_are_found_and_moved_there() {
    let ctx = Context::shipped().expect("shipped");
    let truth = hips_moved_forward(&ctx, 0.015);
    let opt = SynthOptions { frames: 600, seed: 11, scale_spread: 0.05, ..SynthOptions::default() };
    let s = synthesize(&truth.model, &truth.proxy, &opt);
    let pelvis = s.truth.body_scales["pelvis"];
    let mut report = ctx.clone();
    report.settings.functional_hips = FunctionalHips::Report;
    let mut apply = ctx.clone();
    apply.settings.functional_hips = FunctionalHips::Apply;
    let cal_report = calibrate_subject(&report, &[("walk", &s.trial)]).expect("calibrates");
    let cal_apply = calibrate_subject(&apply, &[("walk", &s.trial)]).expect("calibrates");
    assert!(cal_report.joint_moves.is_empty(), "report moves nothing");
    assert_eq!(cal_apply.joint_moves.len(), 2, "{:?}", cal_report.functional_centres);
    let want = 15.0 * pelvis[0];
    for m in &cal_apply.joint_moves {
        eprintln!(
            "{}: moved {:+.1} {:+.1} {:+.1} mm (truth {want:+.1} 0 0), residual {:?} mm",
            m.joint, m.moved_mm[0], m.moved_mm[1], m.moved_mm[2], m.residual_mm
        );
        let err = (nalgebra::Vector3::from(m.moved_mm) - nalgebra::Vector3::new(want, 0.0, 0.0)).norm();
        assert!(err <= 4.0, "{}: moved {:?} mm, truth {want:.1} mm forward", m.joint, m.moved_mm);
    }
    let before = hip_flexion_rmse_deg(&ctx, &s, &cal_report);
    let after = hip_flexion_rmse_deg(&apply, &s, &cal_apply);
    eprintln!("hip flexion against the truth: {before:.2}° with the model's hips, {after:.2}° with the moved ones");
    assert!(after < before, "{after:.2}° moved against {before:.2}°");
}

#[test]
fn functional_hips_is_a_setting_that_reports_by_default() {
    let s = smocap::solve::SolverSettings::default();
    assert_eq!(s.functional_hips, FunctionalHips::Report);
    assert!(s.functional_hips_symmetric);
    let table: toml::Table = toml::from_str("functional_hips = \"apply\"").expect("toml");
    assert_eq!(s.with_overrides(&table).expect("applies").functional_hips, FunctionalHips::Apply);
    let bad: toml::Table = toml::from_str("functional_hips = \"always\"").expect("toml");
    assert!(s.with_overrides(&bad).is_err());
}
