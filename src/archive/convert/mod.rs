//! `smocap convert`: every trial of every dataset to one MCAP file, each subject calibrated once.
//! The run reads top to bottom as its stages: [`plan`] (discover, shard, what is left to do),
//! per subject [`calibrate`], then [`solve`] (solve and write, [`crate::archive::trial_job`]);
//! [`summary`] is what it reports. Subjects run in parallel on one pool of `jobs` workers, a
//! subject's trials too, so one subject calibrates while another's trials are solved and no
//! worker idles while work remains; a trial that fails is recorded with its reason and the
//! others go on.
//!
//! Backends: on the CPU (the default) each trial is solved by one lane on one worker, trials in
//! parallel. With a device backend (`wgpu`, or `auto` on a real GPU) each subject builds its own
//! backend (it holds the subject's model on the device) once calibrated, and its trials go
//! through it in batches ([`crate::archive::trial_job::solve_and_write_all`]): the segments of a batch's trials share the
//! lanes of one scheduler, so that short trials fill a device batch together, and the batch's
//! QPs run on a pool of `jobs` threads. The backend is owned by the subject's task and used by one
//! batch at a time, so it is never shared between threads: no lock, and no worker of the pool
//! waits on a lock that a task it took up while waiting holds (rayon workers take up other tasks
//! while they wait). Several subjects converted at once each hold their own backend (and each
//! batch its own pool: with several subjects batched at once, more threads than `jobs` share
//! the cores). With `lanes` set, the CPU backend solves a subject's trials in batches the same
//! way. The files do not depend on the grouping, the lane count or `jobs`: each segment is
//! solved as when its trial is solved alone.

mod calibrate;
mod plan;
mod solve;
mod summary;

pub use plan::{inside, output_path};
pub use solve::batches;
pub use summary::{BodyOutcome, ConvertSummary, DatasetNote, HookOutcome, SubjectCalibration, TrialOutcome};

use crate::archive::config::Dataset;
use crate::archive::discover::{SubjectGroup, TrialEntry};
use crate::archive::mcap_out::{partial_path, WriterOptions};
use crate::archive::shard::{assign, Shard};
use crate::pipeline::running::device::BackendChoice;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How to run a conversion.
#[derive(Clone, Debug)]
pub struct ConvertOptions {
    /// Outputs go to `<out>/<dataset>/<trial path with .mcap>`.
    pub out: PathBuf,
    pub jobs: usize,
    pub shard: Option<Shard>,
    /// Skip trials whose output exists and records the same input SHA-256.
    pub resume: bool,
    /// Counters to update as trials and frames finish (for a progress display).
    pub progress: Option<std::sync::Arc<crate::archive::progress::Progress>>,
    /// How each trial's file is written (epoch, compression).
    pub writer: WriterOptions,
    /// Trials longer than this are read this many frames at a time (default
    /// [`crate::archive::trial_job::WINDOW_FRAMES`]); shorter ones are held whole. Results do not depend
    /// on it.
    pub window_frames: usize,
    /// Evaluation backend. `auto` is taken per subject as [`crate::pipeline::running::device::choose`]
    /// does; settle it before ([`crate::pipeline::running::device::settle`]) to decide once.
    pub backend: BackendChoice,
    /// Lanes of the scheduler with a subject's trials solved in batches: default 4096 on a device
    /// backend; on the CPU backend, setting it solves trials in batches too (else one lane per
    /// trial, trials in parallel).
    pub lanes: Option<usize>,
    /// Label quality control for every trial (`--label-qc`), over what the datasets' settings
    /// say; `None` keeps theirs (default `repair`).
    pub label_qc: Option<crate::pipeline::input::label_qc::QcMode>,
    /// Work on each converted trial's complete file after it is written (`--robot`).
    pub hook: Option<std::sync::Arc<dyn TrialHook>>,
}

pub use crate::archive::hook::{HookWork, SolvedMotion, TrialHook};

