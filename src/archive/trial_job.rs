//! One trial of `smocap convert`: read it, solve it frame by frame and stream each frame into its
//! MCAP file as it is solved ([`super::mcap_out::TrialWriter`]); what is kept is the trial's input
//! and three numbers per frame for the summary.
//!
//! The solver runs on the caller's thread; the file is written (kinematics of the frame,
//! protobuf encoding, zstd) on a writer thread of its own, fed through a bounded queue of
//! [`QUEUE_FRAMES`] solved frames, so a slow disk holds the solver back rather than memory
//! growing. With a hook ([`super::hook`], `--robot`), the writer also keeps each frame's
//! coordinates (`nq` numbers a frame) for it; the hook runs on the trial's motion once the last
//! frame is written, before the file is finished.

use super::config::Dataset;
use super::hook::{HookOutcome, HookWork, SolvedMotion, TrialHook};
use super::mcap_out::{McapOutError, RunInfo, TrialNames, TrialWriter, WriterOptions};
use crate::io::MarkerFile;
use crate::kinematics::backend::BatchBackend;
use crate::pipeline::input::convention::{conform_trial, decide_conventions, Conform, InputOptions};
use crate::pipeline::input::file_frames::FileFrames;
use crate::pipeline::input::frames::TrialFrames;
use crate::pipeline::input::trial::SinkError;
use crate::pipeline::results::verdict::{Judge, Verdict};
use crate::pipeline::running::marker_errors::MarkerErrors;
use crate::pipeline::running::stream::{solve_trials_streaming, TrialStream};
use crate::pipeline::running::unfittable::Unfittable;
use crate::pipeline::stats::P50P90;
use crate::pipeline::{Context, SolvedFrame};
use crate::solve::Calibration;
use rayon::prelude::*;
use std::path::Path;

/// A subject ready to solve its trials.
pub struct Calibrated {
    /// The context the trials are read with (units, up axis).
    pub base: Context,
    /// The context with the markers placed, when marker placement moved them.
    pub placed: Option<Context>,
    pub calibration: Calibration,
    pub settings_json: String,
    /// The scaled model (`.osim` text), zstd-compressed ([`compress_model`]) once per subject.
    pub scaled_model: Option<Vec<u8>>,
    /// Why the calibration cannot be trusted ([`crate::solve::Calibration::suspect`], and trials that are not
    /// one person's, [`crate::pipeline::calibration::subject_check::inconsistencies`]): every trial of the
    /// subject is then `suspect`. Empty when it can.
    pub suspect: Vec<String>,
}

/// zstd level of the scaled-model attachment, compressed once per subject: 3. On gait2354's
/// 404 kB `.osim` (zstd 1.5 CLI): level 3 12.2 kB, 9 10.7 kB, 19 ≈ 10.5 kB; level 9's set-up alone
/// (tables cleared) was 6 % of converting that 151-frame trial in `perf`, for 10 bytes a frame.
const MODEL_ZSTD_LEVEL: i32 = 3;

/// Frames in flight between the solver and the writer thread of one trial.
pub const QUEUE_FRAMES: usize = 256;
/// Frames handed to the writer thread at a time.
const BATCH_FRAMES: usize = 32;

/// `text` compressed with zstd (for the scaled-model attachment); `None` if compression fails.
pub fn compress_model(text: &str) -> Option<Vec<u8>> {
    zstd::bulk::compress(text.as_bytes(), MODEL_ZSTD_LEVEL).ok()
}

impl Calibrated {
    /// The context the trials are solved with.
    pub fn ctx(&self) -> &Context {
        self.placed.as_ref().unwrap_or(&self.base)
    }
}

/// Frames read at a time from a trial longer than this (shorter trials are held whole): what a
/// trial holds while it is converted is bounded by it, whatever the trial's length. The result
/// does not depend on it. 4096 frames of 53 markers hold 5.2 MB of positions.
pub const WINDOW_FRAMES: usize = 4096;

