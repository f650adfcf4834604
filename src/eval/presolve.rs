//! Pre-solve evaluation (issue 6; METHOD.md "Evaluation"): the hard synthetic set
//! ([`super::hard`]) solved with `--presolve never|auto|always`; per case and overall, the outlier
//! rate (frames whose marker RMSE exceeds the case's median **without** pre-solve by 6 MADs,
//! [`outlier_threshold`]), median and p90 marker RMSE, per-frame time and its overhead against
//! `never`.
//!
//! Trial cases go through the trial pipeline ([`solve_trial_with`], one thread, one lane, so a
//! frame's time is its own). `twisted` frames are solved one by one from their guesses with the
//! same objective as a trial frame (scales tracked to the calibration, pose prior at the guess);
//! `auto` re-solves that case's outliers from the guess with pre-solve and keeps the lower energy,
//! as the trial pass does.

use super::hard::{base, hard_set, HardCase};
use crate::kinematics::assembly::FrameProblem;
use crate::model::proxy::ProxyKind;
use crate::pipeline::input::trial::observations;
use crate::pipeline::{calibrate_subject, solve_trial_with, Context};
use crate::solve::presolve::outlier_threshold;
use crate::solve::{make_qp, Calibration, FrameSolver, FrameStats, FrameStatus, Presolve, Presolver};
use serde::Serialize;
use std::time::Instant;

/// The three modes in the order reported.
pub const MODES: [Presolve; 3] = [Presolve::Never, Presolve::Auto, Presolve::Always];

/// One case solved in one mode.
#[derive(Clone, Debug, Serialize)]
pub struct ModeResult {
    pub mode: Presolve,
    /// Frames solved (bridged frames excluded).
    pub frames: usize,
    /// Frames above the case's threshold.
    pub outliers: usize,
    pub outlier_rate_pct: f64,
    pub rmse_mm_p50: f64,
    pub rmse_mm_p90: f64,
    pub ms_per_frame_p50: f64,
    pub ms_per_frame_mean: f64,
    /// Mean time per frame over `never`'s.
    pub overhead: f64,
    /// Frames whose kept result came from the `auto` re-solve.
    pub presolved: usize,
    /// Median over frames of the largest rotation-proxy error against the truth (deg).
    pub max_angle_error_deg_p50: f64,
    #[serde(skip)]
    rmse_mm: Vec<f64>,
}

/// One case in every mode.
#[derive(Clone, Debug, Serialize)]
pub struct CaseResult {
    pub case: String,
    /// `median + 6 MAD` of the `never` RMSEs (mm).
    pub threshold_mm: f64,
    /// Median marker RMSE at the true proxies (mm): what a solve that found the truth reaches.
    pub truth_rmse_mm_p50: f64,
    pub modes: Vec<ModeResult>,
}

/// The whole evaluation.
#[derive(Clone, Debug, Serialize)]
pub struct PresolveEval {
    pub frames_per_case: usize,
    pub seed: u64,
    pub cases: Vec<CaseResult>,
    /// All cases pooled (each case keeps its own threshold).
    pub overall: Vec<ModeResult>,
}

/// Runs the evaluation on `ctx`'s model: calibrates the subject on its base motion, then solves
/// every hard case in every mode.
pub fn evaluate(ctx: &Context, frames: usize, seed: u64) -> anyhow::Result<PresolveEval> {
    let b = base(&ctx.model, &ctx.proxy, frames, seed);
    let cal = calibrate_subject(ctx, &[("base", &b.trial)])?;
    let mut cases = Vec::new();
    for case in hard_set(&ctx.model, &ctx.proxy, frames, seed) {
        let mut modes = Vec::new();
        for mode in MODES {
            let mut c = ctx.clone();
            c.settings.presolve = mode;
            modes.push(solve_case(&c, &case, &cal)?);
        }
        let threshold = outlier_threshold(&modes[0].rmse_mm);
        finish(&mut modes, threshold);
        let truth_rmse_mm_p50 = truth_rmse_mm(ctx, &case, &cal);
        cases.push(CaseResult { case: case.name.into(), threshold_mm: threshold, truth_rmse_mm_p50, modes });
    }
    let mut overall: Vec<ModeResult> = MODES
        .iter()
        .enumerate()
        .map(|(i, &mode)| {
            let all: Vec<&ModeResult> = cases.iter().map(|c| &c.modes[i]).collect();
            let mut r = summarise(mode, &[], &[], 0, &[]);
            r.frames = all.iter().map(|m| m.frames).sum();
            r.outliers = all.iter().map(|m| m.outliers).sum();
            r.outlier_rate_pct = 100.0 * r.outliers as f64 / r.frames.max(1) as f64;
            r.rmse_mm = all.iter().flat_map(|m| m.rmse_mm.iter().copied()).collect();
            r.rmse_mm_p50 = quantile(&r.rmse_mm, 0.5);
            r.rmse_mm_p90 = quantile(&r.rmse_mm, 0.9);
            r.presolved = all.iter().map(|m| m.presolved).sum();
            let total: f64 = all.iter().map(|m| m.ms_per_frame_mean * m.frames as f64).sum();
            r.ms_per_frame_mean = total / r.frames.max(1) as f64;
            r.ms_per_frame_p50 = f64::NAN;
            r.max_angle_error_deg_p50 = f64::NAN;
            r
        })
        .collect();
    let never_mean = overall[0].ms_per_frame_mean;
    for r in &mut overall {
        r.overhead = r.ms_per_frame_mean / never_mean;
    }
    Ok(PresolveEval { frames_per_case: frames, seed, cases, overall })
}

