//! `smocap convert`: every trial of every dataset to one MCAP file, each subject calibrated once.
//! Subjects run in parallel (`jobs` workers), a subject's trials too; a trial that fails is
//! recorded with its reason and the others go on.

use super::config::Dataset;
use super::discover::{discover, SubjectGroup, TrialEntry};
use super::inspect::recorded_input_hash;
use super::mcap_out::{partial_path, write_trial, RunInfo};
use super::shard::{assign, Shard};
use crate::pipeline::stats::P50P90;
use crate::pipeline::subject::{calibrate_placed, prepare_subject, read_trial};
use crate::pipeline::{solve_trial_counted, Context};
use crate::solve::Calibration;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
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
}

/// One trial's fate.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrialOutcome {
    pub dataset: String,
    pub subject: String,
    /// Path relative to the dataset root.
    pub trial: String,
    pub output: String,
    /// "ok", "skipped" (already converted, `--resume`) or "failed".
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
}

/// A dataset's fate (skipped ones say why).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DatasetNote {
    pub name: String,
    pub root: String,
    pub skipped: Option<String>,
}

/// The run: every trial found (in this shard), with its status.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ConvertSummary {
    pub smocap_version: String,
    /// `I/N` when sharded.
    pub shard: Option<String>,
    pub datasets: Vec<DatasetNote>,
    pub trials: Vec<TrialOutcome>,
}

impl ConvertSummary {
    pub fn failed(&self) -> usize {
        self.trials.iter().filter(|t| t.status == "failed").count()
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
            if let Some(why) = &d.skipped {
                s += &format!("{:<24} skipped: {why}\n", d.name);
                continue;
            }
            let count = |st: &str| ts.iter().filter(|t| t.status == st).count();
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
        s
    }
}

/// Where a trial's output goes: `<out>/<dataset>/<rel with its extension replaced by .mcap>`.
pub fn output_path(out: &Path, dataset: &str, rel: &str) -> PathBuf {
    out.join(dataset).join(Path::new(rel).with_extension("mcap"))
}

/// Converts `datasets`; `log` receives one progress line per trial (and notes).
pub fn convert(datasets: &[Dataset], opt: &ConvertOptions, log: &(dyn Fn(&str) + Sync)) -> ConvertSummary {
    let mut notes = Vec::new();
    let mut groups: Vec<SubjectGroup> = Vec::new();
    for (i, d) in datasets.iter().enumerate() {
        let root = match (&d.synthetic, &d.root) {
            (Some(_), Some(r)) => r.clone(),
            (Some(_), None) => opt.out.join(".synthetic").join(&d.name),
            (None, r) => r.clone().unwrap_or_default(),
        };
        let mut note = DatasetNote { name: d.name.clone(), root: root.display().to_string(), skipped: None };
        let found = match &d.synthetic {
            Some(spec) => super::synthetic::generate(spec, &root).map_err(|e| format!("generating it: {e:#}")),
            None if !root.is_dir() => Err(format!("root {} not found", root.display())),
            None => Ok(()),
        }
        .and_then(|()| discover(i, d, &root).map_err(|e| e.to_string()));
        match found {
            Ok(g) => groups.extend(g),
            Err(why) => {
                log(&format!("note: dataset '{}' skipped: {why}", d.name));
                note.skipped = Some(why);
            }
        }
        notes.push(note);
    }
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
            let solved = (t.status == "ok").then_some(t.frames as u64);
            p.finished(&format!("{}/{}", t.dataset, t.trial), t.status == "failed", solved);
        }
        let what = match (&t.status[..], &t.error) {
            ("failed", Some(e)) => format!("failed: {e}"),
            (st, _) => format!("{st} ({} frames, {:.2} s)", t.frames, t.solve_s),
        };
        log(&format!("[{k}/{total}] {}/{}: {what}", t.dataset, t.trial));
    };
    let run = || -> Vec<TrialOutcome> {
        groups.par_iter().flat_map_iter(|g| subject(&datasets[g.dataset], g, opt, &report)).collect()
    };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(opt.jobs.max(1)).build();
    let mut trials = match &pool {
        Ok(p) => p.install(run),
        Err(_) => run(),
    };
    trials.sort_by(|a, b| (&a.dataset, &a.trial).cmp(&(&b.dataset, &b.trial)));
    ConvertSummary {
        smocap_version: env!("CARGO_PKG_VERSION").into(),
        shard: opt.shard.map(|s| format!("{}/{}", s.index, s.count)),
        datasets: notes,
        trials,
    }
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
    }
}

