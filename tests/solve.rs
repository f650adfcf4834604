//! The trust-region solver and the trial driver on synthetic ground truth from the shipped model.

use smocap::kinematics::assembly::FrameProblem;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::pipeline::results::report::trial_report;
use smocap::pipeline::{calibrate_subject, solve_trial, Context};
use smocap::solve::{init::cold_start, make_qp, FrameSolver, FrameStatus, QpBackend};

fn run(opt: SynthOptions) -> smocap::pipeline::results::report::TrialReport {
    let ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &opt);
    let cal = calibrate_subject(&ctx, &[("t", &s.trial)]).unwrap();
    let r = solve_trial(&ctx, "t", &s.trial, &cal, 2).unwrap();
    trial_report(&ctx, &r, Some(&s.truth))
}

#[test]
fn noise_free_trial_recovers_joint_angles_and_scales_exactly() {
    let rep = run(SynthOptions { frames: 120, seed: 11, noise_m: 0.0, ..SynthOptions::default() });
    let (pe, se) = (rep.pose_error_deg.unwrap(), rep.scale_error_pct.unwrap());
    eprintln!(
        "noise-free: pose rmse {:.4}° p90 {:.4}°, scale mean {:.4} % max {:.4} %, it p50 {:?}",
        pe.rmse, pe.p90, se.mean, se.max, rep.iterations
    );
    assert!(pe.rmse <= 0.05, "pose RMSE {}°", pe.rmse);
    assert!(se.mean <= 0.05, "scale error {} %", se.mean);
}

#[test]
fn two_millimetre_noise_keeps_joint_angles_within_a_degree_and_scales_within_a_percent() {
    for seed in [12, 13, 14, 15] {
        let rep = run(SynthOptions { frames: 300, seed, noise_m: 0.002, ..SynthOptions::default() });
        let (pe, se) = (rep.pose_error_deg.unwrap(), rep.scale_error_pct.unwrap());
        let rmse = rep.marker_rmse_mm.unwrap();
        eprintln!("2 mm, seed {seed}: pose rmse {:.3}° p90 {:.3}°, scale mean {:.3} % max {:.3} %, marker rmse p50 {:.2} mm, it {:?}", pe.rmse, pe.p90, se.mean, se.max, rmse.p50, rep.iterations);
        assert!(pe.rmse <= 1.0, "seed {seed}: pose RMSE {}°", pe.rmse);
        assert!(se.mean <= 1.0, "seed {seed}: scale error {} %", se.mean);
        // Residual close to the noise level: sqrt(3) · 2 mm per marker.
        assert!(rmse.p50 < 4.5, "seed {seed}: marker RMSE {} mm", rmse.p50);
    }
}

#[test]
fn frames_without_markers_are_reported_and_bridged_while_the_rest_solve() {
    let ctx = Context::shipped().unwrap();
    let mut s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 60, seed: 4, ..SynthOptions::default() });
    let nm = s.trial.n_markers();
    for f in [0usize, 30, 31] {
        for v in &mut s.trial.positions[f * nm * 3..(f + 1) * nm * 3] {
            *v = f64::NAN;
        }
    }
    let cal = calibrate_subject(&ctx, &[("t", &s.trial)]).unwrap();
    let r = solve_trial(&ctx, "t", &s.trial, &cal, 1).unwrap();
    assert_eq!(r.bridged, vec![0, 30, 31]);
    let rep = trial_report(&ctx, &r, Some(&s.truth));
    assert_eq!(rep.frames, 60);
    assert!(rep.pose_error_deg.unwrap().rmse < 2.0);
    // Bridged frames lie between their neighbours.
    let k = 0;
    let (a, b, m) = (r.proxies[29][k], r.proxies[32][k], r.proxies[30][k]);
    assert!((m - a).abs() <= (b - a).abs() + 1e-12);
}

