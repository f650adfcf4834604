//! Pre-solve: its local Gauss–Newton models against the full assembly and finite differences,
//! recovery from twisted initial guesses, and the `never` / `auto` modes of the trial pipeline.

use smocap::kinematics::assembly::{EvalWorkspace, FrameProblem};
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::model::proxy::ProxyKind;
use smocap::pipeline::{calibrate_subject, solve_trial_with, Context};
use smocap::solve::presolve::outlier_threshold;
use smocap::solve::{make_qp, FrameSolver, Presolve, Presolver};

/// One noisy synthetic frame, its truth proxies, tracking weights and reference.
fn frame_data(ctx: &Context, seed: u64, pose_w: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 1, seed, ..SynthOptions::default() });
    let truth = s.truth.proxies[0].clone();
    let mut w = vec![0.0; ctx.model.ny()];
    for t in &ctx.proxy.terms {
        w[t.y_index] = if ctx.proxy.proxies[t.proxy].kind == ProxyKind::Scale { 1.0 } else { pose_w };
    }
    let reference = ctx.proxy.state(&truth);
    (s.trial.positions, truth, w, reference)
}

#[test]
fn local_models_are_the_subproblem_blocks_of_the_full_assembly_and_match_finite_differences() {
    let ctx = Context::shipped().unwrap();
    let eval = ctx.evaluator();
    let (obs, truth, tw, tref) = frame_data(&ctx, 3, 1e-3);
    // Away from the truth, so residuals and tracking errors are not small.
    let p: Vec<f64> = truth.iter().enumerate().map(|(k, v)| v + 0.05 * ((k as f64 * 1.7).sin())).collect();
    let mut pre = Presolver::new(&eval, &ctx.settings, true);
    assert!(pre.subproblems.len() >= 15, "{} subproblems", pre.subproblems.len());
    let mut ws = EvalWorkspace::new(&ctx.model, &ctx.proxy);
    for s in 0..pre.subproblems.len() {
        let sub = pre.subproblems[s].clone();
        let mut w = vec![0.0; ctx.model.markers.len()];
        for &m in &sub.markers {
            w[m] = ctx.marker_weights[m];
        }
        let frame = FrameProblem { observed: &obs, marker_weights: &w, tracking_ref: &tref, tracking_weights: &tw };
        let (h, g, e) = pre.local_gauss_newton(&eval, s, &frame, &p);
        eval.linearize(&p, &frame, &mut ws);
        let n = sub.proxies.len();
        let scale = ws.gn.h.amax().max(1e-12);
        for (i, &ki) in sub.proxies.iter().enumerate() {
            assert!((g[i] - ws.gn.g[ki]).abs() <= 1e-10 * ws.gn.g.amax().max(1e-12), "g, subproblem {s}");
            for (k, &kk) in sub.proxies.iter().enumerate() {
                assert!((h[i * n + k] - ws.gn.h[(ki, kk)]).abs() <= 1e-10 * scale, "H, subproblem {s}");
            }
        }
        // Central differences of the local energy.
        for (i, &k) in sub.proxies.iter().enumerate() {
            let d = 1e-6;
            let mut q = p.clone();
            q[k] += d;
            let ep = pre.local_gauss_newton(&eval, s, &frame, &q).2;
            q[k] -= 2.0 * d;
            let em = pre.local_gauss_newton(&eval, s, &frame, &q).2;
            let fd = (ep - em) / (2.0 * d);
            assert!((fd - g[i]).abs() <= 1e-5 * (1.0 + g[i].abs()), "subproblem {s} proxy {k}: fd {fd} vs g {}", g[i]);
        }
        assert!(e > 0.0);
    }
}

#[test]
fn outlier_threshold_is_median_plus_six_raw_mads() {
    // median 3, deviations 2 1 0 1 2 → MAD 1.
    assert_eq!(outlier_threshold(&[1.0, 2.0, 3.0, 4.0, 5.0, f64::NAN]), 9.0);
    assert!(outlier_threshold(&[]).is_nan());
}

