//! Continuous angles along a trial: no output jumps by a turn between neighbouring frames from
//! wrapping alone, however the trial is cut into segments and however often the subject turns.

use smocap::io::sto::read_sto;
use smocap::io::MarkerTrial;
use smocap::pipeline::export::write_mot;
use smocap::pipeline::{calibrate_subject, solve_trial, Context};
use smocap::synth::{synthesize, SynthOptions};
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