/// Opens a trial for dataset `d` in the model's conventions, with the dataset's rate override:
/// held whole when it has at most `window` frames, else read `window` frames at a time.
pub fn open_for(
    d: &Dataset,
    ctx: &Context,
    path: &Path,
    input: &InputOptions,
    window: usize,
) -> Result<Box<dyn TrialFrames>, String> {
    // Label quality control before anything reads the frames (calibration, solve).
    let name = path.display().to_string();
    crate::pipeline::input::label_qc::screened(ctx, &name, open_unscreened(d, ctx, path, input, window)?)
}

/// [`open_for`] without label quality control.
fn open_unscreened(
    d: &Dataset,
    ctx: &Context,
    path: &Path,
    input: &InputOptions,
    window: usize,
) -> Result<Box<dyn TrialFrames>, String> {
    let file = MarkerFile::open(path, window).map_err(|e| e.to_string())?;
    if file.held() {
        let mut t = file.trial;
        conform_trial(ctx, &mut t, input);
        if let Some(r) = d.rate {
            t.set_rate(r);
        }
        if let Some(w) = crate::pipeline::input::trial::mask_implausible(&mut t) {
            t.warnings.push(w);
        }
        return Ok(Box::new(t));
    }
    let mut header = file.trial.clone();
    let raw = FileFrames::new(file, header.clone(), Conform::default(), f64::INFINITY, window);
    let (_, conform) = decide_conventions(ctx, &raw, input);
    if let Some(r) = d.rate {
        header.set_rate(r);
    }
    Ok(Box::new(raw.reconform(header, conform, crate::pipeline::input::trial::MAX_COORDINATE_M)))
}

/// What one converted trial yields for the summary.
pub struct Solved {
    pub frames: usize,
    pub solve_s: f64,
    pub ms_per_frame: P50P90,
    pub iterations: P50P90,
    pub rmse_mm: Option<P50P90>,
    /// Why the result is `suspect` ([`crate::pipeline::results::verdict`]); recorded in the file's
    /// `smocap.run` metadata as `verdict` and `verdict_reason`.
    pub suspect: Option<String>,
    /// Label quality control events (recorded in the file's `smocap.run` as `label_qc`, JSON).
    pub label_qc: Vec<crate::pipeline::input::label_qc::LabelEvent>,
    /// Runs of unfittable frames ([`crate::pipeline::running::unfittable`]; the file's
    /// `/smocap/unfittable`), and the verdict's words for those blamed on the data.
    pub unfittable: Vec<Unfittable>,
    pub reason: Option<String>,
    /// What the trial's hook did ([`TrialJob::hook`]), when it had one.
    pub robot: Option<HookOutcome>,
}

/// Solves `job.trial` and streams it to `job.out` (via its `.partial` file); `job.run` is the `smocap.run`
/// metadata; `frames_done` counts frames as they are written (progress display). On any error
/// the temporary file is removed and no file has the final name. Solved on the caller's thread,
/// one lane, on the CPU backend.
pub fn solve_and_write(
    job: TrialJob<'_>,
    cal: &Calibrated,
    opt: &WriterOptions,
    frames_done: Option<&std::sync::atomic::AtomicU64>,
) -> Result<Solved, String> {
    let job = [job];
    solve_and_write_all(&job, cal, opt, frames_done, Solver { threads: 1, lanes: 1, backend: None })
        .pop()
        .expect("one result per trial")
}

/// One trial of [`solve_and_write_all`]: where it goes, its name, frames and `smocap.run`, and
/// the work done on its solved motion before its file is finished (`--robot`).
pub struct TrialJob<'a> {
    pub out: &'a Path,
    pub name: &'a str,
    pub trial: &'a dyn TrialFrames,
    pub run: &'a RunInfo,
    pub hook: Option<&'a dyn TrialHook>,
}

