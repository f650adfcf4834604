//! `smocap convert`: every trial of every dataset to one MCAP file, each subject calibrated once.
//! Subjects run in parallel (`jobs` workers), a subject's trials too; a trial that fails is
//! recorded with its reason and the others go on.
//!
//! Backends: on the CPU (the default) each trial is solved by one lane on one worker, trials in
//! parallel. With a device backend (`wgpu`, or `auto` on a real GPU) each subject builds its own
//! backend (it holds the subject's model on the device) once calibrated, and its trials go
//! through it in batches ([`solve_and_write_all`]): the segments of a batch's trials share the
//! lanes of one scheduler, so that short trials fill a device batch together, and the batch's
//! QPs run on a pool of `jobs` threads. The backend is owned by the subject's task and used by one
//! batch at a time, so it is never shared between threads: no lock, and no worker of the pool
//! waits on a lock that a task it took up while waiting holds (rayon workers take up other tasks
//! while they wait). Several subjects converted at once each hold their own backend (and each
//! batch its own pool: with several subjects batched at once, more threads than `jobs` share
//! the cores). With `lanes` set, the CPU backend solves a subject's trials in batches the same
//! way. The files do not depend on the grouping, the lane count or `jobs`: each segment is
//! solved as when its trial is solved alone.

use super::config::Dataset;
use super::discover::{discover, SubjectGroup, TrialEntry};
use super::inspect::recorded_run;
use super::mcap_out::{partial_path, RunInfo, WriterOptions};
use super::shard::{assign, Shard};
use super::trial_job::{open_for, solve_and_write, solve_and_write_all, Calibrated, Solver, TrialJob};
use crate::kinematics::backend::BatchBackend;
use crate::pipeline::convention::InputOptions;
use crate::pipeline::device::{BackendChoice, Chosen};
use crate::pipeline::frames::TrialFrames;
use crate::pipeline::stats::P50P90;
use crate::pipeline::subject::prepare_subject;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
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
    pub progress: Option<std::sync::Arc<super::progress::Progress>>,
    /// How each trial's file is written (epoch, compression).
    pub writer: WriterOptions,
    /// Trials longer than this are read this many frames at a time (default
    /// [`super::trial_job::WINDOW_FRAMES`]); shorter ones are held whole. Results do not depend
    /// on it.
    pub window_frames: usize,
    /// Evaluation backend. `auto` is taken per subject as [`crate::pipeline::device::choose`]
    /// does; settle it before ([`crate::pipeline::device::settle`]) to decide once.
    pub backend: BackendChoice,
    /// Lanes of the scheduler with a subject's trials solved in batches: default 4096 on a device
    /// backend; on the CPU backend, setting it solves trials in batches too (else one lane per
    /// trial, trials in parallel).
    pub lanes: Option<usize>,
    /// Label quality control for every trial (`--label-qc`), over what the datasets' settings
    /// say; `None` keeps theirs (default `repair`).
    pub label_qc: Option<crate::pipeline::label_qc::QcMode>,
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

/// One trial's fate.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrialOutcome {
    pub dataset: String,
    pub subject: String,
    /// Path relative to the dataset root.
    pub trial: String,
    pub output: String,
    /// "ok", "skipped" (already converted, `--resume`), "suspect" (converted, but see `error`:
    /// [`crate::pipeline::verdict`]) or "failed".
    pub status: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    pub frames: usize,
    pub solve_s: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ms_per_frame: Option<P50P90>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations: Option<P50P90>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rmse_mm: Option<P50P90>,
    /// The evaluation backend that solved it: `cpu`, or `wgpu: <adapter description>`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backend: Option<String>,
    /// Label quality control events: swaps, jumps, ghosts and what was done
    /// ([`crate::pipeline::label_qc`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub label_qc: Vec<crate::pipeline::label_qc::LabelEvent>,
}

/// A dataset's fate (skipped ones say why: its root is absent; failed ones too: a bad glob, a
/// synthetic dataset that could not be generated, an unreadable folder).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DatasetNote {
    pub name: String,
    pub root: String,
    pub skipped: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
}

/// Errors that stop a conversion before any trial.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error(transparent)]
    Lock(#[from] super::lock::LockError),
}

