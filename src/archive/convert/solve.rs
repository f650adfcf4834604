//! Stages 3 and 4 of a conversion, per subject: its trials solved and written, one lane per
//! trial on the CPU (trials in parallel on the run's pool), or in batches through one backend
//! ([`batched`]: a device, or the CPU with `lanes` set).

use super::calibrate::Held;
use super::{failed, outcome, ConvertOptions, TrialOutcome, BATCH_HELD_FRAMES, BATCH_TRIALS};
use crate::archive::config::Dataset;
use crate::archive::discover::{SubjectGroup, TrialEntry};
use crate::archive::mcap_out::RunInfo;
use crate::archive::trial_job::{open_for, solve_and_write, solve_and_write_all, Calibrated, Solver, TrialJob};
use crate::kinematics::backend::BatchBackend;
use crate::pipeline::input::convention::InputOptions;
use crate::pipeline::input::frames::TrialFrames;
use crate::pipeline::running::device::Chosen;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Solves and writes a subject's trials `todo` with its calibration `cal`; `report` receives
/// each outcome as it is known. Err: no backend for the subject (every trial fails with it).
#[allow(clippy::too_many_arguments)]
pub(super) fn solve_all(
    d: &Dataset,
    g: &SubjectGroup,
    todo: &[super::plan::Todo<'_>],
    input: &InputOptions,
    held: &Held,
    cal: &Calibrated,
    opt: &ConvertOptions,
    report: &(dyn Fn(&TrialOutcome) + Sync),
    log: &(dyn Fn(&str) + Sync),
) -> Result<Vec<TrialOutcome>, String> {
    // The backend holds the model (on the device for wgpu): chosen once the markers are final.
    let pinned = cal.ctx().pinned_to(&cal.calibration);
    let chosen = match crate::pipeline::running::device::choose(
        opt.backend,
        &pinned.evaluator(),
        crate::kinematics::gpu::DEFAULT_CAP,
    ) {
        Ok(c) => c,
        Err(e) => return Err(format!("evaluation backend: {e}")),
    };
    drop(pinned);
    if let Some(note) = chosen.note() {
        log(&format!("note: {}/{}: {note}", d.name, g.subject));
    }
    let solved = match (chosen, opt.lanes) {
        (Chosen::Cpu { .. }, None) => todo
            .par_iter()
            .map(|(t, out, hash)| {
                let o = solve_one(d, g, t, out, hash, input, held, cal, opt);
                report(&o);
                o
            })
            .collect(),
        (Chosen::Cpu { .. }, Some(lanes)) => batched(d, g, todo, input, held, cal, opt, None, lanes, report),
        (Chosen::Wgpu(mut b), lanes) => {
            let device = b.device();
            let lanes = lanes.unwrap_or(4096);
            let backend = Some((b.as_mut() as &mut dyn BatchBackend, device.as_str()));
            batched(d, g, todo, input, held, cal, opt, backend, lanes, report)
        }
    };
    Ok(solved)
}

/// Consecutive runs `[i0, i1)` of trials of `frames` frames solved together: until their
/// segments fill `lanes`, they would hold more than [`BATCH_HELD_FRAMES`], or there are
/// [`BATCH_TRIALS`] of them.
pub fn batches(frames: &[u64], lanes: usize, window: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let (mut i0, mut segs, mut held) = (0, 0, 0);
    for (i, &n) in frames.iter().enumerate() {
        let n = usize::try_from(n).unwrap_or(usize::MAX);
        let (s, h) = (crate::pipeline::running::stream::segment_count(n), n.min(window));
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
    held: &Held,
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
            match frames_of(d, t, input, held, cal, opt) {
                Ok(trial) => {
                    let run = run_info(d, g, t, hash, cal, trial.get(), opt, (name, device));
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
            .map(|(t, out, trial, run)| TrialJob {
                out: out.as_path(),
                name: &t.rel,
                trial: trial.get(),
                run,
                hook: opt.hook.as_deref(),
            })
            .collect();
        let solver = Solver { threads: opt.jobs, lanes, backend: backend.as_mut().map(|(b, _)| &mut **b as _) };
        let progress = opt.progress.as_deref().map(|p| &p.frames_done);
        let results = solve_and_write_all(&jobs, cal, &opt.writer, progress, solver);
        let done: Vec<TrialOutcome> = opened
            .iter()
            .zip(results)
            .map(|((t, out, ..), r)| {
                let o = trial_outcome(d, g, t, out, r, &summary);
                report(&o);
                o
            })
            .collect();
        outcomes.extend(done);
    }
    outcomes
}

/// A converted trial's outcome, with its hook's ([`super::TrialHook`]).
fn trial_outcome(
    d: &Dataset,
    g: &SubjectGroup,
    t: &TrialEntry,
    out: &Path,
    r: Result<crate::archive::trial_job::Solved, String>,
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
            unfittable: s.unfittable.clone(),
            reason: s.reason.clone(),
            robot: s.robot.clone(),
            body: None,
            ..outcome(d, g, t, out, if s.suspect.is_some() { "suspect" } else { "ok" }, s.suspect.clone())
        },
        Err(e) => failed(d, g, t, out, e),
    }
}

/// A trial's frames for the solve: held from calibration, or read now.
enum Frames<'h> {
    Held(&'h dyn TrialFrames),
    Read(Box<dyn TrialFrames>),
}

impl Frames<'_> {
    fn get(&self) -> &dyn TrialFrames {
        match self {
            Frames::Held(t) => *t,
            Frames::Read(t) => t.as_ref(),
        }
    }
}

/// Trial `t`'s frames: those calibration read and held whole (`held`, read and screened with the
/// same context: the same frames and label events), else read and screened now.
fn frames_of<'h>(
    d: &Dataset,
    t: &TrialEntry,
    input: &InputOptions,
    held: &'h Held,
    cal: &Calibrated,
    opt: &ConvertOptions,
) -> Result<Frames<'h>, String> {
    match held.get(&t.rel) {
        Some(h) => Ok(Frames::Held(h.as_ref())),
        None => open_for(d, &cal.base, &t.path, input, opt.window_frames).map(Frames::Read),
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
    held: &Held,
    cal: &Calibrated,
    opt: &ConvertOptions,
) -> TrialOutcome {
    let (writer, progress) = (&opt.writer, opt.progress.as_deref());
    let trial = match frames_of(d, t, input, held, cal, opt) {
        Ok(m) => m,
        Err(e) => return failed(d, g, t, out, e),
    };
    let run = run_info(d, g, t, hash, cal, trial.get(), opt, ("cpu", "cpu"));
    let frames_done = progress.map(|p| &p.frames_done);
    let job = TrialJob { out, name: &t.rel, trial: trial.get(), run: &run, hook: opt.hook.as_deref() };
    let r = solve_and_write(job, cal, writer, frames_done);
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
        ("settings_sha256", &crate::archive::sha256_hex(cal.settings_json.as_bytes())),
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
    // what the body mesh is shaped to (`export --gltf/--mesh`): calibrated stature, given subject
    let sub = &ctx.subject;
    let sex = sub.sex.map(|s| if s == crate::model::anthropometry::Sex::Male { "male" } else { "female" });
    for (k, v) in [
        ("subject_stature_m", cal.calibration.prior.stature_m.map(|h| format!("{h}"))),
        ("subject_height_m", sub.height_m.map(|h| format!("{h}"))),
        ("subject_mass_kg", sub.mass_kg.map(|m| format!("{m}"))),
        ("subject_sex", sex.map(String::from)),
    ] {
        if let Some(v) = v {
            run.insert(k.into(), v);
        }
    }
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
