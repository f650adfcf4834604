//! `smocap bench`: throughput and convergence of the joint solve on every dataset of a
//! `datasets.toml`, beside the published SmoCap figures (METHOD.md) and OpenSim 4.6's IK on the
//! shared datasets (`reference/opensim-4.6/*/*_summary.json`).
//!
//! Each subject is set up and calibrated once (on its static trial, else its motion trials), as
//! `smocap convert` does, then its trials are solved one after the other; nothing is written.
//!
//! What is timed ([`TIMED`]): per frame, the frame's trust-region solve in its lane
//! ([`crate::pipeline::TrialResult::frame_seconds`]: warm start, linearisations, QPs, energy
//! evaluations; with one lane, nothing else); FPS is the dataset's frames over the sum of those
//! per-frame times, 1000 / mean ms (the published FPS equals 1000 / median ms). `wall_fps` in the report
//! is frames over the summed wall time of [`solve_trial_with`] (adding marker matching, packing the
//! observations in memory, the thread pool and backend of each trial, gap bridging). Not timed:
//! reading files, loading and setting up the model, calibration, choosing the evaluation backend.

mod figure;

pub use figure::{write_figure, FigureError};

use crate::archive::config::Dataset;
use crate::archive::discover::{discover, SubjectGroup};
use crate::pipeline::calibration::subject::{calibrate_placed_with, prepare_subject, read_trial};
use crate::pipeline::running::device::{choose, BackendChoice, Chosen};
use crate::pipeline::stats::{percentile, P50P90};
use crate::pipeline::{solve_trial_with, Context};
use crate::solve::FrameStatus;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What the figures of a bench time, as written into every report.
pub const TIMED: &str = "ms/frame: each frame's trust-region solve in its lane (warm start, \
linearisations, QPs, energy evaluations); FPS: frames / summed ms/frame; wall_fps: frames / wall \
time of solving the trials in memory (adds marker matching, per-trial pools, gap bridging). \
Excluded: file I/O, model loading and setup, calibration, backend choice.";

/// How to run a bench.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Synthetic datasets without a `root` are generated under `<out>/.synthetic/<name>`, as
    /// `smocap convert` does.
    pub out: PathBuf,
    /// Worker threads of a trial's solve (1: the published single-thread setting).
    pub threads: usize,
    /// Lanes of the scheduler; default: `threads` on the CPU backend, 4096 on wgpu.
    pub lanes: Option<usize>,
    pub backend: BackendChoice,
    /// Folder of OpenSim reference outputs (`<dataset>/*_summary.json`), when present.
    pub reference: Option<PathBuf>,
}

/// The figures of one dataset (frames pooled over its trials).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DatasetBench {
    pub name: String,
    /// Why the dataset was not run (e.g. its root is absent).
    pub skipped: Option<String>,
    pub subjects: usize,
    /// Trials solved.
    pub trials: usize,
    /// `trial: reason` of each trial that could not be solved.
    pub failed: Vec<String>,
    pub frames: usize,
    /// Summed wall time of the trial solves (s).
    pub solve_s: f64,
    /// Frames per second of the solver: frames over the summed per-frame solve times.
    pub fps: f64,
    /// Frames over `solve_s`.
    pub wall_fps: f64,
    pub ms_per_frame: Option<P50P90>,
    pub iterations: Option<P50P90>,
    /// Marker RMSE of the solved frames (bridged frames excluded), mm.
    pub rmse_mm: Option<P50P90>,
    /// Evaluation backend of the last subject (`cpu` or `wgpu`).
    pub backend: String,
    /// Per-frame solve time (ms) and marker RMSE (mm), for the figure.
    #[serde(skip)]
    pub frame_ms: Vec<f64>,
    #[serde(skip)]
    pub frame_rmse_mm: Vec<f64>,
    #[serde(skip)]
    pub frame_iterations: Vec<f64>,
}

/// One line of the table: smocap's, the paper's or OpenSim's figures for a dataset.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Row {
    pub dataset: String,
    /// `smocap`, `SmoCap (published)` or `OpenSim 4.6 IK`.
    pub source: String,
    pub frames: usize,
    pub fps: Option<f64>,
    pub ms_p50: Option<f64>,
    pub ms_p90: Option<f64>,
    pub iterations_p50: Option<f64>,
    pub iterations_p90: Option<f64>,
    pub rmse_mm_p50: Option<f64>,
    pub rmse_mm_p90: Option<f64>,
}