#[test]
fn box_qp_and_clarabel_backends_reach_the_same_frame_solution() {
    let ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 5, seed: 9, ..SynthOptions::default() });
    let eval = ctx.evaluator();
    let stride = 3 * ctx.model.markers.len();
    let zeros = vec![0.0; ctx.model.ny()];
    let frame = FrameProblem {
        observed: &s.trial.positions[2 * stride..3 * stride],
        marker_weights: &ctx.marker_weights,
        tracking_ref: &zeros,
        tracking_weights: &zeros,
    };
    let mut out = Vec::new();
    for qp in [QpBackend::Boxqp, QpBackend::Clarabel] {
        let mut settings = ctx.settings.clone();
        settings.rel_decrease_tol = 1e-12;
        settings.max_iterations = 60;
        let mut solver = FrameSolver::new(&eval, settings, make_qp(qp));
        let mut p = ctx.proxy.default_proxies();
        cold_start(&mut solver, &frame, &mut p);
        let st = solver.solve(&frame, &mut p);
        assert_ne!(st.status, FrameStatus::QpFailed);
        out.push((st.energy, p));
    }
    let (e0, e1) = (out[0].0, out[1].0);
    assert!((e0 - e1).abs() <= 1e-6 * e0.max(1e-12), "energies {e0} vs {e1}");
    for (a, b) in out[0].1.iter().zip(&out[1].1) {
        assert!((a - b).abs() < 1e-3, "{a} vs {b}");
    }
}

#[test]
fn cold_start_finds_a_subject_facing_backwards() {
    let ctx = Context::shipped().unwrap();
    let s = synthesize(
        &ctx.model,
        &ctx.proxy,
        &SynthOptions { frames: 3, seed: 21, noise_m: 0.0, ..SynthOptions::default() },
    );
    let eval = ctx.evaluator();
    let stride = 3 * ctx.model.markers.len();
    // Rotate the observed markers by 180° about the vertical (z) axis.
    let mut obs = s.trial.positions[..stride].to_vec();
    for c in obs.chunks_mut(3) {
        c[0] = -c[0];
        c[1] = -c[1];
    }
    let y_truth = ctx.proxy.state(&s.truth.proxies[0]);
    let frame = FrameProblem {
        observed: &obs,
        marker_weights: &ctx.marker_weights,
        tracking_ref: &y_truth,
        tracking_weights: &vec![0.0; ctx.model.ny()],
    };
    let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(QpBackend::Boxqp));
    let mut p = ctx.proxy.default_proxies();
    for (k, px) in ctx.proxy.proxies.iter().enumerate() {
        if px.kind == smocap::model::proxy::ProxyKind::Scale {
            p[k] = s.truth.proxies[0][k];
        }
    }
    cold_start(&mut solver, &frame, &mut p);
    let st = solver.solve(&frame, &mut p);
    assert!(st.rmse_m < 1e-3, "RMSE {} m after a cold start", st.rmse_m);
}

#[test]
fn scale_symmetry_constraint_holds_in_calibration_and_in_every_frame() {
    use smocap::model::profile::Profile;
    use smocap::pipeline::context::{SHIPPED_MODEL, SHIPPED_PROFILE};
    let text = format!(
        "{SHIPPED_PROFILE}\n[[constraint]]\nproxies = {{ femur_r = 1.0, femur_l = -1.0 }}\nmin = -0.01\nmax = 0.01\n"
    );
    let profile = Profile::parse(&text, std::path::Path::new("sym.toml")).unwrap();
    let model = smocap::io::mjcf::parse_mjcf(SHIPPED_MODEL, "fullbody.xml").unwrap();
    let ctx = Context::new(model, profile, "sym.toml", "test".into()).unwrap();
    assert_eq!(ctx.settings.qp, QpBackend::Clarabel, "constraints need clarabel");
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 30, seed: 8, ..SynthOptions::default() });
    let (r, l) = (ctx.proxy.proxy_index("femur_r").unwrap(), ctx.proxy.proxy_index("femur_l").unwrap());
    let truth_gap = (s.truth.proxies[0][r] - s.truth.proxies[0][l]).abs();
    let cal = calibrate_subject(&ctx, &[("t", &s.trial)]).unwrap();
    let gap = cal.proxies[r] - cal.proxies[l];
    eprintln!("truth gap {truth_gap:.4}, calibrated gap {gap:.4}");
    assert!(gap.abs() <= 0.01 + 1e-6, "calibrated femur gap {gap}");
    let res = solve_trial(&ctx, "t", &s.trial, &cal, 1).unwrap();
    for p in &res.proxies {
        assert!((p[r] - p[l]).abs() <= 0.01 + 1e-6, "frame gap {}", p[r] - p[l]);
    }
}

#[test]
fn a_constraint_naming_an_unknown_proxy_is_an_error_listing_the_proxies() {
    use smocap::model::profile::Profile;
    use smocap::model::proxy::ProxyMap;
    let ctx = Context::shipped().unwrap();
    let text = "[[constraint]]\nproxies = { femur_x = 1.0 }\nmax = 0.1\n";
    let mut profile = Profile::parse(text, std::path::Path::new("c.toml")).unwrap();
    profile.scale_groups = ctx.profile.scale_groups.clone();
    let err = ProxyMap::new(&ctx.model, &profile).unwrap_err().to_string();
    assert!(err.contains("femur_x") && err.contains("femur_r"), "{err}");
}