/// The run: every trial found (in this shard), with its status.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ConvertSummary {
    pub smocap_version: String,
    /// `I/N` when sharded.
    pub shard: Option<String>,
    pub datasets: Vec<DatasetNote>,
    pub trials: Vec<TrialOutcome>,
    /// Each calibrated subject's calibration cost, in dataset and subject order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub calibrations: Vec<SubjectCalibration>,
    /// Wall time of the conversion (s: from the trials found, synthetic datasets generated, to
    /// the last trial written).
    #[serde(default)]
    pub wall_seconds: f64,
    /// Workers of the conversion (`--jobs`).
    #[serde(default)]
    pub threads: usize,
}

/// What calibrating one subject cost.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SubjectCalibration {
    pub dataset: String,
    pub subject: String,
    /// Wall time (s).
    pub seconds: f64,
    pub stages: Vec<crate::solve::calibrate::StageCost>,
}

impl ConvertSummary {
    /// Trials that failed or are suspect.
    pub fn failed(&self) -> usize {
        self.trials.iter().filter(|t| t.status == "failed" || t.status == "suspect").count()
    }

    /// Datasets that failed as a whole (no trial of theirs could be looked at).
    pub fn failed_datasets(&self) -> usize {
        self.datasets.iter().filter(|d| d.failed.is_some()).count()
    }

    /// Trials converted or already done (`ok` or `skipped`).
    pub fn succeeded(&self) -> usize {
        self.trials.iter().filter(|t| t.status == "ok" || t.status == "skipped").count()
    }

    /// One line per dataset: trials ok/skipped/failed, frames, frames/s, p50/p90 figures.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:<24} {:>5} {:>7} {:>6} {:>8} {:>9} {:>14} {:>12} {:>14}\n",
            "dataset",
            "ok",
            "skipped",
            "failed",
            "frames",
            "frames/s",
            "ms/frame p50/90",
            "iter p50/90",
            "RMSE mm p50/90"
        );
        for d in &self.datasets {
            let ts: Vec<&TrialOutcome> = self.trials.iter().filter(|t| t.dataset == d.name).collect();
            if let Some(why) = &d.failed {
                s += &format!("{:<24} failed: {why}\n", d.name);
                continue;
            }
            if let Some(why) = &d.skipped {
                s += &format!("{:<24} skipped: {why}\n", d.name);
                continue;
            }
            let count =
                |st: &str| ts.iter().filter(|t| t.status == st || st == "failed" && t.status == "suspect").count();
            let solved: Vec<&&TrialOutcome> = ts.iter().filter(|t| t.status == "ok").collect();
            let frames: usize = solved.iter().map(|t| t.frames).sum();
            let secs: f64 = solved.iter().map(|t| t.solve_s).sum();
            let med = |f: fn(&TrialOutcome) -> Option<P50P90>| {
                let v: Vec<P50P90> = solved.iter().filter_map(|t| f(t)).collect();
                if v.is_empty() {
                    return "-".to_string();
                }
                let p50: Vec<f64> = v.iter().map(|x| x.p50).collect();
                let p90: Vec<f64> = v.iter().map(|x| x.p90).collect();
                let m = |x: &[f64]| crate::pipeline::stats::percentile(x, 0.5);
                format!("{:.2}/{:.2}", m(&p50), m(&p90))
            };
            s += &format!(
                "{:<24} {:>5} {:>7} {:>6} {:>8} {:>9.0} {:>14} {:>12} {:>14}\n",
                d.name,
                count("ok"),
                count("skipped"),
                count("failed"),
                frames,
                if secs > 0.0 { frames as f64 / secs } else { 0.0 },
                med(|t| t.ms_per_frame),
                med(|t| t.iterations),
                med(|t| t.rmse_mm),
            );
        }
        s + &self.throughput()
    }

    /// Where the time went: calibration per subject (by stage), end-to-end frames/s against the
    /// solver's capacity (frames/s per worker, summed over solved trials, times the workers).
    pub fn throughput(&self) -> String {
        let mut s = String::new();
        if !self.calibrations.is_empty() {
            let n = self.calibrations.len();
            let total: f64 = self.calibrations.iter().map(|c| c.seconds).sum();
            let mut names: Vec<&str> = Vec::new();
            for c in &self.calibrations {
                for st in &c.stages {
                    if !names.contains(&st.stage.as_str()) {
                        names.push(&st.stage);
                    }
                }
            }
            let per: Vec<String> = names
                .iter()
                .map(|name| {
                    let stages = self.calibrations.iter().flat_map(|c| &c.stages);
                    let t: f64 = stages.filter(|st| st.stage == *name).map(|st| st.seconds).sum();
                    format!("{name} {:.1}", t / n as f64 * 1e3)
                })
                .collect();
            let max = self.calibrations.iter().map(|c| c.seconds).fold(0.0, f64::max);
            s += &format!(
                "calibration: {n} subjects, {:.1} ms per subject (max {:.1}; {:.2} s in all), by stage (ms per subject): {}\n",
                total / n as f64 * 1e3,
                max * 1e3,
                total,
                per.join(", ")
            );
        }
        let solved: Vec<&TrialOutcome> =
            self.trials.iter().filter(|t| t.status == "ok" || t.status == "suspect").collect();
        let frames: usize = solved.iter().map(|t| t.frames).sum();
        let secs: f64 = solved.iter().map(|t| t.solve_s).sum();
        if frames > 0 && secs > 0.0 && self.wall_seconds > 0.0 {
            let end_to_end = frames as f64 / self.wall_seconds;
            let capacity = frames as f64 / secs * self.threads.max(1) as f64;
            s += &format!(
                "throughput: {frames} frames in {:.2} s wall: {end_to_end:.0} frames/s end to end; solver {:.0} frames/s per worker × {} = {capacity:.0}; ratio {:.2}\n",
                self.wall_seconds,
                frames as f64 / secs,
                self.threads.max(1),
                end_to_end / capacity
            );
        }
        s
    }
}