/// A whole bench run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BenchReport {
    pub smocap_version: String,
    /// What is timed (see [`TIMED`]).
    pub timed: String,
    pub threads: usize,
    pub datasets: Vec<DatasetBench>,
    /// The published SmoCap figures (METHOD.md).
    pub published: Vec<Row>,
    /// OpenSim 4.6 IK on the shared datasets (ms/frame: marginal mean, single thread).
    pub opensim: Vec<Row>,
}

/// The published figures (Li & Sugita 2026, as restated in METHOD.md).
pub fn published() -> Vec<Row> {
    [
        ("CAMS-Knee", 10740, 4902.0, 0.204, 0.301, 2.0, 3.0, 18.2, 20.6),
        ("Riglet", 10138, 3353.0, 0.298, 0.383, 3.0, 3.0, 17.8, 21.1),
        ("MoYo (yoga)", 11698, 3013.0, 0.332, 0.498, 2.0, 3.0, 25.8, 32.4),
    ]
    .into_iter()
    .map(|(d, frames, fps, m50, m90, i50, i90, r50, r90)| Row {
        dataset: d.into(),
        source: "SmoCap (published)".into(),
        frames,
        fps: Some(fps),
        ms_p50: Some(m50),
        ms_p90: Some(m90),
        iterations_p50: Some(i50),
        iterations_p90: Some(i90),
        rmse_mm_p50: Some(r50),
        rmse_mm_p90: Some(r90),
    })
    .collect()
}

#[derive(Deserialize)]
struct OpenSimSummary {
    frames: usize,
    ms_per_frame_marginal: f64,
    rms_p50_m: f64,
    rms_p90_m: f64,
}

/// OpenSim's rows from `<dir>/<dataset>/*_summary.json` (one per dataset folder; the folder name
/// is the dataset's). A missing folder gives none; unreadable files are skipped.
pub fn opensim_rows(dir: &Path) -> Vec<Row> {
    let mut rows = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else { return rows };
    let mut dirs: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_dir()).collect();
    dirs.sort();
    for d in dirs {
        let Ok(files) = std::fs::read_dir(&d) else { continue };
        for f in files.filter_map(|e| e.ok().map(|e| e.path())) {
            if !f.file_name().is_some_and(|n| n.to_string_lossy().ends_with("_summary.json")) {
                continue;
            }
            let Some(s) =
                std::fs::read_to_string(&f).ok().and_then(|t| serde_json::from_str::<OpenSimSummary>(&t).ok())
            else {
                continue;
            };
            rows.push(Row {
                dataset: d.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
                source: "OpenSim 4.6 IK".into(),
                frames: s.frames,
                fps: (s.ms_per_frame_marginal > 0.0).then(|| 1e3 / s.ms_per_frame_marginal),
                ms_p50: Some(s.ms_per_frame_marginal),
                ms_p90: None,
                iterations_p50: None,
                iterations_p90: None,
                rmse_mm_p50: Some(s.rms_p50_m * 1e3),
                rmse_mm_p90: Some(s.rms_p90_m * 1e3),
            });
        }
    }
    rows
}

impl DatasetBench {
    fn empty(name: &str) -> DatasetBench {
        DatasetBench {
            name: name.into(),
            skipped: None,
            subjects: 0,
            trials: 0,
            failed: Vec::new(),
            frames: 0,
            solve_s: 0.0,
            fps: 0.0,
            wall_fps: 0.0,
            ms_per_frame: None,
            iterations: None,
            rmse_mm: None,
            backend: String::new(),
            frame_ms: Vec::new(),
            frame_rmse_mm: Vec::new(),
            frame_iterations: Vec::new(),
        }
    }