#[test]
fn a_frame_far_from_its_warm_start_is_not_declared_converged_by_a_box_limited_step() {
    // The subject moved 1 m further than the warm start says (a long gap): the translation step
    // is cut by the 0.25 m step box while the model is exact along it.
    let ctx = Context::shipped().unwrap();
    let s = synthesize(
        &ctx.model,
        &ctx.proxy,
        &SynthOptions { frames: 3, seed: 5, noise_m: 0.0, ..SynthOptions::default() },
    );
    let eval = ctx.evaluator();
    let stride = 3 * ctx.model.markers.len();
    let zeros = vec![0.0; ctx.model.ny()];
    let frame = FrameProblem {
        observed: &s.trial.positions[..stride],
        marker_weights: &ctx.marker_weights,
        tracking_ref: &zeros,
        tracking_weights: &zeros,
    };
    let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(QpBackend::Boxqp));
    let mut p = s.truth.proxies[0].clone();
    p[ctx.proxy.proxy_index("pelvis_tx").unwrap()] -= 1.0;
    let st = solver.solve(&frame, &mut p);
    assert!(st.rmse_m < 1e-3, "RMSE {} m, status {:?}, {} iterations", st.rmse_m, st.status, st.iterations);
}

#[path = "common/mod.rs"]
mod common;

#[test]
fn marker_placement_moves_free_markers_onto_their_observations_and_keeps_fixed_ones() {
    use rand::RngExt;
    use smocap::kinematics::cpu::{forward, Workspace};
    use smocap::model::profile::Profile;
    use smocap::model::proxy::ProxyMap;
    let model = common::random_model(11, 6);
    let proxy = ProxyMap::new(&model, &Profile::default_for(&model)).expect("proxy map");
    let mut r = common::rng(5);
    // Where the markers really are: each moved by up to 3 cm in its body frame.
    let mut real = model.clone();
    for m in &mut real.markers {
        m.offset += nalgebra::Vector3::from_fn(|_, _| r.random_range(-0.03..0.03));
    }
    let movable: Vec<bool> = (0..model.markers.len()).map(|m| m % 3 != 0).collect();
    let (mut frames, mut poses) = (Vec::new(), Vec::new());
    let mut ws = Workspace::new(&real);
    for _ in 0..4 {
        let p: Vec<f64> = proxy
            .proxies
            .iter()
            .map(|px| {
                let (lo, hi) = (px.range.0.max(-1.0), px.range.1.min(1.2));
                r.random_range(lo..hi)
            })
            .collect();
        forward(&real, &proxy.state(&p), &mut ws);
        frames.push(ws.markers.clone());
        poses.push(p);
    }
    let slices: Vec<&[f64]> = frames.iter().map(|f| f.as_slice()).collect();
    let placed = smocap::solve::placement::place_markers(&model, &proxy, &slices, &poses, &movable);
    for (m, p) in placed.iter().enumerate() {
        match p {
            Some(o) => {
                assert!(movable[m]);
                assert!(
                    (o - real.markers[m].offset).norm() < 1e-9,
                    "marker {m} placed at {o} not {}",
                    real.markers[m].offset
                );
            }
            None => assert!(!movable[m], "movable marker {m} observed in every frame was not placed"),
        }
    }
}