/// Everything one subject needs to write its trials.
struct Calibrated {
    ctx: Context,
    calibration: Calibration,
    settings_json: String,
    scaled_model: Option<String>,
}

/// Converts one subject's trials (those not already done when resuming).
fn subject(
    d: &Dataset,
    g: &SubjectGroup,
    opt: &ConvertOptions,
    report: &(dyn Fn(&TrialOutcome) + Sync),
) -> Vec<TrialOutcome> {
    let mut outcomes = Vec::new();
    let mut todo = Vec::new();
    for t in &g.trials {
        let out = output_path(&opt.out, &d.name, &t.rel);
        let hash = std::fs::read(&t.path).map(|b| super::sha256_hex(&b));
        match hash {
            Err(e) => outcomes.push(outcome(d, g, t, &out, "failed", Some(format!("{}: {e}", t.path.display())))),
            Ok(h) if opt.resume && out.is_file() && recorded_input_hash(&out).as_deref() == Some(h.as_str()) => {
                // A temporary file left by an interrupted rerun is not needed.
                let _ = std::fs::remove_file(partial_path(&out));
                outcomes.push(outcome(d, g, t, &out, "skipped", None))
            }
            Ok(h) => todo.push((t, out, h)),
        }
    }
    outcomes.iter().for_each(report);
    if todo.is_empty() {
        return outcomes;
    }
    let fail_all = |why: String| -> Vec<TrialOutcome> {
        todo.iter().map(|(t, out, _)| outcome(d, g, t, out, "failed", Some(why.clone()))).inspect(report).collect()
    };
    let sub = match prepare_subject(&d.subject_files(g.static_trial.clone())) {
        Ok(s) => s,
        Err(e) => return [outcomes, fail_all(format!("subject setup: {e}"))].concat(),
    };
    let input = d.input_options();
    let static_trial = match &sub.static_path {
        Some(p) => match read_trial(&sub.ctx, p, &input) {
            Ok((t, _)) => Some((p.display().to_string(), t)),
            Err(e) => return [outcomes, fail_all(format!("static trial: {e}"))].concat(),
        },
        None => None,
    };
    let mut loaded = Vec::new();
    for (t, out, hash) in &todo {
        match read_trial(&sub.ctx, &t.path, &input) {
            Ok((m, _)) => loaded.push((*t, out, hash, m)),
            Err(e) => {
                let o = outcome(d, g, t, out, "failed", Some(e.to_string()));
                report(&o);
                outcomes.push(o);
            }
        }
    }
    // Calibrate on the static trial, else on the motion trials whose markers match the model's.
    let cal_input: Vec<(&str, &crate::io::MarkerTrial)> = match &static_trial {
        Some((n, t)) => vec![(n.as_str(), t)],
        None => loaded
            .iter()
            .filter(|(t, .., m)| {
                crate::pipeline::trial::match_markers(&sub.ctx, &t.rel, m)
                    .is_ok_and(|x| x.columns.iter().any(Option::is_some))
            })
            .map(|(t, .., m)| (t.rel.as_str(), m))
            .collect(),
    };
    let cal = if cal_input.is_empty() {
        Err("no trial to calibrate on".to_string())
    } else {
        calibrate_placed(&sub.ctx, &cal_input).map_err(|e| format!("calibration failed: {e}"))
    };
    let cal = match cal {
        Ok((calibration, placed)) => {
            let ctx = placed.unwrap_or(sub.ctx);
            let source = d.model.as_ref().filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("osim")));
            let text = source.and_then(|p| std::fs::read_to_string(p).ok());
            let name = source.map(|p| p.display().to_string()).unwrap_or_default();
            let scaled_model = crate::pipeline::export::scaled_osim(
                &ctx,
                &calibration,
                text.as_deref().map(|t| (t, name.as_str())),
                crate::io::osim::MassScaling::default(),
            )
            .ok()
            .map(|(m, _)| m);
            let settings_json = serde_json::to_string_pretty(&ctx.settings).unwrap_or_default();
            Calibrated { ctx, calibration, settings_json, scaled_model }
        }
        Err(why) => {
            let failed: Vec<TrialOutcome> = loaded
                .iter()
                .map(|(t, out, ..)| outcome(d, g, t, out, "failed", Some(why.clone())))
                .inspect(report)
                .collect();
            return [outcomes, failed].concat();
        }
    };
    let solved: Vec<TrialOutcome> = loaded
        .par_iter()
        .map(|(t, out, hash, m)| {
            let o = solve_one(d, g, t, out, hash, m, &cal, opt.progress.as_deref());
            report(&o);
            o
        })
        .collect();
    [outcomes, solved].concat()
}

