//! Unfittable frames explained (issue 32, item 2): windows of a synthetic trial in which the
//! markers of one segment are displaced (soft-tissue-like, not swapped) are reported as bad
//! data, with their markers and frames, and the trial does not fail; a clean trial reports none.

use smocap::io::MarkerTrial;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::model::CoordinateKind;
use smocap::pipeline::results::report::trial_report;
use smocap::pipeline::session::judge;
use smocap::pipeline::{calibrate_subject, solve_trial, Context};

/// Displaces the markers `names` by `by` (m) in frames `frames` of `t`.
fn displace(t: &mut MarkerTrial, names: &[&str], frames: std::ops::Range<usize>, by: [f64; 3]) {
    let nm = t.n_markers();
    for name in names {
        let m = t.labels.iter().position(|l| l == name).unwrap_or_else(|| panic!("{name} in {:?}", t.labels));
        for f in frames.clone() {
            for (x, d) in t.positions[(f * nm + m) * 3..(f * nm + m) * 3 + 3].iter_mut().zip(by) {
                *x += d;
            }
        }
    }
}

/// Windows: (markers of one segment, frames, displacement).
const WINDOWS: [(&[&str], std::ops::Range<usize>, [f64; 3]); 3] = [
    (&["RUPA", "RELB", "RMEL"], 60..66, [0.06, 0.08, -0.05]),
    (&["RTIB", "RANK", "RMMA"], 140..143, [0.07, 0.0, 0.05]),
    (&["LUPA", "LELB", "LMEL"], 220..230, [0.0, -0.1, 0.1]),
];

#[test]
fn displaced_segments_are_reported_as_bad_data_and_the_trial_does_not_fail() {
    let ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 300, seed: 11, ..SynthOptions::default() });
    let cal = calibrate_subject(&ctx, &[("walk", &s.trial)]).unwrap();
    let clean = solve_trial(&ctx, "walk", &s.trial, &cal, 1).unwrap();
    assert!(clean.marker_errors.unfittable.is_empty(), "{:?}", clean.marker_errors.unfittable);
    let mut bad = s.trial.clone();
    for (names, frames, by) in WINDOWS {
        displace(&mut bad, names, frames, by);
    }
    let r = solve_trial(&ctx, "walk", &bad, &cal, 1).unwrap();
    assert_ne!(judge(&r).status(), "failed");
    let report = trial_report(&ctx, &r, Some(&s.truth));
    assert_ne!(report.status, "failed");
    for u in &report.unfittable {
        eprintln!("{}", u.why);
    }
    // Each window is one run blamed on the data, inside the window, naming its markers.
    for (names, frames, _) in WINDOWS {
        let u = report
            .unfittable
            .iter()
            .find(|u| u.first < frames.end && u.last >= frames.start)
            .unwrap_or_else(|| panic!("window {frames:?} not reported: {:?}", report.unfittable));
        assert!(u.first >= frames.start && u.last < frames.end, "{frames:?}: {u:?}");
        assert_eq!(u.cause, "data", "{u:?}");
        assert!(u.why.starts_with("the data is bad here"), "{}", u.why);
        assert!(u.markers.iter().any(|(m, _)| names.contains(&m.as_str())), "{frames:?}: {:?}", u.markers);
    }
    assert!(report.unfittable.iter().all(|u| WINDOWS.iter().any(|w| u.first >= w.1.start && u.last < w.1.end)));
    assert!(report.reason.as_deref().is_some_and(|r| r.starts_with("the data is bad here")), "{:?}", report.reason);
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["unfittable"].as_array().map(Vec::len), Some(WINDOWS.len()));

    // Continuity (issue 32, item 1), measured: the largest step of a rotational coordinate, the
    // truth's and the solve's, and the largest difference from the clean solve outside the windows.
    let rot: Vec<usize> = (0..ctx.model.coordinates.len())
        .filter(|&j| ctx.model.coordinates[j].kind == CoordinateKind::Rotational && !ctx.proxy.y_terms[j].is_empty())
        .collect();
    let ys = |r: &smocap::pipeline::running::trial::TrialResult| -> Vec<Vec<f64>> {
        r.proxies.iter().map(|p| ctx.proxy.state(p)).collect()
    };
    let (yc, yb) = (ys(&clean), ys(&r));
    // Per coordinate, its largest step (degrees).
    let steps = |y: &[Vec<f64>]| -> Vec<f64> {
        rot.iter().map(|&j| y.windows(2).map(|w| (w[1][j] - w[0][j]).abs()).fold(0.0, f64::max).to_degrees()).collect()
    };
    let step = |y: &[Vec<f64>]| steps(y).into_iter().fold(0.0, f64::max);
    eprintln!("re-solved frames: {:?}", r.presolved);
    let names: Vec<&str> = s.truth.coordinate_names.iter().map(String::as_str).collect();
    let truth_step = s
        .truth
        .coordinates
        .windows(2)
        .flat_map(|w| {
            rot.iter()
                .filter_map(|&j| names.iter().position(|n| *n == ctx.model.coordinates[j].name))
                .map(move |t| (w[1][t] - w[0][t]).abs())
        })
        .fold(0.0, f64::max)
        .to_degrees();
    let inside = |f: usize| WINDOWS.iter().any(|w| w.1.contains(&f));
    let outside = (0..yc.len())
        .filter(|&f| !inside(f))
        .flat_map(|f| rot.iter().map(|&j| (yc[f][j] - yb[f][j]).abs()).collect::<Vec<_>>())
        .fold(0.0, f64::max)
        .to_degrees();
    eprintln!(
        "largest step: truth {truth_step:.2}°, clean solve {:.2}°, displaced solve {:.2}°; outside the windows within {outside:.3}° of the clean solve",
        step(&yc),
        step(&yb)
    );
    // No coordinate jumps by more than the truth's largest step + 10°, or, for one the clean
    // solve already moves more (forearm pronation, barely observed), than the clean solve + 10°.
    for ((&j, c), b) in rot.iter().zip(steps(&yc)).zip(steps(&yb)) {
        let name = &ctx.model.coordinates[j].name;
        assert!(
            b <= truth_step.max(c) + 10.0,
            "{name}: largest step {b:.2}° (clean solve {c:.2}°, truth {truth_step:.2}°)"
        );
        if b > truth_step + 10.0 {
            eprintln!("  {name}: largest step {b:.2}° (clean solve {c:.2}°)");
        }
    }
    assert!(outside < 1.0, "outside the windows {outside:.3}° from the clean solve");
}