/// Solves one case in the mode of `ctx.settings.presolve`.
fn solve_case(ctx: &Context, case: &HardCase, cal: &Calibration) -> anyhow::Result<ModeResult> {
    let mode = ctx.settings.presolve;
    let (proxies, stats, seconds, presolved) = match &case.guesses {
        None => {
            let r = solve_trial_with(ctx, case.name, &case.trial, cal, 1, 1, None)?;
            (r.proxies, r.stats, r.frame_seconds, r.presolved.len())
        }
        Some(guesses) => solve_frames(ctx, case, guesses, cal),
    };
    let keep: Vec<usize> = (0..stats.len()).filter(|&f| stats[f].status != FrameStatus::TooFewMarkers).collect();
    let rmse: Vec<f64> = keep.iter().map(|&f| stats[f].rmse_m * 1e3).collect();
    let ms: Vec<f64> = keep.iter().map(|&f| seconds[f] * 1e3).collect();
    let rot: Vec<usize> = (0..ctx.proxy.np()).filter(|&k| ctx.proxy.proxies[k].kind == ProxyKind::Rotation).collect();
    let err: Vec<f64> = keep
        .iter()
        .map(|&f| {
            rot.iter()
                .map(|&k| crate::model::math::wrap_angle(proxies[f][k] - case.truth[f][k]).abs().to_degrees())
                .fold(0.0, f64::max)
        })
        .collect();
    Ok(summarise(mode, &rmse, &ms, presolved, &err))
}

/// Independent frames from their guesses: never (TR-QP), always (pre-solve, TR-QP), auto (TR-QP,
/// then the case's outliers again with pre-solve, the lower energy kept).
fn solve_frames(
    ctx: &Context,
    case: &HardCase,
    guesses: &[Vec<f64>],
    cal: &Calibration,
) -> (Vec<Vec<f64>>, Vec<FrameStats>, Vec<f64>, usize) {
    let mode = ctx.settings.presolve;
    let eval = ctx.evaluator();
    let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(ctx.settings.qp));
    let mut pre = Presolver::new(&eval, &ctx.settings, false);
    let map: Vec<Option<usize>> = (0..ctx.model.markers.len()).map(Some).collect();
    let obs = observations(&case.trial, &map);
    let stride = 3 * ctx.model.markers.len();
    let y_cal = ctx.proxy.state(&cal.proxies);
    let mut weights = vec![0.0; ctx.model.ny()];
    for t in &ctx.proxy.terms {
        let scale = ctx.proxy.proxies[t.proxy].kind == ProxyKind::Scale;
        weights[t.y_index] = if scale { ctx.settings.scale_tracking_weight } else { ctx.settings.pose_prior_weight };
    }
    let nq = ctx.model.nq();
    let start = |g: &[f64]| -> (Vec<f64>, Vec<f64>) {
        let mut p = g.to_vec();
        for (k, px) in ctx.proxy.proxies.iter().enumerate() {
            if px.kind == ProxyKind::Scale {
                p[k] = cal.proxies[k];
            }
        }
        let mut reference = y_cal.clone();
        reference[..nq].copy_from_slice(&ctx.proxy.state(&p)[..nq]);
        (p, reference)
    };
    let mut solve = |f: usize, with: bool| -> (Vec<f64>, FrameStats, f64) {
        let (mut p, reference) = start(&guesses[f]);
        let frame = FrameProblem {
            observed: &obs[f * stride..(f + 1) * stride],
            marker_weights: &ctx.marker_weights,
            tracking_ref: &reference,
            tracking_weights: &weights,
        };
        let t0 = Instant::now();
        solver.clamp(&mut p);
        if with {
            pre.run(&eval, &mut solver, &frame, &mut p);
        }
        let stats = solver.solve(&frame, &mut p);
        (p, stats, t0.elapsed().as_secs_f64())
    };
    let n = guesses.len();
    let mut out: Vec<(Vec<f64>, FrameStats, f64)> = (0..n).map(|f| solve(f, mode == Presolve::Always)).collect();
    let mut presolved = 0;
    if mode == Presolve::Auto {
        let thr = outlier_threshold(&out.iter().map(|o| o.1.rmse_m).collect::<Vec<_>>());
        for f in 0..n {
            if out[f].1.rmse_m > thr {
                let (p, stats, t) = solve(f, true);
                if stats.energy < out[f].1.energy {
                    out[f] = (p, stats, out[f].2 + t);
                    presolved += 1;
                } else {
                    out[f].2 += t;
                }
            }
        }
    }
    let mut proxies = Vec::with_capacity(n);
    let mut stats = Vec::with_capacity(n);
    let mut seconds = Vec::with_capacity(n);
    for (p, s, t) in out {
        proxies.push(p);
        stats.push(s);
        seconds.push(t);
    }
    (proxies, stats, seconds, presolved)
}