/// Solves one trial and writes its MCAP file.
#[allow(clippy::too_many_arguments)]
fn solve_one(
    d: &Dataset,
    g: &SubjectGroup,
    t: &TrialEntry,
    out: &Path,
    hash: &str,
    trial: &crate::io::MarkerTrial,
    cal: &Calibrated,
    progress: Option<&super::progress::Progress>,
) -> TrialOutcome {
    let fail = |e: String| outcome(d, g, t, out, "failed", Some(e));
    let unused = std::sync::atomic::AtomicU64::new(0);
    let frames_done = progress.map_or(&unused, |p| &p.frames_done);
    let r = match solve_trial_counted(&cal.ctx, &t.rel, trial, &cal.calibration, 1, frames_done) {
        Ok(r) => r,
        Err(e) => return fail(e.to_string()),
    };
    let mut run = RunInfo::new();
    for (k, v) in [
        ("smocap_version", env!("CARGO_PKG_VERSION")),
        ("git_revision", option_env!("SMOCAP_GIT_REV").unwrap_or("unknown")),
        ("settings_sha256", &super::sha256_hex(cal.settings_json.as_bytes())),
        ("input_sha256", hash),
        ("input", &t.path.display().to_string()),
        ("dataset", &d.name),
        ("subject", &g.subject),
        ("trial", &t.rel),
        ("model", &cal.ctx.model_source),
        ("backend", "cpu"),
        ("adapter", "cpu"),
        ("qp_backend", &format!("{:?}", cal.ctx.settings.qp).to_lowercase()),
        ("frames", &r.proxies.len().to_string()),
        ("first_sample_time_s", &trial.times.first().copied().unwrap_or(0.0).to_string()),
    ] {
        run.insert(k.into(), v.into());
    }
    if let Some(parent) = out.parent() {
        if let Err(e) = std::fs::create_dir_all(parent) {
            return fail(format!("{}: {e}", parent.display()));
        }
    }
    if let Err(e) = write_trial(out, &cal.ctx, trial, &r, &run, &cal.settings_json, cal.scaled_model.as_deref()) {
        let _ = std::fs::remove_file(partial_path(out));
        return fail(e.to_string());
    }
    let ms: Vec<f64> = r.frame_seconds.iter().map(|s| s * 1e3).collect();
    let it: Vec<f64> = r.stats.iter().map(|s| s.iterations as f64).collect();
    let rmse: Vec<f64> = r.stats.iter().map(|s| s.rmse_m * 1e3).filter(|x| x.is_finite()).collect();
    TrialOutcome {
        frames: r.proxies.len(),
        solve_s: r.frame_seconds.iter().sum(),
        ms_per_frame: Some(P50P90::of(&ms)),
        iterations: Some(P50P90::of(&it)),
        rmse_mm: (!rmse.is_empty()).then(|| P50P90::of(&rmse)),
        ..outcome(d, g, t, out, "ok", None)
    }
}
