//! `smocap convert`: whole archives described by `datasets.toml` to MCAP files.

use crate::archive::config::read_datasets;
use crate::archive::mcap_out::WriterOptions;
use crate::archive::progress::{Display, Mode, Progress};
use crate::archive::shard::Shard;
use crate::archive::{convert, ConvertOptions};
use anyhow::Context as _;
use clap::{Args, ValueEnum as _};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// The datasets file.
    #[arg(default_value = "datasets.toml")]
    pub datasets: PathBuf,
    /// Convert only the dataset with this name.
    #[arg(long)]
    pub dataset: Option<String>,
    /// Output folder: `<out>/<dataset>/<trial path>.mcap`, mirroring each dataset's tree.
    #[arg(long, default_value = "smocap-out")]
    pub out: PathBuf,
    /// Parallel workers (subjects and trials); the machine's parallelism by default.
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Convert only shard I of N (0-based; subjects kept whole, balanced by frame count). When
    /// absent, read from SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT or
    /// JOB_COMPLETION_INDEX/SMOCAP_SHARD_COUNT.
    #[arg(long)]
    pub shard: Option<Shard>,
    /// Skip trials whose output exists and records the same input SHA-256.
    #[arg(long)]
    pub resume: bool,
    /// Write the summary (every trial found, with its status) as JSON here.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
    /// No progress display and no line per trial (the final table and failures still print).
    #[arg(long, short)]
    pub quiet: bool,
    /// Seconds between plain progress lines when stderr is not a terminal (a terminal shows
    /// progress bars instead).
    #[arg(long, default_value_t = 10.0, value_name = "SECONDS")]
    pub progress_every: f64,
    /// Log time of each trial's first sample: `YYYY-MM-DDTHH:MM:SSZ` (UTC) or seconds since
    /// 1970-01-01 (TRC and C3D files record no start time that smocap reads).
    #[arg(long, default_value = "2000-01-01T00:00:00Z", value_parser = parse_epoch)]
    pub epoch: u64,
    /// zstd level of the MCAP chunks (1-22).
    #[arg(long, default_value_t = crate::archive::mcap_out::DEFAULT_ZSTD_LEVEL,
        value_parser = clap::value_parser!(u32).range(1..=22))]
    pub zstd_level: u32,
    /// Record each frame's wall-clock solve time in `/smocap/stats` (`solve_s`); without it
    /// the files of the same input are byte-identical across runs.
    #[arg(long)]
    pub timings: bool,
    /// Exit 0 when no trial is found (by default a run that finds nothing to do exits 1).
    #[arg(long)]
    pub allow_empty: bool,
    /// Trials longer than this many frames are read from their files a window of this many
    /// frames at a time, so that memory does not grow with a trial's length (shorter trials
    /// are read whole). The results do not depend on it.
    #[arg(long, default_value_t = crate::archive::trial_job::WINDOW_FRAMES, value_name = "FRAMES",
        value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub window_frames: usize,
    /// Evaluation backend: `cpu` (default; the f64 reference: one lane per trial, trials in
    /// parallel); `wgpu` / `wgpu-f64` (a device backend per subject, its trials solved in
    /// batches whose segments share the lanes); `auto`: wgpu only on a real GPU, else the CPU
    /// backend with a note. `wgpu` without an adapter is an error before any work.
    #[arg(long, value_enum, default_value_t = crate::pipeline::running::device::BackendChoice::Cpu)]
    pub backend: crate::pipeline::running::device::BackendChoice,
    /// Lanes of the scheduler (segments in flight) of a subject's trials solved in batches:
    /// default 4096 on wgpu; given with the CPU backend, trials are solved in batches too. The
    /// lane count changes the speed, not the result.
    #[arg(long)]
    pub lanes: Option<usize>,
    /// Label quality control of every trial (swapped labels, jumps, ghosts): `repair` (default:
    /// exchanges repaired, jumps masked), `flag` (reported, data unchanged, trial suspect) or
    /// `off`; overrides the datasets' `[settings] label_qc`. Events go into each file's
    /// `smocap.run` metadata and the summary.
    #[arg(long, value_enum)]
    pub label_qc: Option<crate::pipeline::input::label_qc::QcMode>,
    /// Retarget every converted trial onto a robot: a shipped robot (`g1`) or a mapping file
    /// (`smocap retarget --robot`). Writes `<trial>.<robot>.pkl`, `.csv`, `.npz` and the report
    /// `.json` beside `<trial>.mcap` and adds `/robot/tf` and `/robot/scene` to it
    /// (docs/guide/retargeting.md).
    #[arg(long, value_name = "ROBOT")]
    pub robot: Option<String>,
    /// The robot's MJCF, when the `--robot` mapping file does not name it.
    #[arg(long, requires = "robot", value_name = "MJCF")]
    pub robot_mjcf: Option<PathBuf>,
    /// Retargeting settings (TOML, as `smocap retarget --settings`).
    #[arg(long, requires = "robot", value_name = "TOML")]
    pub robot_settings: Option<PathBuf>,
    /// Where the robot stands in the MCAP's `world`: `X,Y` or `X,Y,Z` (m, Z up; default 0,0,0:
    /// where the human is). Its files are not moved.
    #[arg(long, requires = "robot", value_parser = super::robot::parse_offset, value_name = "X,Y[,Z]")]
    pub robot_offset: Option<[f64; 3]>,
    /// Measure the subject's body mesh on every converted trial: shaped to the subject, posed at
    /// every frame; writes `<trial>.body.json` (`export --skin-report`'s report) beside
    /// `<trial>.mcap` and puts its figures (height against stature, landmarks off the skin,
    /// virtual markers' error) and a verdict in the summary (about 0.6 s a trial). A body
    /// `suspect` (a figure past its bound) or `failed` makes the exit status 3.
    #[arg(long)]
    pub body: bool,
}

