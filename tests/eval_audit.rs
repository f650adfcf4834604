//! Leakage audit on a few small synthetic subjects: the report's shape (trials, wins, per-subject
//! errors of both methods), errors finite and of plausible size, the baseline's scaling from
//! marker pairs, and determinism for a seed. No accuracy threshold: the ≥ 20-subject result is a
//! CLI run recorded in docs/EVALUATION.md.

use smocap::eval::audit::stagewise::{measure, pinned, shipped_measurements};
use smocap::eval::audit::subjects::{subject, SubjectSpec};
use smocap::eval::audit::{audit_synthetic, segment_lengths};
use smocap::model::proxy::ProxyKind;
use smocap::pipeline::Context;

fn small() -> SubjectSpec {
    SubjectSpec { static_frames: 30, motion_frames: 40, ..SubjectSpec::default() }
}

#[test]
fn audit_report_has_trials_wins_and_both_methods_errors() {
    let ctx = Context::shipped().unwrap();
    let r = audit_synthetic(&ctx, 2, 3, &small());
    assert!(r.failed.is_empty(), "{:?}", r.failed);
    assert_eq!(r.trials, 2);
    assert_eq!(r.subjects.len(), 2);
    for w in [r.wins.pose, r.wins.scale, r.wins.marker] {
        assert!(w <= 2);
    }
    assert!(r.wins.pose + r.stagewise_wins.pose <= 2);
    for s in &r.subjects {
        for e in [&s.joint, &s.stagewise] {
            // Plausible sizes: degrees, millimetres and percent of everyday magnitude.
            assert!(e.pose_deg.is_finite() && e.pose_deg > 0.0 && e.pose_deg < 45.0, "{e:?}");
            assert!(e.knee_deg.is_finite() && e.knee_deg < 45.0, "{e:?}");
            assert!(e.scale_mm.is_finite() && e.scale_mm < 200.0, "{e:?}");
            assert!(e.scale_pct.is_finite() && e.scale_pct < 60.0, "{e:?}");
            assert!(e.marker_rmse_mm.is_finite() && e.marker_rmse_mm > 0.5 && e.marker_rmse_mm < 100.0, "{e:?}");
        }
    }
    let json = serde_json::to_value(&r).unwrap();
    for k in ["pose", "scale", "marker"] {
        assert!(json["wins"][k].is_u64(), "wins.{k}");
    }
    assert_eq!(json["trials"], 2);
    assert!(json["subjects"][0]["joint"]["pose_deg"].is_f64());
    assert!(json["subjects"][0]["stagewise"]["scale_mm"].is_f64());
    // Deterministic for a seed.
    let again = audit_synthetic(&ctx, 1, 3, &small());
    assert_eq!(again.subjects[0].joint.pose_deg, r.subjects[0].joint.pose_deg);
    assert_eq!(again.subjects[0].stagewise.scale_mm, r.subjects[0].stagewise.scale_mm);
}

#[test]
fn stagewise_scaling_measures_every_group_and_freezes_it() {
    let ctx = Context::shipped().unwrap();
    let s = subject(&ctx, &small(), 5, 0);
    let scale = measure(&ctx, &s.static_trial, &shipped_measurements(), &[]);
    assert!(scale.notes.is_empty(), "{:?}", scale.notes);
    let p = pinned(&ctx, &scale);
    let lengths = segment_lengths(&ctx);
    for (k, px) in p.proxy.proxies.iter().enumerate() {
        if px.kind != ProxyKind::Scale {
            continue;
        }
        // Every scale group is measured, pinned, and within a plausible range of the truth.
        assert_eq!(px.range.0, px.range.1, "{} not pinned", px.name);
        assert_eq!(px.default, px.range.0);
        let truth = s.truth_proxies[0][k];
        assert!((px.default - truth).abs() < 0.3, "{}: measured {} truth {truth}", px.name, px.default);
        assert!(lengths[k] > 0.02 && lengths[k] < 1.0, "{}: length {}", px.name, lengths[k]);
    }
}

#[test]
fn synthetic_subjects_keep_their_morphology_between_static_and_motion() {
    let ctx = Context::shipped().unwrap();
    let s = subject(&ctx, &small(), 9, 1);
    assert_eq!(s.static_trial.n_frames(), 30);
    assert_eq!(s.motion.n_frames(), 40);
    assert_eq!(s.truth_q.len(), 40);
    let scales: Vec<usize> = (0..ctx.proxy.np()).filter(|&k| ctx.proxy.proxies[k].kind == ProxyKind::Scale).collect();
    for &k in &scales {
        let v = s.truth_proxies[0][k];
        assert!((0.9 - 1e-12..=1.1 + 1e-12).contains(&v));
        assert!(s.truth_proxies.iter().all(|p| p[k] == v));
    }
    assert!(s.motion.positions.iter().all(|v| v.is_finite()));
}