/// Median marker RMSE (mm) at the truth, scales at the calibration.
fn truth_rmse_mm(ctx: &Context, case: &HardCase, cal: &Calibration) -> f64 {
    let eval = ctx.evaluator();
    let mut ws = crate::kinematics::assembly::EvalWorkspace::new(&ctx.model, &ctx.proxy);
    let map: Vec<Option<usize>> = (0..ctx.model.markers.len()).map(Some).collect();
    let obs = observations(&case.trial, &map);
    let stride = 3 * ctx.model.markers.len();
    let none = vec![0.0; ctx.model.ny()];
    let rmse: Vec<f64> = (0..case.truth.len())
        .map(|f| {
            let mut p = case.truth[f].clone();
            for (k, px) in ctx.proxy.proxies.iter().enumerate() {
                if px.kind == ProxyKind::Scale {
                    p[k] = cal.proxies[k];
                }
            }
            let frame = FrameProblem {
                observed: &obs[f * stride..(f + 1) * stride],
                marker_weights: &ctx.marker_weights,
                tracking_ref: &none,
                tracking_weights: &none,
            };
            let (_, sq, used) = eval.energy(&p, &frame, &mut ws);
            if used > 0 {
                (sq / used as f64).sqrt() * 1e3
            } else {
                f64::NAN
            }
        })
        .collect();
    quantile(&rmse, 0.5)
}

fn summarise(mode: Presolve, rmse: &[f64], ms: &[f64], presolved: usize, err: &[f64]) -> ModeResult {
    ModeResult {
        mode,
        frames: rmse.len(),
        outliers: 0,
        outlier_rate_pct: f64::NAN,
        rmse_mm_p50: quantile(rmse, 0.5),
        rmse_mm_p90: quantile(rmse, 0.9),
        ms_per_frame_p50: quantile(ms, 0.5),
        ms_per_frame_mean: ms.iter().sum::<f64>() / ms.len().max(1) as f64,
        overhead: f64::NAN,
        presolved,
        max_angle_error_deg_p50: quantile(err, 0.5),
        rmse_mm: rmse.to_vec(),
    }
}

/// Outliers against `threshold` and overheads against the first (`never`) mode.
fn finish(modes: &mut [ModeResult], threshold: f64) {
    let never = modes[0].ms_per_frame_mean;
    for m in modes.iter_mut() {
        m.outliers = m.rmse_mm.iter().filter(|&&r| r > threshold).count();
        m.outlier_rate_pct = 100.0 * m.outliers as f64 / m.frames.max(1) as f64;
        m.overhead = m.ms_per_frame_mean / never;
    }
}

/// The `q` quantile (nearest rank on the sorted values; NaN when empty).
fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

impl PresolveEval {
    /// The table printed by `smocap eval-presolve`.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:<10} {:<7} {:>6} {:>9} {:>9} {:>9} {:>8} {:>9} {:>9} {:>8} {:>9}\n",
            "case",
            "mode",
            "frames",
            "outliers",
            "rmse p50",
            "rmse p90",
            "ms p50",
            "ms mean",
            "overhead",
            "re-solved",
            "ang p50"
        );
        let mut row = |case: &str, m: &ModeResult| {
            s.push_str(&format!(
                "{:<10} {:<7} {:>6} {:>8.2}% {:>6.2} mm {:>6.2} mm {:>8.3} {:>9.3} {:>8.2}x {:>9} {:>8.2}°\n",
                case,
                format!("{:?}", m.mode).to_lowercase(),
                m.frames,
                m.outlier_rate_pct,
                m.rmse_mm_p50,
                m.rmse_mm_p90,
                m.ms_per_frame_p50,
                m.ms_per_frame_mean,
                m.overhead,
                m.presolved,
                m.max_angle_error_deg_p50
            ));
        };
        for c in &self.cases {
            for m in &c.modes {
                row(&c.case, m);
            }
        }
        for m in &self.overall {
            row("overall", m);
        }
        s.push_str(&format!(
            "thresholds (median + 6 MAD of never, mm): {}\n",
            self.cases.iter().map(|c| format!("{} {:.2}", c.case, c.threshold_mm)).collect::<Vec<_>>().join(", ")
        ));
        s.push_str(&format!(
            "rmse at the truth p50 (mm): {}\n",
            self.cases.iter().map(|c| format!("{} {:.2}", c.case, c.truth_rmse_mm_p50)).collect::<Vec<_>>().join(", ")
        ));
        s
    }
}