/// Where a trial's output goes: `<out>/<dataset>/<rel with its extension replaced by .mcap>`.
pub fn output_path(out: &Path, dataset: &str, rel: &str) -> PathBuf {
    out.join(dataset).join(Path::new(rel).with_extension("mcap"))
}

/// True when `path` lies inside `out`: `out` followed by plain names only (no `..`, no root, no
/// prefix), as [`output_path`] gives for a valid dataset name and a discovered trial.
pub fn inside(out: &Path, path: &Path) -> bool {
    use std::path::Component;
    path.strip_prefix(out).is_ok_and(|rel| {
        rel.components().next().is_some() && rel.components().all(|c| matches!(c, Component::Normal(_)))
    })
}

/// Trials that cannot be converted because of where their output would go, with the reason:
/// outside `--out`, or the same output as another trial (`walk01.trc` and `walk01.TRC`, or
/// `walk01.c3d` and `walk01.trc`, both give `walk01.mcap`; on a case-insensitive file system,
/// so do `walk01.trc` and `WALK01.trc`). Keyed by (dataset index, trial path).
fn output_conflicts(datasets: &[Dataset], groups: &[SubjectGroup], out: &Path) -> BTreeMap<(usize, String), String> {
    let mut by_output: BTreeMap<String, Vec<(usize, &TrialEntry)>> = BTreeMap::new();
    let mut bad = BTreeMap::new();
    for g in groups {
        for t in &g.trials {
            let o = output_path(out, &datasets[g.dataset].name, &t.rel);
            if !inside(out, &o) {
                bad.insert((g.dataset, t.rel.clone()), format!("its output {} would lie outside --out", o.display()));
                continue;
            }
            by_output.entry(o.to_string_lossy().to_lowercase()).or_default().push((g.dataset, t));
        }
    }
    for list in by_output.values().filter(|l| l.len() > 1) {
        let names: Vec<String> = list.iter().map(|(_, t)| t.path.display().to_string()).collect();
        for (d, t) in list {
            let o = output_path(out, &datasets[*d].name, &t.rel);
            bad.insert(
                (*d, t.rel.clone()),
                format!("output collision: {} would all write {}; rename one", names.join(" and "), o.display()),
            );
        }
    }
    bad
}

