//! The shipped quadruped (`models/dog.xml` + `models/dog.toml`) goes through the same pipeline
//! as the human model: a synthetic trot with marker noise is calibrated and solved, and the
//! markers, joint angles and scale factors come back to the noise level.

use smocap::kinematics::synth::{periodic_gait, synthesize_with, SynthOptions};
use smocap::model::proxy::ProxyKind;
use smocap::pipeline::results::report::trial_report;
use smocap::pipeline::{calibrate_subject, solve_trial, Context};
use std::f64::consts::PI;
use std::path::Path;

fn dog() -> Context {
    Context::from_files(Path::new("models/dog.xml"), Some(Path::new("models/dog.toml"))).expect("dog loads")
}

/// Trot phases: left fore and right hind together, the other diagonal half a cycle later.
fn trot_phase(name: &str) -> Option<f64> {
    let fore = ["scapula", "shoulder", "elbow", "carpus"].iter().any(|j| name.starts_with(j));
    let hind = ["hip", "stifle", "tarsus"].iter().any(|j| name.starts_with(j));
    let left = name.ends_with("_l");
    match (fore, hind) {
        (true, _) => Some(if left { 0.0 } else { PI }),
        (_, true) => Some(if left { PI } else { 0.0 }),
        _ => None,
    }
}

#[test]
fn dog_model_has_a_coupled_spine_and_tail_and_enough_markers() {
    let ctx = dog();
    assert!(ctx.model.markers.len() >= 30, "{} markers", ctx.model.markers.len());
    for p in ["spine_flexion", "spine_bending", "spine_rotation", "tail_flexion", "tail_bending"] {
        assert!(ctx.proxy.proxy_index(p).is_some(), "proxy {p}");
    }
    // The 12 spine and 6 tail coordinates are not proxies of their own.
    for c in ["ls_flexion", "t6_t7_rotation", "tail3_bending"] {
        assert!(ctx.proxy.proxy_index(c).is_none(), "{c} should be coupled");
    }
    // Left and right limbs share their scale factors.
    assert!(ctx.proxy.proxy_index("femur").is_some() && ctx.proxy.proxy_index("femur_l").is_none());
}

#[test]
fn synthetic_trot_is_recovered_to_the_noise_level() {
    let ctx = dog();
    let noise_m = 0.002;
    let opt = SynthOptions { frames: 300, seed: 3, noise_m, speed_m_s: 2.0, ..SynthOptions::default() };
    // A 2.2 Hz trot (a Labrador's trotting stride frequency is about 2-2.5 Hz).
    let s = synthesize_with(&ctx.model, &ctx.proxy, &opt, periodic_gait(&ctx.proxy, 2.2, trot_phase));
    let cal = calibrate_subject(&ctx, &[("trot", &s.trial)]).expect("calibrates");
    let r = solve_trial(&ctx, "trot", &s.trial, &cal, 2).expect("solves");
    let rep = trial_report(&ctx, &r, Some(&s.truth));
    let rmse = rep.marker_rmse_mm.expect("rmse");
    // The truth itself leaves residuals of RMS √3·σ per marker (σ per axis): a fit that found the
    // truth's basin cannot do worse than that; 10 % for frames stopped by the decrease test.
    let noise_rms_mm = 3f64.sqrt() * noise_m * 1e3;
    let (se, pe) = (rep.scale_error_pct.expect("scale error"), rep.pose_error_deg.expect("pose error"));
    eprintln!(
        "dog trot: marker RMSE mean {:.3} mm (p90 {:.3}), joint angles {:.3}° RMSE, scales {:.3} % mean ({:.3} % max)",
        rmse.mean, rmse.p90, pe.rmse, se.mean, se.max
    );
    assert!(rmse.mean < 1.1 * noise_rms_mm, "marker RMSE mean {:.3} mm vs noise {noise_rms_mm:.3} mm", rmse.mean);
    assert!(rmse.p90 < 1.5 * noise_rms_mm, "marker RMSE p90 {:.3} mm", rmse.p90);
    // Scale factors: 2 mm noise on segments of 0.06-0.3 m, pooled over 20 calibration frames
    // with at least two markers per group, gives errors of a few tenths of a percent; 2 % is
    // several times that (a failed calibration is off by the spread of 10 %).
    assert!(se.mean < 2.0, "scale error mean {:.3} %, max {:.3} %", se.mean, se.max);
    // Joint angles: 2 mm over the shortest marker lever arms (~6 cm) is ~2°; the bound is twice.
    assert!(pe.rmse < 4.0, "joint angle RMSE {:.3}° (p90 {:.3}°)", pe.rmse, pe.p90);
    assert_eq!(s.truth.scales.len(), ctx.proxy.proxies.iter().filter(|p| p.kind == ProxyKind::Scale).count());
}