/// The hook's outcome for a converted trial (`skipped`: done by an earlier run, resuming).
fn hook_outcome(opt: &ConvertOptions, out: &Path, resumed: bool) -> Option<HookOutcome> {
    let hook = opt.hook.as_ref()?;
    if resumed && hook.done(out) {
        return Some(HookOutcome { status: "skipped".into(), note: String::new() });
    }
    Some(hook.run(out).unwrap_or_else(HookOutcome::failed))
}

/// Trials solved together at most: each holds a writer thread (its 1 MiB chunk and zstd
/// context) and a window of its frames.
pub const BATCH_TRIALS: usize = 128;
/// Frames held together at most by the trials solved together (each holds at most a window of
/// [`ConvertOptions::window_frames`]; 131 072 frames of 53 markers are 167 MB of positions), so
/// at most ≈ 650 segments of short trials per batch; a trial holding more is solved in a batch of
/// its own. With the lanes, these bound what a batch holds: more fills a device batch better,
/// at the cost of memory.
pub const BATCH_HELD_FRAMES: usize = 131_072;

/// Errors that stop a conversion before any trial.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error(transparent)]
    Lock(#[from] crate::archive::lock::LockError),
}

/// Converts `datasets`; `log` receives one progress line per trial (and notes). Holds the
/// output folder's locks ([`crate::archive::lock`]: the folder's, or the shard's) for the whole run.
pub fn convert(
    datasets: &[Dataset],
    opt: &ConvertOptions,
    log: &(dyn Fn(&str) + Sync),
) -> Result<ConvertSummary, ConvertError> {
    let _lock = crate::archive::lock::lock_out(&opt.out, opt.shard)?;
    let (notes, mut groups) = plan::discover_all(datasets, opt, log);
    // The run's clock starts once synthetic datasets are generated and every dataset is found.
    let started = std::time::Instant::now();
    // Found over the whole archive (before sharding), so every shard agrees.
    let conflicts = plan::output_conflicts(datasets, &groups, &opt.out);
    if let Some(s) = opt.shard {
        let owner = assign(&groups, s.count);
        groups = groups.into_iter().zip(owner).filter(|(_, o)| *o == s.index).map(|(g, _)| g).collect();
    }
    let total: usize = groups.iter().map(|g| g.trials.len()).sum();
    if let Some(p) = &opt.progress {
        let name = |g: &SubjectGroup| &datasets[g.dataset].name;
        p.plan(groups.iter().flat_map(|g| g.trials.iter().map(move |t| (format!("{}/{}", name(g), t.rel), t.frames))));
        p.subjects_total.store(groups.len() as u64, std::sync::atomic::Ordering::Relaxed);
    }
    let done = std::sync::atomic::AtomicUsize::new(0);
    let report = |t: &TrialOutcome| {
        let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if let Some(p) = &opt.progress {
            let solved = (t.status == "ok" || t.status == "suspect").then_some(t.frames as u64);
            p.finished(&format!("{}/{}", t.dataset, t.trial), t.status == "failed" || t.status == "suspect", solved);
            p.solved_for(t.solve_s);
        }
        let robot = t.robot.as_ref().filter(|r| r.status != "skipped");
        let what = match (&t.status[..], &t.error) {
            ("failed", Some(e)) => format!("failed: {e}"),
            ("suspect", Some(e)) => format!("suspect ({} frames, {:.2} s): {e}", t.frames, t.solve_s),
            (st, _) => format!("{st} ({} frames, {:.2} s)", t.frames, t.solve_s),
        };
        let robot = robot.map_or(String::new(), |r| format!("; robot {}: {}", r.status, r.note));
        log(&format!("[{k}/{total}] {}/{}: {what}{robot}", t.dataset, t.trial));
        for u in &t.unfittable {
            log(&format!("  warning: {}/{}: {}", t.dataset, t.trial, u.why));
        }
    };
    let run = || -> Vec<(Vec<TrialOutcome>, Option<SubjectCalibration>)> {
        groups.par_iter().map(|g| subject(&datasets[g.dataset], g, opt, &conflicts, &report, log)).collect()
    };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(opt.jobs.max(1)).build();
    let per_subject = match &pool {
        Ok(p) => p.install(run),
        Err(_) => run(),
    };
    let mut trials = Vec::new();
    let mut calibrations = Vec::new();
    for (t, c) in per_subject {
        trials.extend(t);
        calibrations.extend(c);
    }
    calibrations.sort_by(|a: &SubjectCalibration, b| (&a.dataset, &a.subject).cmp(&(&b.dataset, &b.subject)));
    trials.sort_by(|a, b| (&a.dataset, &a.trial).cmp(&(&b.dataset, &b.trial)));
    Ok(ConvertSummary {
        smocap_version: env!("CARGO_PKG_VERSION").into(),
        shard: opt.shard.map(|s| format!("{}/{}", s.index, s.count)),
        datasets: notes,
        trials,
        calibrations,
        wall_seconds: started.elapsed().as_secs_f64(),
        threads: opt.jobs.max(1),
    })
}