/// Converts `datasets`; `log` receives one progress line per trial (and notes). Holds the
/// output folder's locks ([`super::lock`]: the folder's, or the shard's) for the whole run.
pub fn convert(
    datasets: &[Dataset],
    opt: &ConvertOptions,
    log: &(dyn Fn(&str) + Sync),
) -> Result<ConvertSummary, ConvertError> {
    let _lock = super::lock::lock_out(&opt.out, opt.shard)?;
    let mut notes = Vec::new();
    let mut groups: Vec<SubjectGroup> = Vec::new();
    for (i, d) in datasets.iter().enumerate() {
        let root = match (&d.synthetic, &d.root) {
            (Some(_), Some(r)) => r.clone(),
            (Some(_), None) => opt.out.join(".synthetic").join(&d.name),
            (None, r) => r.clone().unwrap_or_default(),
        };
        let mut note =
            DatasetNote { name: d.name.clone(), root: root.display().to_string(), skipped: None, failed: None };
        if let Err(why) = super::config::validate_name(&d.name) {
            note.failed = Some(why);
        } else if d.synthetic.is_none() && !root.is_dir() {
            let why = format!("root {} not found", root.display());
            log(&format!("note: dataset '{}' skipped: {why}", d.name));
            note.skipped = Some(why);
        } else {
            let found = match &d.synthetic {
                Some(spec) => super::synthetic::generate(spec, &root).map_err(|e| {
                    let (top, cause) = (e.to_string(), e.root_cause().to_string());
                    if top.contains(&cause) {
                        format!("generating it: {top}")
                    } else {
                        format!("generating it: {top}: {cause}")
                    }
                }),
                None => Ok(()),
            }
            .and_then(|()| discover(i, d, &root).map_err(|e| e.to_string()));
            match found {
                Ok(g) => groups.extend(g),
                Err(why) => note.failed = Some(why),
            }
        }
        if let Some(why) = &note.failed {
            log(&format!("error: dataset '{}' failed: {why}", d.name));
        }
        notes.push(note);
    }
    // The run's clock starts once synthetic datasets are generated and every dataset is found.
    let started = std::time::Instant::now();
    // Found over the whole archive (before sharding), so every shard agrees.
    let conflicts = output_conflicts(datasets, &groups, &opt.out);
    if let Some(s) = opt.shard {
        let owner = assign(&groups, s.count);
        groups = groups.into_iter().zip(owner).filter(|(_, o)| *o == s.index).map(|(g, _)| g).collect();
    }
    let total: usize = groups.iter().map(|g| g.trials.len()).sum();
    if let Some(p) = &opt.progress {
        let name = |g: &SubjectGroup| &datasets[g.dataset].name;
        p.plan(groups.iter().flat_map(|g| g.trials.iter().map(move |t| (format!("{}/{}", name(g), t.rel), t.frames))));
    }
    let done = std::sync::atomic::AtomicUsize::new(0);
    let report = |t: &TrialOutcome| {
        let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if let Some(p) = &opt.progress {
            let solved = (t.status == "ok" || t.status == "suspect").then_some(t.frames as u64);
            p.finished(&format!("{}/{}", t.dataset, t.trial), t.status == "failed" || t.status == "suspect", solved);
        }
        let what = match (&t.status[..], &t.error) {
            ("failed", Some(e)) => format!("failed: {e}"),
            ("suspect", Some(e)) => format!("suspect ({} frames, {:.2} s): {e}", t.frames, t.solve_s),
            (st, _) => format!("{st} ({} frames, {:.2} s)", t.frames, t.solve_s),
        };
        log(&format!("[{k}/{total}] {}/{}: {what}", t.dataset, t.trial));
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
    }
}

/// A failed trial; a temporary file an interrupted run left for it is removed (a trial that is
/// converted overwrites its own).
fn failed(d: &Dataset, g: &SubjectGroup, t: &TrialEntry, out: &Path, why: String) -> TrialOutcome {
    let _ = std::fs::remove_file(partial_path(out));
    outcome(d, g, t, out, "failed", Some(why))
}

