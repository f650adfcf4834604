//! `smocap synth`: a synthetic trial and its truth.

use crate::io::trc;
use crate::kinematics::synth::{synthesize_motion, Motion, SynthOptions};
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Model (MJCF); the shipped full-body model by default.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Solver profile (TOML) that defines the proxies the motion is generated in.
    #[arg(long)]
    pub profile: Option<PathBuf>,
    #[arg(long, default_value_t = 500)]
    pub frames: usize,
    /// Sampling rate (Hz).
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Gaussian marker noise, standard deviation per axis (mm).
    #[arg(long, default_value_t = 2.0)]
    pub noise_mm: f64,
    /// Constant per-marker misplacement on its segment (mm).
    #[arg(long, default_value_t = 0.0)]
    pub misplace_mm: f64,
    /// Amplitude of slow soft-tissue-like drift (mm).
    #[arg(long, default_value_t = 0.0)]
    pub drift_mm: f64,
    /// Fraction of samples missing (in runs of frames).
    #[arg(long, default_value_t = 0.0)]
    pub dropout: f64,
    /// Scale factors are drawn in 1 ± this.
    #[arg(long, default_value_t = 0.1)]
    pub scale_spread: f64,
    /// The motion: `walk` (every coordinate a sum of slow waves while walking forward) or
    /// `fast-arm` (the same with the right shoulder swinging at up to ~1,760°/s).
    #[arg(long, value_enum, default_value_t = Motion::Walk)]
    pub motion: Motion,
    /// Output TRC file (written in mm).
    #[arg(long)]
    pub out: PathBuf,
    /// Output truth JSON (scales, coordinates per frame).
    #[arg(long)]
    pub truth: PathBuf,
}

impl SynthArgs {
    pub fn options(&self) -> SynthOptions {
        SynthOptions {
            frames: self.frames,
            rate_hz: self.rate,
            seed: self.seed,
            noise_m: self.noise_mm * 1e-3,
            misplace_m: self.misplace_mm * 1e-3,
            drift_m: self.drift_mm * 1e-3,
            dropout: self.dropout,
            scale_spread: self.scale_spread,
            ..SynthOptions::default()
        }
    }
}

pub fn run(a: SynthArgs) -> anyhow::Result<u8> {
    anyhow::ensure!((0.0..1.0).contains(&a.dropout), "--dropout must be in [0, 1), got {}", a.dropout);
    anyhow::ensure!(a.frames > 0 && a.rate > 0.0, "--frames and --rate must be positive");
    anyhow::ensure!((0.0..0.5).contains(&a.scale_spread), "--scale-spread must be in [0, 0.5), got {}", a.scale_spread);
    for (flag, v) in [("--noise-mm", a.noise_mm), ("--misplace-mm", a.misplace_mm), ("--drift-mm", a.drift_mm)] {
        anyhow::ensure!(v.is_finite() && v >= 0.0, "{flag} must be finite and ≥ 0, got {v}");
    }
    let ctx = super::load_context(a.model.as_deref(), a.profile.as_deref())?;
    let s = synthesize_motion(&ctx.model, &ctx.proxy, &a.options(), a.motion).with_context(|| {
        "--motion fast-arm: the model has no right shoulder flexion proxy (`arm_flex_r`) to swing; \
         --motion walk works on any model"
    })?;
    trc::write_trc(&a.out, &s.trial, "mm").with_context(|| format!("writing {}", a.out.display()))?;
    let json = serde_json::to_string_pretty(&s.truth)?;
    std::fs::write(&a.truth, json).with_context(|| format!("writing {}", a.truth.display()))?;
    eprintln!(
        "wrote {} frames of {} markers to {} and the truth to {}",
        a.frames,
        ctx.model.markers.len(),
        a.out.display(),
        a.truth.display()
    );
    Ok(0)
}
