//! `smocap audit`: the leakage audit, joint solve against a stage-wise scale-then-IK baseline.

use crate::archive::config::read_datasets;
use crate::eval::audit::subjects::SubjectSpec;
use crate::eval::audit::{audit_real, audit_synthetic};
use crate::pipeline::Context;
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct AuditArgs {
    /// Synthetic subjects (each: a static and a motion trial of the shipped model).
    #[arg(long, default_value_t = 20)]
    pub subjects: usize,
    /// Base seed of the synthetic subjects.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Frames of each synthetic motion trial (100 Hz).
    #[arg(long, default_value_t = 300)]
    pub frames: usize,
    /// Real datasets (those with an OpenSim Scale setup and a static trial are audited too).
    #[arg(long, default_value = "datasets.toml")]
    pub datasets: PathBuf,
    /// Skip the real datasets.
    #[arg(long)]
    pub synthetic_only: bool,
    /// Folder of OpenSim reference outputs; default: `../shared/reference/opensim-4.6` beside
    /// the datasets file.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Write the report (per-subject errors of both methods, wins, real datasets) as JSON here.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
    /// Synthetic markers as a lab places them on skin (`SubjectSpec::realistic`): landmarks
    /// misplaced 10–20 mm along the skin, wands 30–60 mm and turned by 10–20°, soft-tissue motion,
    /// a standing posture 2° off neutral; default: markers misplaced 2–12 mm in any direction.
    #[arg(long)]
    pub realistic: bool,
    /// Override a solver setting of the synthetic subjects' solves (`KEY=VALUE`, as `solve --set`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Also print both methods' errors per coordinate (deg RMS) and per scale group (% RMS),
    /// pooled over the synthetic subjects.
    #[arg(long)]
    pub breakdown: bool,
}

pub fn run(a: AuditArgs) -> anyhow::Result<u8> {
    let mut ctx = Context::shipped()?;
    // The synthetic subjects calibrate on their static trial, in which they stand with their arms
    // at the model's neutral (at the sides, palms toward the thighs): the protocol tells both
    // methods so (`--set static_arms=free` withholds it).
    ctx.static_calibration = true;
    ctx.settings.static_arms = crate::solve::StaticArms::Neutral;
    super::solve::apply_set(&mut ctx, &a.set)?;
    let base = if a.realistic { SubjectSpec::realistic() } else { SubjectSpec::default() };
    let spec = SubjectSpec { motion_frames: a.frames.max(1), ..base };
    let mut report = audit_synthetic(&ctx, a.subjects, a.seed, &spec);
    if !a.synthetic_only && a.datasets.is_file() {
        let datasets = read_datasets(&a.datasets, None)?;
        let base = a.datasets.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
        let reference = a.reference.clone().unwrap_or_else(|| base.join("../shared/reference/opensim-4.6"));
        report.real = audit_real(&datasets, &reference, &|l| eprintln!("{l}"));
    }
    print!("{}", report.table());
    if a.breakdown {
        print!("{}", report.breakdown.table());
    }
    if let Some(p) = &a.report_json {
        std::fs::write(p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(if report.failed.is_empty() { 0 } else { super::EXIT_SOME_FAILED })
}