/// How [`solve_and_write_all`] solves: worker threads for the QPs, lanes of the scheduler, and
/// the evaluation backend (the CPU backend when `None`).
pub struct Solver<'b> {
    pub threads: usize,
    pub lanes: usize,
    pub backend: Option<&'b mut (dyn BatchBackend + 'b)>,
}

/// What a trial's sink keeps while its frames go to its writer thread.
struct Collect {
    tx: Option<std::sync::mpsc::SyncSender<Vec<SolvedFrame>>>,
    batch: Vec<SolvedFrame>,
    judge: Judge,
    /// Joint angles against what a person does (flips make the trial suspect).
    pose: crate::pipeline::results::plausibility::PoseCheck,
    ms: Vec<f64>,
    it: Vec<f64>,
    rmse: Vec<f64>,
    secs: f64,
}

impl Collect {
    fn take(&mut self, f: SolvedFrame) -> Result<(), SinkError> {
        self.judge.frame(f.index, &f.proxies, &f.stats, f.bridged);
        self.pose.frame(f.index, &f.proxies, !f.bridged && f.stats.status != crate::solve::FrameStatus::TooFewMarkers);
        if self.judge.nonfinite().is_some() {
            return Err("the solver's result is not finite".into());
        }
        self.secs += f.seconds;
        self.ms.push(f.seconds * 1e3);
        self.it.push(f.stats.iterations as f64);
        self.rmse.push(f.stats.rmse_m * 1e3);
        self.batch.push(f);
        if self.batch.len() == BATCH_FRAMES {
            let full = std::mem::replace(&mut self.batch, Vec::with_capacity(BATCH_FRAMES));
            // Fails only when the writer stopped, whose own error is the one reported.
            let tx = self.tx.as_ref().ok_or("the writer stopped")?;
            tx.send(full).map_err(|_| "the writer stopped")?;
        }
        Ok(())
    }
}

/// The writer thread's result: the file so far and the marker errors of its frames.
type Written<'w> = Result<(TrialWriter<'w>, MarkerErrors), (usize, McapOutError)>;
type Writing<'s, 'w> = std::thread::ScopedJoinHandle<'s, Written<'w>>;

/// [`solve_and_write`] for several trials of one subject solved together
/// ([`crate::pipeline::running::stream::solve_trials_streaming`]: their segments share the lanes, so
/// that short trials fill a batch of a device backend together); one writer thread per trial.
/// Each trial's file is the same as when it is solved alone. One result per trial, in order.
pub fn solve_and_write_all(
    jobs: &[TrialJob<'_>],
    cal: &Calibrated,
    opt: &WriterOptions,
    frames_done: Option<&std::sync::atomic::AtomicU64>,
    solver: Solver<'_>,
) -> Vec<Result<Solved, String>> {
    let ctx = cal.ctx();
    let mut results: Vec<Option<Result<Solved, String>>> = jobs.iter().map(|_| None).collect();
    std::thread::scope(|scope| {
        // Writers first: a trial whose file cannot be created is not solved.
        let mut live: Vec<(usize, Collect, Writing<'_, '_>)> = Vec::new();
        for (i, job) in jobs.iter().enumerate() {
            match start_writer(scope, job, cal, opt, frames_done) {
                Ok((tx, writing)) => {
                    let n = job.trial.header().n_frames();
                    let c = Collect {
                        tx: Some(tx),
                        batch: Vec::with_capacity(BATCH_FRAMES),
                        judge: Judge::default(),
                        pose: crate::pipeline::results::plausibility::PoseCheck::new(ctx),
                        ms: Vec::with_capacity(n),
                        it: Vec::with_capacity(n),
                        rmse: Vec::with_capacity(n),
                        secs: 0.0,
                    };
                    live.push((i, c, writing));
                }
                Err(e) => results[i] = Some(Err(e)),
            }
        }
        let started: Vec<usize> = live.iter().map(|(i, ..)| *i).collect();
        let solved = {
            let mut sinks: Vec<_> =
                live.iter_mut().map(|(_, c, _)| move |f: SolvedFrame| -> Result<(), SinkError> { c.take(f) }).collect();
            let streams = started
                .iter()
                .zip(sinks.iter_mut())
                .map(|(&i, sink)| TrialStream { name: jobs[i].name, trial: jobs[i].trial, sink })
                .collect();
            let Solver { threads, lanes, backend } = solver;
            solve_trials_streaming(ctx, streams, &cal.calibration, threads, lanes, backend)
        };
        // The trials finished (and their hooks run) in parallel on the run's pool.
        let finished: Vec<(usize, Result<Solved, String>)> = live
            .into_iter()
            .zip(solved)
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|((i, mut c, writing), solved)| {
                let mut solved = solved.map_err(|e| e.to_string());
                let tx = c.tx.take().expect("the sender is kept until the solve ends");
                if solved.is_ok() && !c.batch.is_empty() && tx.send(std::mem::take(&mut c.batch)).is_err() {
                    solved = Err("the writer stopped".into());
                }
                drop(tx);
                (i, finish_trial(&jobs[i], cal, solved, writing.join(), c))
            })
            .collect();
        for (i, r) in finished {
            results[i] = Some(r);
        }
    });
    results.into_iter().map(|r| r.expect("one result per trial")).collect()
}

