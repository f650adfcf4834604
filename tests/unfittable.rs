//! Unfittable frames explained and no limb flips (issue 32, items 1 and 2): windows of a
//! synthetic trial (a walk, and a fast arm swing as the issue asks) in which the markers of one
//! segment are displaced (soft-tissue-like, not swapped) are reported as bad data, with their
//! markers and frames, the trial does not fail, no coordinate jumps (on the fast arm: by more
//! than the truth's largest step + 10° anywhere), and outside the windows the angles stay within
//! 1° of the clean solve; a clean trial reports none; a clean fast swing is followed.

use smocap::io::MarkerTrial;
use smocap::kinematics::synth::{synthesize_motion, Motion, SynthOptions};
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
    // Seed 19: a barely observed coordinate left where a window's free poses put it, until the
    // frames after a continued run were solved again from it (`jumps::carry_on`).
    for seed in 11..21 {
        displaced_segments_with(seed);
    }
}

/// The scenario: a fast arm motion (the right shoulder swinging at up to ~1,760°/s, as
/// in [`a_fast_clean_arm_swing_is_followed`]) with the same displaced windows, one of them on the
/// swinging arm itself. Seed 22: the run on the swinging arm ended 30.8° from the frame after it
/// until a run's reach also counted the steps back onto that frame; seed 24: a frame far from
/// the windows was re-solved by the `auto` pre-solve in the clean trial only (its outlier
/// threshold had counted the windows' frames) until the threshold left unfittable frames out.
#[test]
fn displaced_segments_during_a_fast_arm_swing_are_reported_and_do_not_flip() {
    for seed in 11..31 {
        displaced_segments_with_motion(seed, true);
    }
}

fn displaced_segments_with(seed: u64) {
    displaced_segments_with_motion(seed, false)
}