/// Converts one subject's trials (those not already done when resuming). Trials are read one at
/// a time as they are solved (a subject without a static trial first reads all its motion trials,
/// done ones included, to calibrate on them as an uninterrupted run would).
fn subject(
    d: &Dataset,
    g: &SubjectGroup,
    opt: &ConvertOptions,
    conflicts: &BTreeMap<(usize, String), String>,
    report: &(dyn Fn(&TrialOutcome) + Sync),
    log: &(dyn Fn(&str) + Sync),
) -> (Vec<TrialOutcome>, Option<SubjectCalibration>) {
    let mut outcomes = Vec::new();
    let mut todo = Vec::new();
    for t in &g.trials {
        let out = output_path(&opt.out, &d.name, &t.rel);
        if let Some(why) = conflicts.get(&(g.dataset, t.rel.clone())) {
            // Nothing is written or removed at a contested (or outside) path.
            outcomes.push(outcome(d, g, t, &out, "failed", Some(why.clone())));
            continue;
        }
        let hash = super::sha256_file(&t.path);
        match hash {
            Err(e) => outcomes.push(failed(d, g, t, &out, format!("{}: {e}", t.path.display()))),
            Ok(h) => {
                // Done when the output is complete (verified) and records this input.
                let done = (opt.resume && out.is_file())
                    .then(|| recorded_run(&out))
                    .flatten()
                    .filter(|run| run.get("input_sha256") == Some(&h));
                match done {
                    Some(run) => {
                        // A temporary file left by an interrupted run is not needed.
                        let _ = std::fs::remove_file(partial_path(&out));
                        // A suspect result stays suspect (the same input gives the same result).
                        let (status, why) = match run.get("verdict").map(String::as_str) {
                            Some("suspect") => ("suspect", run.get("verdict_reason").cloned()),
                            _ => ("skipped", None),
                        };
                        outcomes.push(outcome(d, g, t, &out, status, why));
                    }
                    None => todo.push((t, out, h)),
                }
            }
        }
    }
    outcomes.iter().for_each(report);
    if todo.is_empty() {
        return (outcomes, None);
    }
    let fail_all = |why: String| -> Vec<TrialOutcome> {
        todo.iter().map(|(t, out, _)| failed(d, g, t, out, why.clone())).inspect(report).collect()
    };
    let mut files = d.subject_files(g.static_trial.clone());
    match d.subject_info(&g.subject) {
        Ok(info) => files.subject = info,
        Err(e) => return ([outcomes, fail_all(format!("subject setup: {e}"))].concat(), None),
    }
    let mut sub = match prepare_subject(&files) {
        Ok(s) => s,
        Err(e) => return ([outcomes, fail_all(format!("subject setup: {e}"))].concat(), None),
    };
    // What C3D files say of their subject (as `solve`): the prior's height and mass where the
    // dataset gives none, and whether the subject's trials (done ones too) are one person.
    let paths: Vec<&Path> = g.trials.iter().map(|t| t.path.as_path()).chain(sub.static_path.as_deref()).collect();
    let records = crate::pipeline::subject_check::subject_records(&paths);
    if let Some(n) = crate::pipeline::subject_check::fill_from_records(&mut sub.ctx.subject, &records) {
        log(&format!("note: {}/{}: {n}", d.name, g.subject));
    }
    let mut not_one_person = crate::pipeline::subject_check::inconsistencies(&records);
    if !d.settings.is_empty() {
        match sub.ctx.settings.with_overrides(&d.settings) {
            Ok(s) => sub.ctx.settings = s,
            Err(e) => return ([outcomes, fail_all(format!("datasets.toml [settings]: {e}"))].concat(), None),
        }
        sub.ctx.settings.qp = crate::solve::backend_for(sub.ctx.settings.qp, &sub.ctx.proxy);
    }
    if let Some(mode) = opt.label_qc {
        sub.ctx.settings.label_qc.mode = mode;
    }
    let input = d.input_options();
    // Calibrate as `solve` does: the static trial (when there is one) and the motion trials whose
    // markers match the model's, together (read for calibration, then again one at a time).
    let window = opt.window_frames;
    let statics: Vec<(String, Box<dyn TrialFrames>)> = match &sub.static_path {
        Some(p) => match open_for(d, &sub.ctx, p, &input, window) {
            Ok(t) => {
                // Its labels were screened as the trials' are: what was found goes to the log,
                // and a static trial the screen calls suspect makes the calibration suspect.
                if let Some(qc) = t.label_qc() {
                    for line in qc.lines(&p.display().to_string()) {
                        log(&format!("{}/{}: {line}", d.name, g.subject));
                    }
                    not_one_person.extend(qc.suspect.iter().map(|w| format!("static trial: {w}")));
                }
                vec![(p.display().to_string(), t)]
            }
            Err(e) => return ([outcomes, fail_all(format!("static trial: {e}"))].concat(), None),
        },
        None => Vec::new(),
    };
    let motions: Vec<(String, Box<dyn TrialFrames>)> = g
        .trials
        .iter()
        .filter_map(|t| open_for(d, &sub.ctx, &t.path, &input, window).ok().map(|m| (t.rel.clone(), m)))
        .filter(|(rel, m)| {
            crate::pipeline::trial::match_markers(&sub.ctx, rel, m.header())
                .is_ok_and(|x| x.columns.iter().any(Option::is_some))
        })
        .collect();
    let cal = if statics.is_empty() && motions.is_empty() {
        Err("no trial to calibrate on".to_string())
    } else {
        let s: Vec<(&str, &dyn TrialFrames)> = statics.iter().map(|(n, t)| (n.as_str(), t.as_ref())).collect();
        let m: Vec<(&str, &dyn TrialFrames)> = motions.iter().map(|(n, t)| (n.as_str(), t.as_ref())).collect();
        crate::pipeline::subject::calibrate_placed_with(&sub.ctx, &s, &m)
            .map_err(|e| format!("calibration failed: {e}"))
    };
    drop((statics, motions));
    let cal = match cal {
        Ok((calibration, placed)) => {
            let ctx = placed.as_ref().unwrap_or(&sub.ctx);
            let source = d.model.as_ref().filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("osim")));
            let text = source.and_then(|p| std::fs::read_to_string(p).ok());
            let name = source.map(|p| p.display().to_string()).unwrap_or_default();
            let scaled_model = crate::pipeline::export::scaled_osim(
                ctx,
                &calibration,
                text.as_deref().map(|t| (t, name.as_str())),
                crate::io::osim::MassScaling { subject_mass: ctx.subject.mass_kg, ..Default::default() },
            )
            .ok()
            .and_then(|(m, _)| super::trial_job::compress_model(&m));
            let settings_json = serde_json::to_string_pretty(&ctx.settings).unwrap_or_default();
            let mut suspect = calibration.suspect();
            suspect.extend(not_one_person);
            for w in &suspect {
                log(&format!("warning: {}/{}: suspect calibration: {w}", d.name, g.subject));
            }
            Calibrated { base: sub.ctx, placed, calibration, settings_json, scaled_model, suspect }
        }
        Err(why) => return ([outcomes, fail_all(why)].concat(), None),
    };
    let cost = SubjectCalibration {
        dataset: d.name.clone(),
        subject: g.subject.clone(),
        seconds: cal.calibration.seconds,
        stages: cal.calibration.stages.clone(),
    };
    // The backend holds the model (on the device for wgpu): chosen once the markers are final.
    let pinned = cal.ctx().pinned_to(&cal.calibration);
    let chosen =
        match crate::pipeline::device::choose(opt.backend, &pinned.evaluator(), crate::kinematics::gpu::DEFAULT_CAP) {
            Ok(c) => c,
            Err(e) => return ([outcomes, fail_all(format!("evaluation backend: {e}"))].concat(), Some(cost)),
        };
    drop(pinned);
    if let Some(note) = chosen.note() {
        log(&format!("note: {}/{}: {note}", d.name, g.subject));
    }
    let solved = match (chosen, opt.lanes) {
        (Chosen::Cpu { .. }, None) => todo
            .par_iter()
            .map(|(t, out, hash)| {
                let o = solve_one(d, g, t, out, hash, &input, &cal, opt);
                report(&o);
                o
            })
            .collect(),
        (Chosen::Cpu { .. }, Some(lanes)) => batched(d, g, &todo, &input, &cal, opt, None, lanes, report),
        (Chosen::Wgpu(mut b), lanes) => {
            let device = b.device();
            let lanes = lanes.unwrap_or(4096);
            let backend = Some((b.as_mut() as &mut dyn BatchBackend, device.as_str()));
            batched(d, g, &todo, &input, &cal, opt, backend, lanes, report)
        }
    };
    ([outcomes, solved].concat(), Some(cost))
}

