//! Continuous angles along a trial: no output jumps by a turn between neighbouring frames from
//! wrapping alone, however the trial is cut into segments and however often the subject turns.

use smocap::io::sto::read_sto;
use smocap::io::MarkerTrial;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::pipeline::results::export::write_mot;
use smocap::pipeline::{calibrate_subject, solve_trial, Context};
use std::f64::consts::TAU;

/// Turns every frame's markers about the vertical (the model's z) through its centroid, by
/// `turns` full turns spread evenly over the trial.
fn turn_about_vertical(t: &mut MarkerTrial, turns: f64) {
    let (n, nm) = (t.n_frames(), t.n_markers());
    for f in 0..n {
        let a = turns * TAU * f as f64 / n as f64;
        let (s, c) = a.sin_cos();
        let fr = &mut t.positions[f * nm * 3..(f + 1) * nm * 3];
        let seen: Vec<&[f64]> = fr.chunks(3).filter(|p| p[0].is_finite()).collect();
        let cx = seen.iter().map(|p| p[0]).sum::<f64>() / seen.len() as f64;
        let cy = seen.iter().map(|p| p[1]).sum::<f64>() / seen.len() as f64;
        for p in fr.chunks_mut(3) {
            let (x, y) = (p[0] - cx, p[1] - cy);
            p[0] = cx + c * x - s * y;
            p[1] = cy + s * x + c * y;
        }
    }
}

#[test]
fn a_subject_turning_twice_gets_a_continuous_pelvis_rotation_in_the_mot() {
    let ctx = Context::shipped().unwrap();
    let mut s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 1000, seed: 4, ..SynthOptions::default() });
    turn_about_vertical(&mut s.trial, 2.0);
    let cal = calibrate_subject(&ctx, &[("turn", &s.trial)]).unwrap();
    // Several lanes: five segments, each cold-started (wrapping its heading into (−π, π]).
    let r = solve_trial(&ctx, "turn", &s.trial, &cal, 2).unwrap();
    let dir = std::env::temp_dir().join(format!("smocap-continuity-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mot = dir.join("turn.mot");
    write_mot(&ctx, &r, &s.trial, &mot).unwrap();
    let table = read_sto(&mot).unwrap();
    let c = table.column("pelvis_rotation").unwrap();
    let v: Vec<f64> = table.rows.iter().map(|r| r[c]).collect();
    let jump = v.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
    let range = v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min);
    eprintln!("pelvis_rotation: largest step {jump:.2}°, range {range:.1}°");
    assert!(jump < 20.0, "pelvis_rotation steps by {jump}° between neighbouring frames");
    // Two turns are about 720° of heading, not folded into one turn.
    assert!(range > 600.0, "pelvis_rotation spans {range}°");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A true flip, not a wrap: frame 20 of a walk with its right leg solved half a turn round about
/// its long axis (as a cold start can converge) is solved again from frame 19's pose by the
/// pre-solve pass ([`resolve_flips`]) and comes back to the pose the trial was solved with.
#[test]
fn a_frame_with_a_leg_half_a_turn_round_is_solved_again_from_its_neighbour() {
    use smocap::pipeline::running::lanes::{resolve_flips, FrameObservations, FrameResult};
    use smocap::pipeline::running::stream::SubjectInputs;
    let ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 40, seed: 6, ..SynthOptions::default() });
    let cal = calibrate_subject(&ctx, &[("walk", &s.trial)]).unwrap();
    let r = solve_trial(&ctx, "walk", &s.trial, &cal, 1).unwrap();
    // The trial's inputs as the streaming solve builds them.
    let pinned = ctx.pinned_to(&cal);
    let (eval, settings) = (pinned.evaluator(), &pinned.settings);
    let subject = SubjectInputs::new(&pinned, &cal);
    let m = smocap::pipeline::input::trial::match_markers(&pinned, "walk", &s.trial).unwrap();
    let inputs = subject.inputs(FrameObservations { trial: &s.trial, map: &m.columns });
    let mut results: Vec<Option<FrameResult>> =
        r.proxies.iter().zip(&r.stats).map(|(p, st)| Some((p.clone(), *st, 0.0))).collect();
    let names: Vec<&str> = pinned.proxy.proxies.iter().map(|p| p.name.as_str()).collect();
    let hip = names.iter().position(|n| n.contains("hip_rotation_r")).unwrap_or_else(|| panic!("{names:?}"));
    let (k, solved) = (20, r.proxies[20].clone());
    results[k].as_mut().unwrap().0[hip] += std::f64::consts::PI;
    // Nothing to do on the trial as solved; the flipped frame is solved again and kept.
    let mut untouched: Vec<Option<FrameResult>> =
        r.proxies.iter().zip(&r.stats).map(|(p, st)| Some((p.clone(), *st, 0.0))).collect();
    assert!(resolve_flips(&eval, settings, &inputs, &mut untouched).is_empty());
    let kept = resolve_flips(&eval, settings, &inputs, &mut results);
    assert_eq!(kept, [k]);
    let back = &results[k].as_ref().unwrap().0;
    let worst = back.iter().zip(&solved).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(worst < 0.02, "frame {k} solved again differs from the trial's solve by up to {worst:.4} (proxy units)");
}