#[test]
fn stagewise_scaling_reproduces_opensims_scale_tool_on_gait2354() {
    let dir = std::path::Path::new("../shared/datasets/gait2354_subject01");
    if !dir.is_dir() {
        eprintln!("note: {} absent, skipped", dir.display());
        return;
    }
    use smocap::pipeline::calibration::subject::{prepare_subject, read_trial, SubjectFiles};
    let setup_path = dir.join("subject01_Setup_Scale.xml");
    let sub = prepare_subject(&SubjectFiles {
        model: Some(dir.join("gait2354_simbody.osim")),
        markerset: Some(dir.join("gait2354_Scale_MarkerSet.xml")),
        scale_setup: Some(setup_path.clone()),
        static_trial: Some(dir.join("subject01_static.trc")),
        ..Default::default()
    })
    .unwrap();
    let (st, _) = read_trial(&sub.ctx, sub.static_path.as_deref().unwrap(), &Default::default()).unwrap();
    let setup = smocap::io::osim::read_scale_setup(&setup_path).unwrap();
    let scale = measure(&sub.ctx, &st, &setup.measurements, &setup.manual_scales);
    // The factors OpenSim 4.6's ScaleTool applied (reference subject01_scaleSet_applied.xml).
    for (body, want) in
        [("pelvis", 1.02458), ("torso", 1.07972), ("talus_r", 1.11398), ("calcn_l", 1.02708), ("femur_r", 1.14724)]
    {
        let b = sub.ctx.model.body_index(body).unwrap();
        let got = scale.body_factors[b][0].unwrap();
        assert!((got - want).abs() < 2e-3, "{body}: {got} vs OpenSim {want}");
    }
}

/// Issue 20's synthetic acceptance: markers as a lab places them (`SubjectSpec::realistic`:
/// landmarks 10–20 mm off along the skin, wands 30–60 mm off and turned, soft-tissue motion), the
/// subjects standing with their arms at the model's neutral in the static trial (`static_arms =
/// "neutral"`, as `smocap audit` tells both methods). 40 subjects (seed 1), ~7 s in a dev build.
#[test]
fn realistic_audit_joint_solve_wins_pose_and_scale_on_nine_subjects_in_ten() {
    let mut ctx = Context::shipped().unwrap();
    ctx.static_calibration = true;
    ctx.settings.static_arms = smocap::solve::StaticArms::Neutral;
    let r = audit_synthetic(&ctx, 40, 1, &SubjectSpec::realistic());
    assert!(r.failed.is_empty(), "{:?}", r.failed);
    let pooled = |f: fn(&smocap::eval::audit::SubjectAudit) -> f64| {
        (r.subjects.iter().map(|s| f(s).powi(2)).sum::<f64>() / r.subjects.len() as f64).sqrt()
    };
    let (joint, stage) = (pooled(|s| s.joint.pose_deg), pooled(|s| s.stagewise.pose_deg));
    eprintln!(
        "realistic audit (40 subjects): joint solve wins pose {}/40, scale {}/40; all-rotational RMSE {joint:.2}° \
         (stage-wise {stage:.2}°)",
        r.wins.pose, r.wins.scale
    );
    eprint!("{}", r.breakdown.table());
    assert!(r.wins.pose >= 36, "pose wins {}/40", r.wins.pose);
    assert!(r.wins.scale >= 36, "scale wins {}/40", r.wins.scale);
    assert!(joint < stage, "all-rotational RMSE {joint:.2}° (stage-wise {stage:.2}°)");
}

/// Measurement, not a check (`cargo test --test eval_audit -- --ignored --nocapture`): the
/// realistic audit with the markers' misplacement withheld (soft tissue, noise and the static
/// posture as before), which tells how much of the angle and scale errors misplacement makes.
#[test]
#[ignore]
fn realistic_audit_errors_without_misplacement() {
    let mut ctx = Context::shipped().unwrap();
    ctx.static_calibration = true;
    ctx.settings.static_arms = smocap::solve::StaticArms::Neutral;
    let spec = SubjectSpec {
        misplace_mm: (0.0, 0.0),
        tracking_misplace_mm: Some((0.0, 0.0)),
        tracking_rotation_deg: None,
        ..SubjectSpec::realistic()
    };
    for (name, spec) in [("realistic", SubjectSpec::realistic()), ("realistic without misplacement", spec)] {
        let r = audit_synthetic(&ctx, 20, 1, &spec);
        eprintln!("== {name}\n{}{}", r.table(), r.breakdown.table());
    }
}