/// Consecutive runs `[i0, i1)` of trials of `frames` frames solved together: until their
/// segments fill `lanes`, they would hold more than [`BATCH_HELD_FRAMES`], or there are
/// [`BATCH_TRIALS`] of them.
pub fn batches(frames: &[u64], lanes: usize, window: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let (mut i0, mut segs, mut held) = (0, 0, 0);
    for (i, &n) in frames.iter().enumerate() {
        let n = usize::try_from(n).unwrap_or(usize::MAX);
        let (s, h) = (crate::pipeline::stream::segment_count(n), n.min(window));
        if i > i0 && (segs >= lanes || held + h > BATCH_HELD_FRAMES || i - i0 >= BATCH_TRIALS) {
            out.push((i0, i));
            (i0, segs, held) = (i, 0, 0);
        }
        segs += s;
        held += h;
    }
    if i0 < frames.len() {
        out.push((i0, frames.len()));
    }
    out
}

/// Solves a subject's trials in batches ([`batches`]) through one backend (`(backend, device)`;
/// the CPU backend when `None`), each batch's segments sharing `lanes` lanes.
#[allow(clippy::too_many_arguments)]
fn batched(
    d: &Dataset,
    g: &SubjectGroup,
    todo: &[(&TrialEntry, PathBuf, String)],
    input: &InputOptions,
    cal: &Calibrated,
    opt: &ConvertOptions,
    mut backend: Option<(&mut dyn BatchBackend, &str)>,
    lanes: usize,
    report: &(dyn Fn(&TrialOutcome) + Sync),
) -> Vec<TrialOutcome> {
    let (name, device) = match &backend {
        Some((b, device)) => (b.name(), *device),
        None => ("cpu", "cpu"),
    };
    let summary = if name == "cpu" { "cpu".to_string() } else { format!("{name}: {device}") };
    let frames: Vec<u64> = todo.iter().map(|(t, ..)| t.frames).collect();
    let mut outcomes = Vec::with_capacity(todo.len());
    for (i0, i1) in batches(&frames, lanes, opt.window_frames) {
        let mut opened = Vec::new();
        for (t, out, hash) in &todo[i0..i1] {
            match open_for(d, &cal.base, &t.path, input, opt.window_frames) {
                Ok(trial) => {
                    let run = run_info(d, g, t, hash, cal, trial.as_ref(), opt, (name, device));
                    opened.push((*t, out, trial, run));
                }
                Err(e) => {
                    let o = failed(d, g, t, out, e);
                    report(&o);
                    outcomes.push(o);
                }
            }
        }
        let jobs: Vec<TrialJob<'_>> = opened
            .iter()
            .map(|(t, out, trial, run)| TrialJob { out: out.as_path(), name: &t.rel, trial: trial.as_ref(), run })
            .collect();
        let solver = Solver { threads: opt.jobs, lanes, backend: backend.as_mut().map(|(b, _)| &mut **b as _) };
        let progress = opt.progress.as_deref().map(|p| &p.frames_done);
        let results = solve_and_write_all(&jobs, cal, &opt.writer, progress, solver);
        for ((t, out, ..), r) in opened.iter().zip(results) {
            let o = trial_outcome(d, g, t, out, r, &summary);
            report(&o);
            outcomes.push(o);
        }
    }
    outcomes
}

