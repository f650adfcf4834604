//! `smocap merge-reports`: the summaries of sharded `smocap convert` runs joined into one.

use crate::archive::merge::merge;
use crate::archive::ConvertSummary;
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct MergeArgs {
    /// Summaries written by `smocap convert --report-json` (one per shard).
    #[arg(required = true)]
    pub reports: Vec<PathBuf>,
    /// Write the merged summary (all trials, the shards it joins) as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// A trial in two summaries: keep the later one (warning) instead of stopping with an error.
    #[arg(long)]
    pub keep_last: bool,
}

pub fn run(a: MergeArgs) -> anyhow::Result<u8> {
    let mut reports = Vec::new();
    for p in &a.reports {
        let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
        let r: ConvertSummary =
            serde_json::from_str(&text).with_context(|| format!("{}: not a smocap convert summary", p.display()))?;
        reports.push((p.display().to_string(), r));
    }
    let (merged, warnings) = merge(&reports, a.keep_last)?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let s = &merged.summary;
    print!("{}", s.table());
    if let Some(p) = &a.out {
        std::fs::write(p, serde_json::to_string_pretty(&merged)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    let failed = s.failed();
    eprintln!("{} summaries, {} trials, {failed} failed", reports.len(), s.trials.len());
    for t in s.trials.iter().filter(|t| t.status == "failed" || t.status == "suspect") {
        eprintln!("  {}/{}: {}: {}", t.dataset, t.trial, t.status, t.error.as_deref().unwrap_or(""));
    }
    Ok(super::exit_code(s.succeeded(), failed + s.failed_datasets(), false))
}