/// A fast arm swing (right shoulder flexion at up to ~1,760°/s) on clean markers is followed: the
/// continuity of unfittable frames leaves frames that fit alone.
#[test]
fn a_fast_clean_arm_swing_is_followed() {
    let ctx = Context::shipped().unwrap();
    let k = ctx.proxy.proxies.iter().position(|p| p.name.contains("arm_flex_r")).expect("arm_flex_r");
    // 70° about 50° at 4 Hz: peak speed 70° · 2π · 4 Hz ≈ 1,760°/s.
    let amp = 70f64.to_radians();
    let shape = |t: f64, p: &mut [f64]| p[k] = 50f64.to_radians() + amp * (std::f64::consts::TAU * 4.0 * t).sin();
    let opt = SynthOptions { frames: 200, seed: 12, ..SynthOptions::default() };
    let s = smocap::kinematics::synth::synthesize_with(&ctx.model, &ctx.proxy, &opt, shape);
    let cal = calibrate_subject(&ctx, &[("swing", &s.trial)]).unwrap();
    let r = solve_trial(&ctx, "swing", &s.trial, &cal, 1).unwrap();
    let speed =
        s.truth.proxies.windows(2).map(|w| (w[1][k] - w[0][k]).abs()).fold(0.0, f64::max).to_degrees() * opt.rate_hz;
    let err = r.proxies.iter().zip(&s.truth.proxies).map(|(p, t)| (p[k] - t[k]).abs()).fold(0.0, f64::max).to_degrees();
    eprintln!(
        "swing: peak {speed:.0}°/s, largest error of the solved flexion {err:.2}°, unfittable {:?}",
        r.marker_errors.unfittable
    );
    assert!(speed >= 1500.0, "{speed}°/s");
    assert!(err < 5.0, "the swing is not followed: error up to {err:.2}°");
    assert!(r.marker_errors.unfittable.is_empty());
}
