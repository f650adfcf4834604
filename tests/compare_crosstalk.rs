//! Knee cross-talk in `compare`: a knee adduction that follows the flexion (a flexion axis turned
//! about the thigh) is found, its axis error estimated and turned back; on the shared Vicon trial,
//! Plug-in Gait's knees show it (docs/CALIBRATION.md, "Definition offsets against Plug-in Gait").

mod common;

use common::shared;
use smocap::eval::compare::crosstalk::{corrected, fit, knee_cross_talk, knee_pairs, CrossTalkReport};
use smocap::eval::compare::load::{load_motion, AngleMap};
use smocap::eval::compare::{Motion, Quantity, Series};

/// A gait-like knee: flexion 5–65° over a stride, a small adduction of its own (±3°, another
/// rhythm), seen about a flexion axis turned by `theta_deg` in the small-angle model:
/// `adduction' = adduction + sin θ · flexion`, `flexion' = cos θ · flexion`.
fn turned_knee(theta_deg: f64) -> (Vec<f64>, Vec<f64>) {
    let (s, c) = theta_deg.to_radians().sin_cos();
    (0..500)
        .map(|i| {
            let t = i as f64 / 100.0 * std::f64::consts::TAU; // five strides
            let flex = 35.0 - 30.0 * t.cos() + 4.0 * (2.0 * t).sin();
            let add = 3.0 * (7.0 * t + 0.3).sin();
            (c * flex, add + s * flex)
        })
        .unzip()
}

#[test]
fn a_knee_axis_turned_by_a_known_angle_is_recovered_within_half_a_degree() {
    for theta in [-20.0, -5.0, 0.0, 4.0, 12.0, 25.0] {
        let (f, a) = turned_knee(theta);
        let x = fit(&f, &a).expect("fits");
        eprintln!("turned {theta:+.1}°: r = {:.3}, slope {:.3}, axis error {:+.2}°", x.r, x.slope, x.axis_error_deg);
        assert!((x.axis_error_deg - theta).abs() < 0.5, "turned {theta}°: found {x:?}");
        if theta != 0.0 {
            assert!(x.r.signum() == theta.signum() && (theta.abs() < 10.0 || x.r.abs() > 0.8), "{theta}: {x:?}");
        }
    }
    // Turned back, the adduction no longer follows the flexion.
    let (f, a) = turned_knee(12.0);
    let m = Motion {
        source: "synthetic".into(),
        times: (0..f.len()).map(|i| i as f64 / 100.0).collect(),
        series: vec![
            Series { name: "knee_angle_r".into(), quantity: Quantity::Angle, values: f },
            Series { name: "knee_adduction_r".into(), quantity: Quantity::Angle, values: a },
        ],
        unfittable: Vec::new(),
    };
    let pairs = knee_pairs(&AngleMap::plug_in_gait());
    assert_eq!(pairs.len(), 2, "{pairs:?}");
    let found = knee_cross_talk(&m, &pairs);
    assert_eq!(found.len(), 1);
    assert!(found[0].side == "r" && found[0].r_corrected.abs() < 0.05, "{:?}", found[0]);
    let back = corrected(&m, &found);
    let again = knee_cross_talk(&back, &pairs);
    assert!(again[0].fit.axis_error_deg.abs() < 1e-9 && again[0].fit.r.abs() < 0.05, "{:?}", again[0]);
}

#[test]
fn plug_in_gait_knees_of_the_shared_vicon_trial_show_cross_talk() {
    let path = shared("datasets/vicon_plugingait_flatfoot/PiG_Motion3_FF.c3d");
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let vicon = load_motion(&path, None).expect("Vicon's angles");
    let x = CrossTalkReport::of(&vicon, &vicon, &AngleMap::plug_in_gait());
    assert_eq!(x.reference.len(), 2, "{x:?}");
    for k in &x.reference {
        eprintln!(
            "Vicon {}: knee adduction against flexion r = {:.3}, slope {:.3} °/°, axis error {:+.1}° ({} frames; r {:.3} after)",
            k.side, k.fit.r, k.fit.slope, k.fit.axis_error_deg, k.fit.frames, k.r_corrected
        );
        assert!(k.fit.r > 0.9 && k.fit.axis_error_deg > 8.0, "{k:?}");
        assert!(k.r_corrected.abs() < 0.05, "{k:?}");
    }
}