/// A converted trial's outcome.
fn trial_outcome(
    d: &Dataset,
    g: &SubjectGroup,
    t: &TrialEntry,
    out: &Path,
    r: Result<super::trial_job::Solved, String>,
    backend: &str,
) -> TrialOutcome {
    match r {
        Ok(s) => TrialOutcome {
            frames: s.frames,
            solve_s: s.solve_s,
            ms_per_frame: Some(s.ms_per_frame),
            iterations: Some(s.iterations),
            rmse_mm: s.rmse_mm,
            backend: Some(backend.into()),
            label_qc: s.label_qc.clone(),
            ..outcome(d, g, t, out, if s.suspect.is_some() { "suspect" } else { "ok" }, s.suspect.clone())
        },
        Err(e) => failed(d, g, t, out, e),
    }
}

/// Reads one trial, solves it (one lane, the CPU backend) and streams it to its MCAP file.
#[allow(clippy::too_many_arguments)]
fn solve_one(
    d: &Dataset,
    g: &SubjectGroup,
    t: &TrialEntry,
    out: &Path,
    hash: &str,
    input: &InputOptions,
    cal: &Calibrated,
    opt: &ConvertOptions,
) -> TrialOutcome {
    let (writer, progress) = (&opt.writer, opt.progress.as_deref());
    let trial = match open_for(d, &cal.base, &t.path, input, opt.window_frames) {
        Ok(m) => m,
        Err(e) => return failed(d, g, t, out, e),
    };
    let run = run_info(d, g, t, hash, cal, trial.as_ref(), opt, ("cpu", "cpu"));
    let r = solve_and_write(out, &t.rel, trial.as_ref(), cal, &run, writer, progress.map(|p| &p.frames_done));
    trial_outcome(d, g, t, out, r, "cpu")
}