fn displaced_segments_with_motion(seed: u64, swing: bool) {
    eprintln!("seed {seed}{}", if swing { ", fast arm swing" } else { "" });
    let ctx = Context::shipped().unwrap();
    let opt = SynthOptions { frames: 300, seed, ..SynthOptions::default() };
    let motion = if swing { Motion::FastArm } else { Motion::Walk };
    let s = synthesize_motion(&ctx.model, &ctx.proxy, &opt, motion).unwrap();
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
    // The bound, on its scenario (a fast arm): no coordinate of the solved motion steps
    // by more than the truth's largest step + 10°, anywhere.
    if swing {
        assert!(step(&yb) <= truth_step + 10.0, "a step of {:.2}° (truth's largest {truth_step:.2}°)", step(&yb));
    }
    // On a walk the truth's largest step is 2.6–2.8°, below the clean solve's own noise in a
    // barely observed coordinate (forearm pronation steps up to 13.7° between frames that fit to
    // 3 mm; solved to convergence, the same: it is the 2 mm marker noise, not the solver), so the
    // bound is held where the continuity of unfittable frames acts, into, inside and out of a
    // window; elsewhere the frames fit and are the clean solve's (within 1°, below).
    let touches = |f: usize| inside(f) || inside(f + 1);
    for (&j, c) in rot.iter().zip(steps(&yc)) {
        let name = &ctx.model.coordinates[j].name;
        let step_at = |y: &[Vec<f64>], f: usize| (y[f + 1][j] - y[f][j]).abs().to_degrees();
        let (mut at_windows, mut elsewhere) = ((0.0f64, 0usize), 0.0f64);
        for f in 0..yb.len() - 1 {
            if touches(f) {
                if step_at(&yb, f) > at_windows.0 {
                    at_windows = (step_at(&yb, f), f);
                }
            } else {
                elsewhere = elsewhere.max(step_at(&yb, f) - step_at(&yc, f));
            }
        }
        assert!(
            at_windows.0 <= truth_step + 10.0,
            "{name}: a step of {:.2}° at frame {} of a window (truth's largest {truth_step:.2}°)",
            at_windows.0,
            at_windows.1
        );
        assert!(elsewhere < 1.0, "{name}: outside the windows a step {elsewhere:.2}° larger than the clean solve's");
        if c > truth_step + 10.0 {
            eprintln!("  {name}: the clean solve's own largest step {c:.2}°; at the windows {:.2}°", at_windows.0);
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
    // `Motion::FastArm`: 70° about 50° at 4 Hz, peak speed 70° · 2π · 4 Hz ≈ 1,760°/s.
    let opt = SynthOptions { frames: 200, seed: 12, ..SynthOptions::default() };
    let s = synthesize_motion(&ctx.model, &ctx.proxy, &opt, Motion::FastArm).unwrap();
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

/// `smocap convert` and `smocap compare` on an archive trial whose right upper arm's markers are
/// displaced for 6 frames: the summary and stderr report the run as bad data (the trial `ok`), the
/// MCAP file carries it on `/smocap/unfittable`, and `compare` lists the window, its frames
/// included in the statistics or, with `--exclude-unfittable`, left out.
#[test]
fn convert_and_compare_report_a_displaced_window() {
    use smocap::archive::config::SyntheticSpec;
    use std::process::Command;
    let dir = std::env::temp_dir().join(format!("smocap-unfittable-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let spec = SyntheticSpec { subjects: 1, trials: 1, frames: 200, seed: 11 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    let trc = dir.join("data/subj01/walk01.trc");
    let mut t = smocap::io::read_markers(&trc).unwrap();
    displace(&mut t, &["RUPA", "RELB", "RMEL"], 60..66, [0.06, 0.08, -0.05]);
    smocap::io::trc::write_trc(&trc, &t, "mm").unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(
        &toml,
        "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\nstatic = \"{subject}/static.trc\"\n",
    )
    .unwrap();
    let smocap = |args: &[&str]| Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().unwrap();
    let (out, summary) = (dir.join("out"), dir.join("summary.json"));
    let o = smocap(
        &["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--report-json"]
            .into_iter()
            .chain([summary.to_str().unwrap(), "--quiet"])
            .collect::<Vec<_>>(),
    );
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");
    eprintln!("{stdout}{stderr}");
    let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let trial = &s["trials"][0];
    assert_eq!(trial["status"], "ok", "{trial}");
    let runs = trial["unfittable"].as_array().unwrap_or_else(|| panic!("no unfittable runs: {trial}"));
    assert_eq!(runs.len(), 1, "{runs:?}");
    let (first, last) = (runs[0]["first"].as_u64().unwrap(), runs[0]["last"].as_u64().unwrap());
    assert!(first >= 60 && last < 66, "{runs:?}");
    assert_eq!(runs[0]["cause"], "data");
    assert!(trial["reason"].as_str().is_some_and(|r| r.starts_with("the data is bad here")), "{trial}");
    assert!(
        stdout.contains("unfittable frames: 1 runs in 1 trials (1 blamed on the data, 0 on the model)"),
        "{stdout}"
    );
    // The MCAP channel, read back as the readers do.
    let mcap = out.join("lab/subj01/walk01.mcap");
    let rec = smocap::archive::export::read_trial_record(&mcap).unwrap();
    let u = rec.unfittable.expect("a /smocap/unfittable message");
    assert_eq!(u.runs.len(), 1);
    assert_eq!((u.runs[0].first_frame as u64, u.runs[0].last_frame as u64), (first, last));
    assert_eq!(u.runs[0].cause, "data");
    assert!(
        u.runs[0].markers.iter().any(|m| ["RUPA", "RELB", "RMEL"].contains(&m.as_str())),
        "{:?}",
        u.runs[0].markers
    );
    assert!(u.reason.starts_with("the data is bad here"), "{}", u.reason);
    // `compare` (against itself: the statistics are zero either way) lists the window.
    let m = mcap.to_str().unwrap();
    for (extra, how) in
        [(None, "included in the statistics"), (Some("--exclude-unfittable"), "left out of the statistics")]
    {
        let o = smocap(&["compare", m, m].into_iter().chain(extra).collect::<Vec<_>>());
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let line = text.lines().find(|l| l.starts_with("unfittable frames ")).unwrap_or_else(|| panic!("{text}"));
        assert!(line.starts_with(&format!("unfittable frames {first}–{last} (")), "{line}");
        assert!(line.contains("the data is bad here: markers ") && line.contains(how), "{line}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
