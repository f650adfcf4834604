//! `convert`: whole archives described by a `datasets.toml` to MCAP files, as `smocap convert`
//! (`smocap::archive::convert`), with its progress reporting handed to an optional callback.

use crate::errors::{message, ArchiveError};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use smocap::archive::config::read_datasets;
use smocap::archive::hook::TrialHook;
use smocap::archive::progress::{status_line, Progress, Snapshot};
use smocap::archive::shard::Shard;
use smocap::archive::{convert as convert_archive, ConvertOptions};
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// Calls the progress callback (from any thread), keeping the first exception it raises.
struct Reporter {
    callback: Option<Py<PyAny>>,
    progress: Arc<Progress>,
    start: Instant,
    error: Mutex<Option<PyErr>>,
}

impl Reporter {
    fn send(&self, event: &str, line: &str) {
        let Some(cb) = &self.callback else { return };
        let s: Snapshot = self.progress.snapshot();
        Python::attach(|py| {
            let r = (|| -> PyResult<()> {
                let d = PyDict::new(py);
                d.set_item("event", event)?;
                d.set_item("line", line)?;
                d.set_item("trials_done", s.trials_done)?;
                d.set_item("trials_total", s.trials_total)?;
                d.set_item("trials_failed", s.trials_failed)?;
                d.set_item("frames_done", s.frames_done)?;
                d.set_item("frames_total", s.frames_total)?;
                d.set_item("subjects_calibrated", s.subjects_calibrated)?;
                d.set_item("subjects_total", s.subjects_total)?;
                d.set_item("calibration_s", s.calibration_s)?;
                d.set_item("solve_s", s.solve_s)?;
                d.set_item("elapsed_s", self.start.elapsed().as_secs_f64())?;
                cb.call1(py, (d,))?;
                Ok(())
            })();
            if let Err(e) = r {
                let mut first = self.error.lock().unwrap_or_else(|p| p.into_inner());
                first.get_or_insert(e);
            }
        });
    }

    fn status(&self) -> String {
        status_line(&self.progress.snapshot(), self.start.elapsed().as_secs_f64())
    }
}

/// Converts every trial of the datasets in `config` (a `datasets.toml`) to one MCAP file under
/// `out`, as `smocap convert`; returns the summary (`--report-json`'s content) as a dict.
///
/// `shard` is 'I/N' (default: from Slurm/Kubernetes variables, as the command line). `progress`
/// is called with a dict: `event` ('note', 'trial': a trial's line, 'progress': every
/// `progress_every` s, 'done'), `line` (the command line's text) and the counters `trials_done`,
/// `trials_total`, `trials_failed`, `frames_done`, `frames_total`, `subjects_calibrated`,
/// `subjects_total`, `calibration_s` and `solve_s` (the workers' time so far), `elapsed_s`. Failed trials
/// are listed in the summary with their reason; a run that cannot start raises ArchiveError.
/// `robot` (a shipped robot, `"g1"`, or a mapping file) retargets every converted trial onto it,
/// as `smocap convert --robot`: `<trial>.<robot>.pkl`, `.csv`, `.npz`, `.json` beside each
/// `<trial>.mcap` and the robot's channels in it; each trial's `robot` entry says what became of it.
/// `body` measures the subject's body mesh on every converted trial, as `smocap convert --body`:
/// `<trial>.body.json` beside each file and each trial's `body` entry (figures and verdict).
#[pyfunction]
#[pyo3(signature = (config, out, jobs = None, resume = false, shard = None,
    backend = "cpu", progress = None, dataset = None, progress_every = 1.0, lanes = None, robot = None,
    body = false))]