#[test]
fn presolve_recovers_frames_from_twisted_initial_guesses() {
    let ctx = Context::shipped().unwrap();
    let eval = ctx.evaluator();
    let heading = ctx.proxy.proxy_index("pelvis_rotation").unwrap();
    let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(ctx.settings.qp));
    let mut pre = Presolver::new(&eval, &ctx.settings, false);
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 160, seed: 5, ..SynthOptions::default() });
    let mut tw = vec![0.0; ctx.model.ny()];
    for t in &ctx.proxy.terms {
        let scale = ctx.proxy.proxies[t.proxy].kind == ProxyKind::Scale;
        tw[t.y_index] = if scale { ctx.settings.scale_tracking_weight } else { ctx.settings.pose_prior_weight };
    }
    let stride = 3 * ctx.model.markers.len();
    let (mut plain_ok, mut pre_ok, mut n) = (0, 0, 0);
    let (mut plain_sum, mut pre_sum) = (0.0, 0.0);
    for f in (0..160).step_by(10) {
        let truth = &s.truth.proxies[f];
        // Facing the other way, left and right limbs swapped.
        let mut guess = truth.clone();
        guess[heading] += 3.0;
        for (k, px) in ctx.proxy.proxies.iter().enumerate() {
            if let Some(l) = px.name.strip_suffix("_r").and_then(|st| ctx.proxy.proxy_index(&format!("{st}_l"))) {
                if px.kind != ProxyKind::Scale {
                    guess.swap(k, l);
                }
            }
        }
        solver.clamp(&mut guess);
        let reference = ctx.proxy.state(&guess);
        let frame = FrameProblem {
            observed: &s.trial.positions[f * stride..(f + 1) * stride],
            marker_weights: &ctx.marker_weights,
            tracking_ref: &reference,
            tracking_weights: &tw,
        };
        let mut plain = guess.clone();
        let a = solver.solve(&frame, &mut plain);
        let mut with = guess.clone();
        pre.run(&eval, &mut solver, &frame, &mut with);
        let b = solver.solve(&frame, &mut with);
        eprintln!("frame {f}: rmse plain {:.1} mm, with pre-solve {:.1} mm", a.rmse_m * 1e3, b.rmse_m * 1e3);
        plain_sum += a.energy;
        pre_sum += b.energy;
        plain_ok += usize::from(a.rmse_m < 0.005);
        pre_ok += usize::from(b.rmse_m < 0.005);
        n += 1;
    }
    eprintln!("recovered: plain {plain_ok}/{n}, with pre-solve {pre_ok}/{n}");
    assert!(plain_ok < n, "no frame lands in a wrong basin without pre-solve: not a test of it");
    assert!(pre_ok >= n - 1, "pre-solve recovered {pre_ok} of {n}");
    assert!(pre_ok >= plain_ok && pre_sum <= plain_sum * (1.0 + 1e-9), "energy {pre_sum} vs plain {plain_sum}");
}

#[test]
fn never_leaves_the_trial_solve_unchanged_and_auto_changes_only_the_frames_it_resolves() {
    let mut ctx = Context::shipped().unwrap();
    let s = synthesize(
        &ctx.model,
        &ctx.proxy,
        &SynthOptions { frames: 150, seed: 21, dropout: 0.05, ..SynthOptions::default() },
    );
    let cal = calibrate_subject(&ctx, &[("t", &s.trial)]).unwrap();
    ctx.settings.presolve = Presolve::Never;
    let never = solve_trial_with(&ctx, "t", &s.trial, &cal, 1, 1, None).unwrap();
    let again = solve_trial_with(&ctx, "t", &s.trial, &cal, 1, 1, None).unwrap();
    assert!(never.presolved.is_empty());
    assert_eq!(never.proxies, again.proxies, "never is deterministic");
    ctx.settings.presolve = Presolve::Auto;
    let auto = solve_trial_with(&ctx, "t", &s.trial, &cal, 1, 1, None).unwrap();
    for f in 0..never.proxies.len() {
        if auto.presolved.contains(&f) {
            assert!(auto.stats[f].energy < never.stats[f].energy, "frame {f} kept without a lower energy");
        } else {
            assert_eq!(auto.proxies[f], never.proxies[f], "frame {f} changed without being re-solved");
        }
    }
}