fn parse_epoch(s: &str) -> Result<u64, String> {
    crate::archive::mcap_out::parse_epoch(s)
}

pub fn run(a: ConvertArgs) -> anyhow::Result<u8> {
    let datasets = read_datasets(&a.datasets, a.dataset.as_deref())?;
    let shard = match a.shard {
        Some(s) => Some(s),
        None => Shard::from_env(|k| std::env::var(k).ok())?,
    };
    if let Some(l) = a.lanes {
        anyhow::ensure!((1..=1 << 20).contains(&l), "--lanes {l}: expected 1 to {}", 1 << 20);
    }
    // Settled once for the run (each subject then builds its own backend).
    let (backend, note) = crate::pipeline::running::device::settle(a.backend).map_err(|e| {
        anyhow::anyhow!(
            "--backend {}: {e}",
            a.backend.to_possible_value().map_or("?".into(), |v| v.get_name().to_string())
        )
    })?;
    if let Some(note) = note {
        eprintln!("note: {note}");
    }
    let writer =
        WriterOptions { epoch_ns: a.epoch, zstd_level: a.zstd_level, timings: a.timings, ..WriterOptions::default() };
    let hook = match &a.robot {
        Some(r) => {
            let mut setup = super::robot::RobotSetup::load(r, a.robot_mjcf.as_deref(), a.robot_settings.as_deref())?;
            setup.offset = a.robot_offset.unwrap_or_default().into();
            Some(Arc::new(super::robot::ConvertHook { setup, writer }) as Arc<dyn crate::archive::convert::TrialHook>)
        }
        None => None,
    };
    let progress = Arc::new(Progress::default());
    let opt = ConvertOptions {
        out: a.out.clone(),
        jobs: a.jobs.unwrap_or_else(super::default_threads).max(1),
        shard,
        resume: a.resume,
        progress: Some(progress.clone()),
        writer,
        window_frames: a.window_frames,
        backend,
        lanes: a.lanes,
        label_qc: a.label_qc,
        hook,
    };
    let every = Duration::try_from_secs_f64(a.progress_every)
        .ok()
        .context("--progress-every: a non-negative number of seconds expected")?;
    if let Some(j) = a.jobs {
        anyhow::ensure!((1..=4096).contains(&j), "--jobs {j}: expected 1 to 4096 workers");
    }
    let display = Display::start(progress, Mode::auto(a.quiet, every));
    let summary = convert(&datasets, &opt, &|line| display.println(line));
    display.finish();
    let mut summary = summary?;
    if a.body {
        super::skin_report::convert_pass(&mut summary, opt.jobs, a.resume)?;
    }
    print!("{}", summary.table());
    if let Some(p) = &a.report_json {
        std::fs::write(p, serde_json::to_string_pretty(&summary)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    let failed = summary.failed();
    if failed > 0 {
        eprintln!("{failed} of {} trials failed:", summary.trials.len());
        for t in summary.trials.iter().filter(|t| t.status == "failed" || t.status == "suspect") {
            eprintln!("  {}/{}: {}: {}", t.dataset, t.trial, t.status, t.error.as_deref().unwrap_or(""));
        }
    }
    let robot_failed = summary.hook_failed();
    if robot_failed > 0 {
        eprintln!("{robot_failed} trials converted without their robot:");
        for (t, r) in
            summary.trials.iter().filter_map(|t| Some((t, t.robot.as_ref()?))).filter(|(_, r)| r.status == "failed")
        {
            eprintln!("  {}/{}: {}", t.dataset, t.trial, r.note);
        }
    }
    let body_bad: Vec<_> = summary
        .trials
        .iter()
        .filter_map(|t| Some((t, t.body.as_ref()?)))
        .filter(|(_, b)| b.status == "failed" || b.status == "suspect")
        .collect();
    if !body_bad.is_empty() {
        eprintln!("{} trials' bodies are suspect or missing:", body_bad.len());
        for (t, b) in &body_bad {
            eprintln!("  {}/{}: body {}: {}", t.dataset, t.trial, b.status, b.note);
        }
    }
    let body_failed = body_bad.len();
    for d in summary.datasets.iter().filter(|d| d.failed.is_some()) {
        eprintln!("dataset '{}' failed: {}", d.name, d.failed.as_deref().unwrap_or(""));
    }
    let (ok, bad) = (summary.succeeded(), failed + summary.failed_datasets() + robot_failed + body_failed);
    if ok + bad == 0 {
        eprintln!(
            "{}: no trial found{}",
            a.datasets.display(),
            if a.allow_empty { "" } else { " (exit 1; --allow-empty to accept)" }
        );
    }
    Ok(super::exit_code(ok, bad, a.allow_empty))
}
