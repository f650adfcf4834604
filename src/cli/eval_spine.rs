//! `smocap eval-spine`: the spine ablation (poly / nopoly / classical) on the shipped model.

use crate::eval::spine::{acceptance, run, SpineOptions, AXES};
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct EvalSpineArgs {
    /// Frames of the synthetic yoga-like trial (100 Hz).
    #[arg(long, default_value_t = 2000)]
    pub frames: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Marker noise, standard deviation per axis (mm).
    #[arg(long, default_value_t = 2.0)]
    pub noise_mm: f64,
    /// Each level's deviation from its coupling share in the truth, as a fraction of the share.
    #[arg(long, default_value_t = 0.3)]
    pub deviation: f64,
    /// The level left free in the classical variant.
    #[arg(long, default_value = "L3_L4")]
    pub classical_level: String,
    /// Solves of each variant (round-robin) pooled for ms/frame.
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Write the JSON report here.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
}

pub fn run_cli(a: EvalSpineArgs) -> anyhow::Result<u8> {
    anyhow::ensure!(a.frames >= 3, "--frames must be at least 3 (second differences), got {}", a.frames);
    anyhow::ensure!(a.noise_mm.is_finite() && a.noise_mm >= 0.0, "--noise-mm must be finite and ≥ 0");
    anyhow::ensure!((0.0..1.0).contains(&a.deviation), "--deviation must be in [0, 1), got {}", a.deviation);
    let opt = SpineOptions {
        frames: a.frames,
        seed: a.seed,
        noise_m: a.noise_mm * 1e-3,
        deviation: a.deviation,
        classical_level: a.classical_level.clone(),
        repeats: a.repeats.max(1),
        ..SpineOptions::default()
    };
    println!(
        "spine ablation: shipped model, {} yoga-like frames at {} Hz, {} mm noise, level deviation ±{:.0} %, seed {}, classical joint at {}; one thread, {} solves per variant",
        opt.frames,
        opt.rate_hz,
        a.noise_mm,
        opt.deviation * 100.0,
        opt.seed,
        opt.classical_level,
        opt.repeats
    );
    let r = run(&opt)?;
    println!(
        "{:<10} {:>6} {:>6} {:>9} {:>9} {:>8} {:>6} {:>9} {:>9} {:>10} {:>10}",
        "variant",
        "pose",
        "spine",
        "RMSE mm",
        "ms p50",
        "ms p90",
        "it p50",
        "spine°",
        "temporal",
        "spatial",
        "scale err"
    );
    let row = |name: &str| format!("{name:<10}");
    for v in &r.variants {
        println!(
            "{} {:>6} {:>6} {:>9.3} {:>9.3} {:>8.3} {:>6.0} {:>9.3} {:>9.5} {:>10.5} {:>9.2}%",
            row(v.variant.name()),
            v.pose_proxies,
            v.spine_proxies,
            v.marker_rmse_mm.mean,
            v.ms_per_frame.p50,
            v.ms_per_frame.p90,
            v.iterations.p50,
            v.spine_error_deg,
            v.roughness.temporal_axis_deg2.iter().sum::<f64>() / 3.0,
            v.roughness.spatial_deg2,
            v.scale_error_pct.map_or(f64::NAN, |s| s.mean)
        );
    }
    println!(
        "{} {:>6} {:>6} {:>9} {:>9} {:>8} {:>6} {:>9} {:>9.5} {:>10.5}",
        row("truth"),
        "",
        "",
        "",
        "",
        "",
        "",
        "",
        r.truth.temporal_axis_deg2.iter().sum::<f64>() / 3.0,
        r.truth.spatial_deg2
    );
    println!(
        "per axis ({}): spatial roughness deg², temporal roughness deg²/frame², total-angle error deg",
        AXES.join(", ")
    );
    for v in &r.variants {
        let f = |x: [f64; 3], p: usize| x.map(|v| format!("{v:.p$}")).join(" / ");
        println!(
            "  {:<10} spatial {}   temporal {}   total angle {}",
            v.variant.name(),
            f(v.roughness.spatial_axis_deg2, 4),
            f(v.roughness.temporal_axis_deg2, 5),
            f(v.total_angle_error_deg, 2)
        );
    }
    println!(
        "  {:<10} spatial {}   temporal {}",
        "truth",
        r.truth.spatial_axis_deg2.map(|v| format!("{v:.4}")).join(" / "),
        r.truth.temporal_axis_deg2.map(|v| format!("{v:.5}")).join(" / ")
    );
    println!("acceptance (issue 6):");
    for (what, ok) in acceptance(&r) {
        println!("  [{}] {what}", if ok { "ok" } else { "NOT MET" });
    }
    if let Some(p) = &a.report_json {
        std::fs::write(p, serde_json::to_string_pretty(&r)?).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(0)
}