/// Creates `job`'s file and starts its writer thread, fed batches of solved frames.
fn start_writer<'s, 'w>(
    scope: &'s std::thread::Scope<'s, 'w>,
    job: &'w TrialJob<'w>,
    cal: &'w Calibrated,
    opt: &WriterOptions,
    frames_done: Option<&'w std::sync::atomic::AtomicU64>,
) -> Result<(std::sync::mpsc::SyncSender<Vec<SolvedFrame>>, Writing<'s, 'w>), String> {
    let ctx = cal.ctx();
    if let Some(parent) = job.out.parent() {
        std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
    }
    let field = |k: &str| job.run.get(k).cloned().unwrap_or_default();
    let names = TrialNames { dataset: field("dataset"), subject: field("subject"), trial: field("trial") };
    let mut writer =
        TrialWriter::create(job.out, ctx, job.trial.header(), &cal.calibration, &names, job.trial.label_qc(), opt)
            .map_err(|e| e.to_string())?;
    if job.hook.is_some() {
        writer.keep_motion();
    }
    // The marker errors (unfittable frames) are accumulated on the writer thread, off the solver's.
    let mut errors = MarkerErrors::new(ctx, &cal.calibration);
    // Frames go over in batches of BATCH_FRAMES: one wake-up of the writer per batch, not
    // per frame (per-frame hand-over cost 7 % of a short trial's conversion in `perf`).
    let (tx, rx) = std::sync::mpsc::sync_channel::<Vec<SolvedFrame>>(QUEUE_FRAMES / BATCH_FRAMES);
    let writing = std::thread::Builder::new()
        .name("smocap-writer".into())
        .spawn_scoped(scope, move || -> Written<'w> {
            for batch in rx {
                for f in &batch {
                    writer.frame(f).map_err(|e| (f.index, e))?;
                    let unsolved = f.bridged || f.stats.status == crate::solve::FrameStatus::TooFewMarkers;
                    errors.frame(f.index, &f.proxies, &f.observed, unsolved);
                }
                if let Some(c) = frames_done {
                    c.fetch_add(batch.len() as u64, std::sync::atomic::Ordering::Relaxed);
                }
            }
            Ok((writer, errors))
        })
        .map_err(|e| format!("starting the writer thread: {e}"))?;
    Ok((tx, writing))
}

