//! `smocap demo`: the whole path on the embedded default (shipped model, synthetic trial).

use crate::kinematics::synth::{synthesize, SynthOptions};
use crate::pipeline::results::report::{trial_report, Report};
use crate::pipeline::{calibrate_subject, solve_trial_with, Context};
use clap::Args;

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Frames to synthesize.
    #[arg(long, default_value_t = 2000)]
    pub frames: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Marker noise (mm).
    #[arg(long, default_value_t = 2.0)]
    pub noise_mm: f64,
    /// Worker threads.
    #[arg(long)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub backend: super::BackendArgs,
}

pub fn run(a: DemoArgs) -> anyhow::Result<u8> {
    let ctx = Context::shipped()?;
    let threads = a.threads.unwrap_or_else(super::default_threads).max(1);
    let (mut chosen, lanes) = a.backend.choose(&ctx, threads)?;
    let opt = SynthOptions { frames: a.frames, seed: a.seed, noise_m: a.noise_mm * 1e-3, ..SynthOptions::default() };
    println!(
        "smocap demo: shipped model '{}' ({} coordinates, {} bodies, {} markers, {} proxies), {} synthetic frames at {} Hz, {} mm noise, seed {}",
        ctx.model.name,
        ctx.model.nq(),
        ctx.model.nb(),
        ctx.model.markers.len(),
        ctx.proxy.np(),
        opt.frames,
        opt.rate_hz,
        a.noise_mm,
        a.seed
    );
    let s = synthesize(&ctx.model, &ctx.proxy, &opt);
    let t0 = std::time::Instant::now();
    let cal = calibrate_subject(&ctx, &[("demo", &s.trial)])?;
    println!(
        "calibrated on {} frames in {:.1} ms (marker RMSE {:.2} mm)",
        cal.frames,
        t0.elapsed().as_secs_f64() * 1e3,
        cal.rmse_m * 1e3
    );
    let r = solve_trial_with(&ctx, "demo", &s.trial, &cal, threads, lanes, chosen.backend())?;
    let mut report = Report::new(&ctx, threads);
    report.set_backend(&chosen, lanes);
    report.push(trial_report(&ctx, &r, Some(&s.truth)));
    print!("{}", report.table());
    let t = &report.trials[0];
    if let (Some(pe), Some(se)) = (t.pose_error_deg, t.scale_error_pct) {
        println!(
            "against the truth: joint angle RMSE {:.3}° (p90 {:.3}°), scale error mean {:.3} % (max {:.3} %)",
            pe.rmse, pe.p90, se.mean, se.max
        );
    }
    println!(
        "{} threads, {} lanes, backend {} ({}); {:.0} frames/s wall",
        threads, lanes, report.backend, report.device, report.totals.frames_per_s
    );
    Ok(0)
}