    /// This dataset as a table row (`None` when skipped or nothing was solved).
    pub fn row(&self) -> Option<Row> {
        let (ms, it) = (self.ms_per_frame?, self.iterations?);
        Some(Row {
            dataset: self.name.clone(),
            source: "smocap".into(),
            frames: self.frames,
            fps: Some(self.fps),
            ms_p50: Some(ms.p50),
            ms_p90: Some(ms.p90),
            iterations_p50: Some(it.p50),
            iterations_p90: Some(it.p90),
            rmse_mm_p50: self.rmse_mm.map(|r| r.p50),
            rmse_mm_p90: self.rmse_mm.map(|r| r.p90),
        })
    }
}

/// The table's header line.
pub const HEADER: [&str; 10] =
    ["dataset", "source", "frames", "FPS", "ms/frame p50", "p90", "iter p50", "p90", "RMSE mm p50", "p90"];

impl BenchReport {
    /// The table: smocap's rows, then OpenSim's and the published ones; skipped datasets and
    /// failed trials as notes below.
    pub fn table(&self) -> String {
        let f = |v: Option<f64>, d: usize| v.map_or("-".to_string(), |x| format!("{x:.d$}"));
        let mut s = format!(
            "{:<22} {:<19} {:>7} {:>8} {:>12} {:>6} {:>8} {:>4} {:>11} {:>6}\n",
            HEADER[0],
            HEADER[1],
            HEADER[2],
            HEADER[3],
            HEADER[4],
            HEADER[5],
            HEADER[6],
            HEADER[7],
            HEADER[8],
            HEADER[9]
        );
        let rows = self.datasets.iter().filter_map(DatasetBench::row).chain(self.opensim.iter().cloned());
        for r in rows.chain(self.published.iter().cloned()) {
            s += &format!(
                "{:<22} {:<19} {:>7} {:>8} {:>12} {:>6} {:>8} {:>4} {:>11} {:>6}\n",
                r.dataset,
                r.source,
                r.frames,
                f(r.fps, 0),
                f(r.ms_p50, 3),
                f(r.ms_p90, 3),
                f(r.iterations_p50, 0),
                f(r.iterations_p90, 0),
                f(r.rmse_mm_p50, 1),
                f(r.rmse_mm_p90, 1),
            );
        }
        for d in &self.datasets {
            if let Some(why) = &d.skipped {
                s += &format!("note: {} skipped: {why}\n", d.name);
            }
            for t in &d.failed {
                s += &format!("note: {} trial failed: {t}\n", d.name);
            }
        }
        s += "OpenSim: marginal mean ms/frame (single thread), in the p50 column.\n";
        s
    }
}

/// Runs the bench on `datasets`; `log` receives progress lines and notes.
pub fn bench(datasets: &[Dataset], opt: &BenchOptions, log: &dyn Fn(&str)) -> BenchReport {
    let mut out = Vec::new();
    for (i, d) in datasets.iter().enumerate() {
        let mut b = DatasetBench::empty(&d.name);
        let root = match (&d.synthetic, &d.root) {
            (Some(_), Some(r)) => r.clone(),
            (Some(_), None) => opt.out.join(".synthetic").join(&d.name),
            (None, r) => r.clone().unwrap_or_default(),
        };
        let found = match &d.synthetic {
            Some(spec) => crate::archive::synthetic::generate(spec, &root).map_err(|e| format!("generating it: {e:#}")),
            None if !root.is_dir() => Err(format!("root {} not found", root.display())),
            None => Ok(()),
        }
        .and_then(|()| discover(i, d, &root).map_err(|e| e.to_string()));
        match found {
            Ok(groups) => {
                for g in &groups {
                    bench_subject(d, g, opt, &mut b, log);
                }
                b.subjects = groups.len();
            }
            Err(why) => {
                log(&format!("note: dataset '{}' skipped: {why}", d.name));
                b.skipped = Some(why);
            }
        }
        b.wall_fps = if b.solve_s > 0.0 { b.frames as f64 / b.solve_s } else { 0.0 };
        let frame_s: f64 = b.frame_ms.iter().sum::<f64>() / 1e3;
        b.fps = if frame_s > 0.0 { b.frame_ms.len() as f64 / frame_s } else { 0.0 };
        if !b.frame_ms.is_empty() {
            b.ms_per_frame = Some(P50P90::of(&b.frame_ms));
            b.iterations = Some(P50P90::of(&b.frame_iterations));
            b.rmse_mm = (!b.frame_rmse_mm.is_empty()).then(|| P50P90::of(&b.frame_rmse_mm));
        }
        out.push(b);
    }
    BenchReport {
        smocap_version: env!("CARGO_PKG_VERSION").into(),
        timed: TIMED.into(),
        threads: opt.threads,
        datasets: out,
        published: published(),
        opensim: opt.reference.as_deref().map(opensim_rows).unwrap_or_default(),
    }
}