/// The per-frame loop that the lane scheduler replaced: one segment, warm-started frame by frame.
fn plain_loop(ctx: &Context, obs: &[f64], cal: &smocap::solve::Calibration) -> Vec<Vec<f64>> {
    use smocap::model::proxy::ProxyKind;
    let eval = ctx.evaluator();
    let (ny, nq, stride) = (ctx.model.ny(), ctx.model.nq(), 3 * ctx.model.markers.len());
    let mut reference = ctx.proxy.state(&cal.proxies);
    let mut tw = vec![0.0; ny];
    for t in &ctx.proxy.terms {
        let scale = ctx.proxy.proxies[t.proxy].kind == ProxyKind::Scale;
        tw[t.y_index] = if scale { ctx.settings.scale_tracking_weight } else { ctx.settings.pose_prior_weight };
    }
    let mut neutral = ctx.proxy.default_proxies();
    for (k, px) in ctx.proxy.proxies.iter().enumerate() {
        if px.kind == ProxyKind::Scale {
            neutral[k] = cal.proxies[k];
        }
    }
    let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(ctx.settings.qp));
    let mut prev: Option<Vec<f64>> = None;
    let mut out = Vec::new();
    for o in obs.chunks(stride) {
        let mut p = prev.clone().unwrap_or_else(|| neutral.clone());
        solver.clamp(&mut p);
        let y = ctx.proxy.state(&p);
        reference[..nq].copy_from_slice(&y[..nq]);
        let frame = FrameProblem {
            observed: o,
            marker_weights: &ctx.marker_weights,
            tracking_ref: &reference,
            tracking_weights: &tw,
        };
        if prev.is_none() {
            smocap::solve::init::multi_start(&mut solver, &frame, &mut p, &cal.proxies);
        }
        if solver.solve(&frame, &mut p).status != FrameStatus::TooFewMarkers {
            prev = Some(p.clone());
        }
        out.push(p);
    }
    out
}

#[test]
fn the_lane_scheduler_on_the_cpu_takes_exactly_the_steps_of_the_per_frame_loop() {
    let ctx = Context::shipped().unwrap();
    let mut s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 150, seed: 21, ..SynthOptions::default() });
    let nm = s.trial.n_markers();
    for v in &mut s.trial.positions[40 * nm * 3..41 * nm * 3] {
        *v = f64::NAN; // a frame with too few markers in the middle
    }
    let cal = calibrate_subject(&ctx, &[("t", &s.trial)]).unwrap();
    let matched = smocap::pipeline::input::trial::match_markers(&ctx, "t", &s.trial).unwrap();
    let obs = smocap::pipeline::input::trial::observations(&s.trial, &matched.columns);
    // Trials are solved at the calibrated morphology: the plain loop gets the same pinned scales.
    let plain = plain_loop(&ctx.pinned_to(&cal), &obs, &cal);
    // One lane (one segment): bit-identical, bridged frame aside.
    let r = solve_trial(&ctx, "t", &s.trial, &cal, 1).unwrap();
    for f in (0..150).filter(|&f| f != 40) {
        assert_eq!(r.proxies[f], plain[f], "frame {f}");
    }
}

#[test]
fn a_foot_whose_markers_all_drop_out_is_bridged_between_the_frames_that_see_it() {
    let ctx = Context::shipped().unwrap();
    let mut s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 80, seed: 7, ..SynthOptions::default() });
    let nm = s.trial.n_markers();
    // Every marker below the right ankle (on the talus, calcaneus or toes) gone in frames 40–42.
    let ankle = ctx.model.coordinate_index("ankle_angle_r").expect("ankle");
    let talus = ctx.model.bodies.iter().position(|b| b.name == "talus_r").expect("talus");
    let foot: Vec<usize> = (0..nm)
        .filter(|&c| {
            let label = &s.trial.labels[c];
            ctx.model.markers.iter().any(|m| &m.name == label && ctx.model.is_ancestor(talus, m.body))
        })
        .collect();
    assert!(foot.len() >= 3, "{foot:?}");
    for f in 40..43 {
        for &c in &foot {
            s.trial.positions[(f * nm + c) * 3..(f * nm + c + 1) * 3].fill(f64::NAN);
        }
    }
    let cal = calibrate_subject(&ctx, &[("t", &s.trial)]).unwrap();
    let r = solve_trial(&ctx, "t", &s.trial, &cal, 1).unwrap();
    assert!(r.bridged.is_empty(), "the frames themselves are solved: {:?}", r.bridged);
    let q = |f: usize| ctx.proxy.state(&r.proxies[f])[ankle];
    // Not held at frame 39's angle: on the line from frame 39 to frame 43.
    for f in 40..43 {
        let w = (f - 39) as f64 / 4.0;
        let line = q(39) + w * (q(43) - q(39));
        assert!((q(f) - line).abs() < 1e-9, "frame {f}: {} against {line}", q(f));
    }
    // The knee, which the shank's markers still see, is solved, not interpolated.
    let knee = ctx.model.coordinate_index("knee_angle_r").expect("knee");
    let k = |f: usize| ctx.proxy.state(&r.proxies[f])[knee];
    let truth = |f: usize| s.truth.coordinates[f][knee];
    assert!((k(41) - truth(41)).abs().to_degrees() < 2.0, "{} against {}", k(41), truth(41));
}
