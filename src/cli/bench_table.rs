//! `smocap bench`: throughput and convergence per dataset of a `datasets.toml`, beside the
//! published SmoCap figures and OpenSim's, as a table, a JSON report and an SVG figure.

use crate::archive::config::read_datasets;
use crate::eval::bench::{bench, write_figure, BenchOptions};
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct BenchTableArgs {
    /// The datasets file.
    #[arg(default_value = "datasets.toml")]
    pub datasets: PathBuf,
    /// Bench only the dataset with this name.
    #[arg(long)]
    pub dataset: Option<String>,
    /// Evaluation backend: `auto` uses wgpu only on a real GPU.
    #[arg(long, value_enum, default_value_t = crate::pipeline::running::device::BackendChoice::Auto)]
    pub backend: crate::pipeline::running::device::BackendChoice,
    /// Worker threads per trial (1, the default, is the published single-thread setting).
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Lanes of the scheduler (default: the thread count on the CPU backend, 4096 on wgpu).
    #[arg(long)]
    pub lanes: Option<usize>,
    /// Where synthetic datasets without a root are generated (`<out>/.synthetic/<name>`).
    #[arg(long, default_value = "smocap-out")]
    pub out: PathBuf,
    /// Folder of OpenSim reference outputs (`<dataset>/*_summary.json`); default:
    /// `../shared/reference/opensim-4.6` beside the datasets file (skipped when absent).
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Write the report (per dataset figures, the reference rows, what is timed) as JSON here.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
    /// Write the figure (SVG: per-frame time and RMSE distributions per dataset) here.
    #[arg(long, default_value = "bench.svg")]
    pub figure: PathBuf,
}

pub fn run(a: BenchTableArgs) -> anyhow::Result<u8> {
    let datasets = read_datasets(&a.datasets, a.dataset.as_deref())?;
    let base = a.datasets.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
    let reference = a.reference.clone().unwrap_or_else(|| base.join("../shared/reference/opensim-4.6"));
    let opt = BenchOptions {
        out: a.out.clone(),
        threads: a.threads.max(1),
        lanes: a.lanes,
        backend: a.backend,
        reference: Some(reference),
    };
    let report = bench(&datasets, &opt, &|line| eprintln!("{line}"));
    print!("{}", report.table());
    println!("timed: {}", report.timed);
    if let Some(p) = &a.report_json {
        std::fs::write(p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    write_figure(&report, &a.figure)?;
    eprintln!("figure: {}", a.figure.display());
    let failed: usize = report.datasets.iter().map(|d| d.failed.len()).sum();
    Ok(if failed > 0 { super::EXIT_SOME_FAILED } else { 0 })
}
