//! Cold starts (`solve::init::multi_start`) on frames without a previous solution: every 10th
//! frame of the base motion and of each hard case (pirouettes, extreme poses, dropout, twisted),
//! solved from the neutral pose at the calibrated morphology as a segment's first frame is.

use smocap::eval::hard::{base, hard_set};
use smocap::kinematics::assembly::FrameProblem;
use smocap::model::math::wrap_angle;
use smocap::model::proxy::ProxyKind;
use smocap::pipeline::input::trial::observations;
use smocap::pipeline::{calibrate_subject, Context};
use smocap::solve::init::multi_start;
use smocap::solve::{make_qp, FrameSolver, FrameStatus};
use std::time::Instant;

/// Per frame: marker RMSE (mm) and largest rotation error against the truth (deg).
struct Solved {
    rmse_mm: Vec<f64>,
    angle_deg: Vec<f64>,
    seconds: f64,
}

fn cold_start_all(ctx: &Context, every: usize) -> Vec<(String, Solved)> {
    let frames = 600;
    let b = base(&ctx.model, &ctx.proxy, frames, 1);
    let cal = calibrate_subject(ctx, &[("base", &b.trial)]).unwrap();
    let pinned = ctx.pinned_to(&cal);
    let eval = pinned.evaluator();
    let mut solver = FrameSolver::new(&eval, pinned.settings.clone(), make_qp(pinned.settings.qp));
    let nq = ctx.model.nq();
    let y_cal = ctx.proxy.state(&cal.proxies);
    let mut weights = vec![0.0; ctx.model.ny()];
    for t in &ctx.proxy.terms {
        let scale = ctx.proxy.proxies[t.proxy].kind == ProxyKind::Scale;
        weights[t.y_index] = if scale { ctx.settings.scale_tracking_weight } else { ctx.settings.pose_prior_weight };
    }
    let mut neutral = ctx.proxy.default_proxies();
    for (k, px) in ctx.proxy.proxies.iter().enumerate() {
        if px.kind == ProxyKind::Scale {
            neutral[k] = cal.proxies[k];
        }
    }
    let rot: Vec<usize> = (0..ctx.proxy.np()).filter(|&k| ctx.proxy.proxies[k].kind == ProxyKind::Rotation).collect();
    let map: Vec<Option<usize>> = (0..ctx.model.markers.len()).map(Some).collect();
    let stride = 3 * ctx.model.markers.len();
    let mut cases = vec![("base".to_string(), b.trial.clone(), b.truth.proxies.clone())];
    for c in hard_set(&ctx.model, &ctx.proxy, frames, 1) {
        cases.push((c.name.to_string(), c.trial, c.truth));
    }
    let mut out = Vec::new();
    for (name, trial, truth) in cases {
        let obs = observations(&trial, &map);
        let mut s = Solved { rmse_mm: Vec::new(), angle_deg: Vec::new(), seconds: 0.0 };
        for f in (0..truth.len()).step_by(every) {
            let mut p = neutral.clone();
            solver.clamp(&mut p);
            let mut reference = y_cal.clone();
            reference[..nq].copy_from_slice(&ctx.proxy.state(&p)[..nq]);
            let frame = FrameProblem {
                observed: &obs[f * stride..(f + 1) * stride],
                marker_weights: &ctx.marker_weights,
                tracking_ref: &reference,
                tracking_weights: &weights,
            };
            let t0 = Instant::now();
            multi_start(&mut solver, &frame, &mut p, &cal.proxies);
            let st = solver.solve(&frame, &mut p);
            s.seconds += t0.elapsed().as_secs_f64();
            if st.status == FrameStatus::TooFewMarkers {
                continue;
            }
            s.rmse_mm.push(st.rmse_m * 1e3);
            s.angle_deg
                .push(rot.iter().map(|&k| wrap_angle(p[k] - truth[f][k]).abs().to_degrees()).fold(0.0, f64::max));
        }
        out.push((name, s));
    }
    out
}

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn cold_starts_find_the_pose_of_frames_without_a_previous_solution() {
    let ctx = Context::shipped().unwrap();
    let every = std::env::var("COLD_START_EVERY").ok().and_then(|v| v.parse().ok()).unwrap_or(10);
    let all = cold_start_all(&ctx, every);
    let mut good = 0;
    let mut total = 0;
    for (name, s) in &all {
        let ok = s.rmse_mm.iter().filter(|&&r| r < 5.0).count();
        println!(
            "{name:10} frames {:3}  rmse < 5 mm {:3}  rmse mean {:.3} p50/p90/max {:.2}/{:.2}/{:.2} mm  angle p50/p90 {:.2}/{:.2}°  {:.3} ms per start",
            s.rmse_mm.len(),
            ok,
            s.rmse_mm.iter().sum::<f64>() / s.rmse_mm.len() as f64,
            quantile(&s.rmse_mm, 0.5),
            quantile(&s.rmse_mm, 0.9),
            quantile(&s.rmse_mm, 1.0),
            quantile(&s.angle_deg, 0.5),
            quantile(&s.angle_deg, 0.9),
            1e3 * s.seconds / s.rmse_mm.len() as f64
        );
        if *name != "extreme" {
            good += ok;
            total += s.rmse_mm.len();
        }
    }
    assert!(good * 100 >= total * 95, "{good} of {total} cold starts within 5 mm");
}