/// The `smocap.run` metadata of a trial solved on `backend` (name, device).
#[allow(clippy::too_many_arguments)]
fn run_info(
    d: &Dataset,
    g: &SubjectGroup,
    t: &TrialEntry,
    hash: &str,
    cal: &Calibrated,
    trial: &dyn TrialFrames,
    opt: &ConvertOptions,
    backend: (&str, &str),
) -> RunInfo {
    let ctx = cal.ctx();
    let overrides = serde_json::to_string(&d.settings).unwrap_or_default();
    let mut run = RunInfo::new();
    for (k, v) in [
        ("smocap_version", env!("CARGO_PKG_VERSION")),
        ("git_revision", option_env!("SMOCAP_GIT_REV").unwrap_or("unknown")),
        ("settings_sha256", &super::sha256_hex(cal.settings_json.as_bytes())),
        ("settings_overrides", &overrides),
        ("input_sha256", hash),
        ("input", &t.path.display().to_string()),
        ("dataset", &d.name),
        ("subject", &g.subject),
        ("trial", &t.rel),
        ("model", &ctx.model_source),
        ("backend", backend.0),
        ("adapter", backend.1),
        ("qp_backend", &format!("{:?}", ctx.settings.qp).to_lowercase()),
        ("frames", &trial.header().n_frames().to_string()),
        ("first_sample_time_s", &trial.header().times.first().copied().unwrap_or(0.0).to_string()),
        ("rate_hz", &trial.header().rate_hz.to_string()),
        ("rate_source", if d.rate.is_some() { "datasets.toml" } else { "file" }),
    ] {
        run.insert(k.into(), v.into());
    }
    run.insert("epoch_ns".into(), opt.writer.epoch_ns.to_string());
    run
}

#[cfg(test)]
mod tests {
    use super::batches;

    #[test]
    fn batches_fill_the_lanes_bound_what_they_hold_and_cover_every_trial_once() {
        assert_eq!(batches(&[], 4, 4096), []);
        assert_eq!(batches(&[100, 100, 100], 1, 4096), [(0, 1), (1, 2), (2, 3)]);
        // 1, 2 and 5 segments: a batch ends once its segments fill the lanes.
        assert_eq!(batches(&[100, 450, 1000, 100], 3, 4096), [(0, 2), (2, 3), (3, 4)]);
        assert_eq!(batches(&[100; 300], 4096, 4096), [(0, 128), (128, 256), (256, 300)]);
        // Held frames: a window each at most.
        assert_eq!(batches(&[4096; 40], 1 << 20, 4096), [(0, 32), (32, 40)]);
        assert_eq!(batches(&[100_000; 40], 1 << 20, 8192), [(0, 16), (16, 32), (32, 40)]);
        assert_eq!(batches(&[1 << 40, 10], 1 << 20, 1 << 20), [(0, 1), (1, 2)]);
    }
}