#[allow(clippy::too_many_arguments)]
pub fn convert<'py>(
    py: Python<'py>,
    config: PathBuf,
    out: PathBuf,
    jobs: Option<usize>,
    resume: bool,
    shard: Option<&str>,
    backend: &str,
    progress: Option<Py<PyAny>>,
    dataset: Option<String>,
    progress_every: f64,
    lanes: Option<usize>,
    robot: Option<&str>,
    body: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let archive_err = |e: &(dyn std::error::Error + 'static)| ArchiveError::new_err(message(e));
    let choice = crate::subject::parse_backend(backend)?;
    if let Some(j) = jobs.filter(|j| !(1..=4096).contains(j)) {
        return Err(PyValueError::new_err(format!("jobs {j}: expected 1 to 4096 workers")));
    }
    if let Some(l) = lanes.filter(|l| !(1..=1 << 20).contains(l)) {
        return Err(PyValueError::new_err(format!("lanes {l}: expected 1 to {}", 1 << 20)));
    }
    let every = Duration::try_from_secs_f64(progress_every)
        .map_err(|_| PyValueError::new_err("progress_every: a non-negative number of seconds expected"))?;
    let shard = match shard {
        Some(s) => Some(s.parse::<Shard>().map_err(|e| PyValueError::new_err(format!("shard {s:?}: {e}")))?),
        None => Shard::from_env(|k| std::env::var(k).ok()).map_err(|e| archive_err(&e))?,
    };
    let hook = match robot {
        Some(r) => {
            let setup = smocap::cli::robot::RobotSetup::load(r, None, None)
                .map_err(|e| crate::errors::ModelError::new_err(format!("{e:#}")))?;
            let writer = Default::default();
            Some(Arc::new(smocap::cli::robot::ConvertHook { setup, writer }) as Arc<dyn TrialHook>)
        }
        None => None,
    };
    let reporter = Reporter {
        callback: progress,
        progress: Arc::new(Progress::default()),
        start: Instant::now(),
        error: Mutex::new(None),
    };
    let summary = py.detach(|| -> PyResult<_> {
        let datasets = read_datasets(&config, dataset.as_deref()).map_err(|e| archive_err(&e))?;
        let (backend, note) = smocap::pipeline::running::device::settle(choice)
            .map_err(|e| ArchiveError::new_err(format!("backend {backend}: {}", message(&e))))?;
        if let Some(note) = note {
            reporter.send("note", &format!("note: {note}"));
        }
        let opt = ConvertOptions {
            out,
            jobs: jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
            shard,
            resume,
            progress: Some(reporter.progress.clone()),
            writer: Default::default(),
            window_frames: smocap::archive::trial_job::WINDOW_FRAMES,
            backend,
            lanes,
            label_qc: None,
            hook,
        };
        // A status line every `every` while the conversion runs, as the command line prints
        // when stderr is not a terminal.
        let done = (Mutex::new(false), Condvar::new());
        let summary = std::thread::scope(|scope| {
            if reporter.callback.is_some() {
                scope.spawn(|| {
                    let mut stop = done.0.lock().unwrap_or_else(|p| p.into_inner());
                    while !*stop {
                        stop = done.1.wait_timeout(stop, every).unwrap_or_else(|p| p.into_inner()).0;
                        if !*stop {
                            reporter.send("progress", &reporter.status());
                        }
                    }
                });
            }
            let summary = convert_archive(&datasets, &opt, &|line| reporter.send("trial", line));
            *done.0.lock().unwrap_or_else(|p| p.into_inner()) = true;
            done.1.notify_all();
            summary
        });
        let mut summary = summary.map_err(|e| archive_err(&e))?;
        if body {
            smocap::cli::skin_report::convert_pass(&mut summary, opt.jobs, resume)
                .map_err(|e| ArchiveError::new_err(format!("{e:#}")))?;
        }
        reporter.send("done", &format!("done: {}", reporter.status()));
        Ok(summary)
    })?;
    if let Some(e) = reporter.error.lock().unwrap_or_else(|p| p.into_inner()).take() {
        return Err(e);
    }
    crate::to_python(py, &summary)
}