/// A trial's outcome once solved and written: its file finished (renamed to its final name) or
/// removed.
fn finish_trial(
    job: &TrialJob<'_>,
    cal: &Calibrated,
    solved: Result<crate::pipeline::StreamedTrial, String>,
    written: std::thread::Result<Written<'_>>,
    c: Collect,
) -> Result<Solved, String> {
    let name = job.name;
    let (mut writer, errors) = match written {
        Ok(Ok(w)) => w,
        Ok(Err((frame, e))) => return Err(format!("trial '{name}': frame {frame}: {e}")),
        Err(_) => return Err(format!("trial '{name}': the writer thread panicked")),
    };
    solved?;
    let mut run = job.run.clone();
    let qc = job.trial.label_qc();
    let mut doubts = c.pose.finish().suspect;
    if let Some(q) = qc {
        run.insert("label_qc".into(), serde_json::to_string(q).unwrap_or_default());
        doubts.extend(q.suspect.iter().cloned());
    }
    if !cal.suspect.is_empty() {
        doubts.push(format!("suspect calibration: {}", cal.suspect.join("; ")));
    }
    let verdict = match (c.judge.verdict(), doubts) {
        (v, pose) if pose.is_empty() => v,
        (Verdict::Ok, pose) => Verdict::Suspect(pose.join("; ")),
        (Verdict::Suspect(why), pose) => Verdict::Suspect(format!("{why}; {}", pose.join("; "))),
        (failed, _) => failed,
    };
    match &verdict {
        // Dropping the writer removes its temporary file.
        Verdict::Failed(why) => return Err(why.clone()),
        Verdict::Suspect(why) => {
            run.insert("verdict".into(), "suspect".into());
            run.insert("verdict_reason".into(), why.clone());
        }
        Verdict::Ok => {}
    }
    let unfittable = errors.finish().unfittable;
    writer.unfittable(&unfittable).map_err(|e| e.to_string())?;
    let work = job.hook.map(|h| (h, hook_work(h, job, cal, &mut writer)));
    writer.finish(&run, &cal.settings_json, cal.scaled_model.as_deref()).map_err(|e| e.to_string())?;
    // The hook's files once the trial's file is complete.
    let robot = work.map(|(h, w)| match w {
        Ok(w) => h.write(job.out, w),
        Err(why) => HookOutcome::failed(why),
    });
    let Collect { mut ms, it, mut rmse, secs, .. } = c;
    rmse.retain(|x: &f64| x.is_finite());
    ms.retain(|x: &f64| x.is_finite());
    Ok(Solved {
        frames: ms.len(),
        solve_s: secs,
        ms_per_frame: P50P90::of(&ms),
        iterations: P50P90::of(&it),
        rmse_mm: (!rmse.is_empty()).then(|| P50P90::of(&rmse)),
        suspect: verdict.reason(),
        label_qc: qc.map(|q| q.events.clone()).unwrap_or_default(),
        reason: crate::pipeline::running::unfittable::reason(&unfittable),
        unfittable,
        robot,
    })
}

/// Runs `hook` on the motion `writer` kept and writes the poses it returns into the file.
fn hook_work(
    hook: &dyn TrialHook,
    job: &TrialJob<'_>,
    cal: &Calibrated,
    writer: &mut TrialWriter<'_>,
) -> Result<HookWork, String> {
    let kept = writer.kept().cloned().unwrap_or_default();
    let name = job.out.file_stem().map_or(job.name.into(), |s| s.to_string_lossy().into_owned());
    let motion = SolvedMotion {
        name: &name,
        model: &cal.ctx().model,
        scales: writer.calibrated_scale(),
        q: &kept.q,
        times: &kept.times,
        frames: &kept.frames,
        world_from_model: writer.world_from_model(),
    };
    let work = hook.on_motion(&motion)?;
    let log_ns: Vec<u64> = work.track.frames.iter().map(|&f| writer.log_ns(f)).collect();
    let (w, file) = writer.raw();
    super::mcap_robot::write_track(w, &work.track, &log_ns, &file).map_err(|e| e.to_string())?;
    Ok(work)
}