/// Sets up, calibrates and solves one subject's trials, adding to `b`.
fn bench_subject(d: &Dataset, g: &SubjectGroup, opt: &BenchOptions, b: &mut DatasetBench, log: &dyn Fn(&str)) {
    let fail_all = |b: &mut DatasetBench, why: &str| {
        b.failed.extend(g.trials.iter().map(|t| format!("{}: {why}", t.rel)));
        log(&format!("{}/{}: {why}", d.name, g.subject));
    };
    let sub = match prepare_subject(&d.subject_files(g.static_trial.clone())) {
        Ok(s) => s,
        Err(e) => return fail_all(b, &format!("subject setup: {e}")),
    };
    let input = d.input_options();
    let static_trial = match sub.static_path.as_deref().map(|p| read_trial(&sub.ctx, p, &input)).transpose() {
        Ok(t) => t.map(|(t, _)| t),
        Err(e) => return fail_all(b, &format!("static trial: {e}")),
    };
    let mut loaded = Vec::new();
    for t in &g.trials {
        match read_trial(&sub.ctx, &t.path, &input) {
            Ok((m, _)) => loaded.push((t.rel.clone(), m)),
            Err(e) => b.failed.push(format!("{}: {e}", t.rel)),
        }
    }
    // As `solve` does: the static trial (when there is one) and the motion trials together.
    let statics: Vec<(&str, &crate::io::MarkerTrial)> = static_trial.iter().map(|t| ("static", t)).collect();
    let motions: Vec<(&str, &crate::io::MarkerTrial)> = loaded.iter().map(|(n, m)| (n.as_str(), m)).collect();
    let (cal, placed) = match calibrate_placed_with(&sub.ctx, &statics, &motions) {
        Ok(c) => c,
        Err(e) => return fail_all(b, &format!("calibration failed: {e}")),
    };
    let ctx: Context = placed.unwrap_or(sub.ctx);
    let mut chosen = match choose(opt.backend, &ctx.evaluator(), crate::kinematics::gpu::DEFAULT_CAP) {
        Ok(c) => c,
        Err(e) => return fail_all(b, &format!("backend: {e}")),
    };
    if let Some(n) = chosen.note() {
        log(&format!("note: {n}"));
    }
    let threads = opt.threads.max(1);
    let lanes = opt.lanes.unwrap_or(match chosen {
        Chosen::Cpu { .. } => threads,
        Chosen::Wgpu(_) => 4096,
    });
    b.backend = chosen.name().into();
    for (name, t) in &loaded {
        match solve_trial_with(&ctx, name, t, &cal, threads, lanes, chosen.backend()) {
            Ok(r) => {
                let solved: Vec<usize> =
                    (0..r.stats.len()).filter(|&f| r.stats[f].status != FrameStatus::TooFewMarkers).collect();
                b.trials += 1;
                b.frames += r.stats.len();
                b.solve_s += r.wall_seconds;
                b.frame_ms.extend(solved.iter().map(|&f| r.frame_seconds[f] * 1e3));
                b.frame_rmse_mm.extend(solved.iter().map(|&f| r.stats[f].rmse_m * 1e3).filter(|x| x.is_finite()));
                b.frame_iterations.extend(solved.iter().map(|&f| r.stats[f].iterations as f64));
                log(&format!(
                    "{}/{}: {} frames, {:.3} s, ms/frame p50 {:.3}",
                    d.name,
                    name,
                    r.stats.len(),
                    r.wall_seconds,
                    percentile(&r.frame_seconds, 0.5) * 1e3
                ));
            }
            Err(e) => b.failed.push(format!("{name}: {e}")),
        }
    }
}
