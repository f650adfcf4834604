//! `smocap solve`: calibrate a subject, then solve its trials.

use crate::pipeline::report::{trial_report, Report};
use crate::pipeline::{calibrate_subject, solve_trial_with};
use crate::solve::QpBackend;
use crate::synth::Truth;
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SolveArgs {
    /// Model: OpenSim `.osim` or MJCF; the shipped full-body model by default.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// OpenSim marker set file (`<MarkerSet>`) attached to the model.
    #[arg(long)]
    pub markerset: Option<PathBuf>,
    /// Solver profile (TOML); the model's default profile when absent.
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// Static calibration trial; without one, frames of the motion trials are used.
    #[arg(long = "static")]
    pub static_trial: Option<PathBuf>,
    /// Motion trials (TRC or C3D).
    #[arg(required = true)]
    pub trials: Vec<PathBuf>,
    /// Truth JSON from `smocap synth`, for pose and scale errors (single trial).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Worker threads (segments of a trial solved in parallel).
    #[arg(long)]
    pub threads: Option<usize>,
    /// QP backend for the trust-region step.
    #[arg(long, value_enum)]
    pub qp: Option<QpBackend>,
    /// Write the JSON report here.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
    #[command(flatten)]
    pub backend: super::BackendArgs,
}

pub fn run(a: SolveArgs) -> anyhow::Result<u8> {
    anyhow::ensure!(a.markerset.is_none() || a.model.is_some(), "--markerset needs --model");
    let mut ctx = super::load_context_with_markers(a.model.as_deref(), a.markerset.as_deref(), a.profile.as_deref())?;
    if let Some(qp) = a.qp {
        ctx.settings.qp = crate::solve::backend_for(qp, &ctx.proxy);
        if ctx.settings.qp != qp {
            eprintln!("note: the profile has general linear constraints, which only the clarabel QP backend solves");
        }
    }
    let threads = a.threads.unwrap_or_else(super::default_threads).max(1);
    anyhow::ensure!(
        a.truth.is_none() || a.trials.len() == 1,
        "--truth describes one trial, but {} trials were given",
        a.trials.len()
    );
    let truth: Option<Truth> = match &a.truth {
        Some(p) => Some(
            serde_json::from_str(&std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?)
                .with_context(|| format!("parsing truth {}", p.display()))?,
        ),
        None => None,
    };
    let static_trial = match &a.static_trial {
        Some(p) => Some(crate::io::read_markers(p)?),
        None => None,
    };
    let (mut chosen, lanes) = a.backend.choose(&ctx, threads)?;
    let mut report = Report::new(&ctx, threads);
    report.set_backend(&chosen, lanes);
    let mut loaded = Vec::new();
    for p in &a.trials {
        let name = p.display().to_string();
        match crate::io::read_markers(p) {
            Ok(t) => loaded.push((name, t)),
            Err(e) => report.push(Report::failed(&name, e.to_string())),
        }
    }
    let calibration_input: Vec<(&str, &crate::io::MarkerTrial)> = match (&a.static_trial, &static_trial) {
        (Some(p), Some(st)) => vec![(p.to_str().unwrap_or("static"), st)],
        _ => loaded.iter().map(|(n, t)| (n.as_str(), t)).collect(),
    };
    let calibration =
        if calibration_input.is_empty() { None } else { Some(calibrate_subject(&ctx, &calibration_input)) };
    for (name, t) in &loaded {
        let result = match &calibration {
            Some(Ok(c)) => {
                solve_trial_with(&ctx, name, t, c, threads, lanes, chosen.backend()).map_err(|e| e.to_string())
            }
            Some(Err(e)) => Err(format!("calibration failed: {e}")),
            None => Err("no calibration".into()),
        };
        match result {
            Ok(r) => {
                for &f in &r.bridged {
                    eprintln!(
                        "{name}: frame {f} (file frame {}, t = {:.3} s) has fewer than {} observed markers; bridged from its neighbours",
                        t.frame_numbers.get(f).copied().unwrap_or(f as i64 + 1),
                        t.times.get(f).copied().unwrap_or(f64::NAN),
                        ctx.settings.min_markers
                    );
                }
                report.push(trial_report(&ctx, &r, truth.as_ref()));
            }
            Err(e) => report.push(Report::failed(name, e)),
        }
    }
    print!("{}", report.table());
    if let Some(path) = &a.report_json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let failed = report.trials.iter().filter(|t| t.status != "ok").count();
    if failed > 0 {
        eprintln!("{failed} of {} trials failed", report.trials.len());
        if failed == report.trials.len() {
            anyhow::bail!(
                "every trial failed: {}",
                report.trials.iter().filter_map(|t| t.error.clone()).collect::<Vec<_>>().join("; ")
            );
        }
        return Ok(super::EXIT_SOME_FAILED);
    }
    Ok(0)
}