fn outcome(
    d: &Dataset,
    g: &SubjectGroup,
    t: &TrialEntry,
    out: &Path,
    status: &str,
    error: Option<String>,
) -> TrialOutcome {
    TrialOutcome {
        dataset: d.name.clone(),
        subject: g.subject.clone(),
        trial: t.rel.clone(),
        output: out.display().to_string(),
        status: status.into(),
        error,
        frames: 0,
        solve_s: 0.0,
        ms_per_frame: None,
        iterations: None,
        rmse_mm: None,
        backend: None,
        label_qc: Vec::new(),
        unfittable: Vec::new(),
        reason: None,
        robot: None,
        body: None,
    }
}

/// A failed trial; a temporary file an interrupted run left for it is removed (a trial that is
/// converted overwrites its own).
fn failed(d: &Dataset, g: &SubjectGroup, t: &TrialEntry, out: &Path, why: String) -> TrialOutcome {
    let _ = std::fs::remove_file(partial_path(out));
    outcome(d, g, t, out, "failed", Some(why))
}

/// Converts one subject's trials (those not already done when resuming): calibrated once, then
/// solved and written. Calibration reads all its motion trials (done ones included, to calibrate
/// on them as an uninterrupted run would); those held whole and still to convert are kept for the
/// solve, until the subject's last trial is solved; the others are read again one at a time as
/// they are solved.
fn subject(
    d: &Dataset,
    g: &SubjectGroup,
    opt: &ConvertOptions,
    conflicts: &BTreeMap<(usize, String), String>,
    report: &(dyn Fn(&TrialOutcome) + Sync),
    log: &(dyn Fn(&str) + Sync),
) -> (Vec<TrialOutcome>, Option<SubjectCalibration>) {
    let progress = opt.progress.as_deref();
    let (outcomes, todo) = plan::pending(d, g, opt, conflicts);
    outcomes.iter().for_each(report);
    if todo.is_empty() {
        // Nothing to calibrate for (every trial done or contested): counted as calibrated.
        progress.inspect(|p| p.calibrated(0.0));
        return (outcomes, None);
    }
    let fail_all = |why: String| -> Vec<TrialOutcome> {
        todo.iter().map(|(t, out, _)| failed(d, g, t, out, why.clone())).inspect(report).collect()
    };
    progress.inspect(|p| p.calibrating());
    let calibrated = calibrate::calibrate(d, g, opt, log);
    let seconds = calibrated.as_ref().map_or(0.0, |(c, ..)| c.calibration.seconds);
    progress.inspect(|p| p.calibrated(seconds));
    let (cal, input, mut held) = match calibrated {
        Ok(c) => c,
        Err(why) => return ([outcomes, fail_all(why)].concat(), None),
    };
    let cost = SubjectCalibration {
        dataset: d.name.clone(),
        subject: g.subject.clone(),
        seconds: cal.calibration.seconds,
        stages: cal.calibration.stages.clone(),
    };
    // Only the trials still to convert are kept (resuming, the done ones were read to calibrate).
    held.retain(|rel, _| todo.iter().any(|(t, ..)| &t.rel == rel));
    match solve::solve_all(d, g, &todo, &input, &held, &cal, opt, report, log) {
        Ok(solved) => ([outcomes, solved].concat(), Some(cost)),
        Err(why) => ([outcomes, fail_all(why)].concat(), Some(cost)),
    }
}
