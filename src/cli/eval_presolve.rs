//! `smocap eval-presolve`: the pre-solve evaluation on the hard synthetic set.

use crate::eval::presolve::evaluate;
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct EvalPresolveArgs {
    /// Frames per hard case (and of the base motion the subject is calibrated on).
    #[arg(long, default_value_t = 600)]
    pub frames: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Model (MJCF or .osim); the shipped full-body model by default.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Solver profile (TOML).
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// Write the results as JSON here.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
}

pub fn run(a: EvalPresolveArgs) -> anyhow::Result<u8> {
    anyhow::ensure!(a.frames >= 2, "--frames must be at least 2");
    let ctx = super::load_context(a.model.as_deref(), a.profile.as_deref())?;
    let result = evaluate(&ctx, a.frames, a.seed)?;
    print!("{}", result.table());
    if let Some(path) = &a.report_json {
        std::fs::write(path, serde_json::to_string_pretty(&result)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(0)
}
