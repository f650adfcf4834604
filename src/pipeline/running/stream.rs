//! Solving one trial frame by frame: each frame goes to a sink as soon as it and the frames before
//! it are solved, so a writer can stream results out without holding the trial's results.
//!
//! Frames leave in frame order. Frames with too few markers, and proxies that a frame's markers do
//! not observe, wait until a later frame observes them (they are bridged between the neighbours
//! that did, see [`crate::pipeline::running::order`]); with several lanes,
//! frames of later segments wait for the earlier segments. With one lane (what `smocap convert`
//! uses on the CPU backend), what is held beyond the input trial is the current gap of unsolved
//! frames. Several trials of one subject can be solved together ([`solve_trials_streaming`]),
//! their segments sharing the lanes, each trial's frames still leaving in its own frame order.

use crate::io::MarkerTrial;
use crate::kinematics::assembly::Evaluator;
use crate::kinematics::backend::{BatchBackend, CpuBackend};
use crate::model::proxy::ProxyKind;
use crate::pipeline::context::Context;
use crate::pipeline::input::frames::{for_each_window, TrialFrames};
use crate::pipeline::input::matching::MarkerMatch;
use crate::pipeline::input::trial::{match_markers, no_match, GapRuns, SinkError, TrialError};
use crate::pipeline::running::continuity::JumpLimits;
use crate::pipeline::running::lanes::{
    resolve_flips, resolve_outliers_above, run_lanes_across, FrameObservations, FrameResult, TrialInputs,
};
use crate::pipeline::running::order::Orderer;
use crate::pipeline::running::sink::{FrameSink, SolvedFrame, Stop};
use crate::pipeline::running::trial::TrialResult;
use crate::pipeline::stats::GapStats;
use crate::solve::{Calibration, FrameStatus, Presolve, SolverSettings};
use rayon::prelude::*;
use std::borrow::Cow;
use std::time::Instant;

/// What is known of a trial once all its frames went to the sink.
#[derive(Clone, Debug)]
pub struct StreamedTrial {
    pub name: String,
    pub frames: usize,
    /// Frames bridged from neighbours.
    pub bridged: usize,
    pub unmatched_model: Vec<String>,
    pub unmatched_trial: Vec<String>,
    /// `(file label, model marker)` for markers matched other than exactly.
    pub renamed: Vec<(String, String)>,
    pub gaps: GapStats,
    /// Frames whose result came from the `auto` pre-solve pass (outliers solved again).
    pub presolved: Vec<usize>,
    /// Wall time of all frames (s), calibration excluded, sink included (of trials solved
    /// together, [`solve_trials_streaming`]: of them all).
    pub wall_seconds: f64,
    pub threads: usize,
}

/// Frames per segment (at least; a trial of `n` frames has `max(1, n / SEGMENT_FRAMES)`
/// segments of equal length ± 1). Segments are solved in parallel (one lane each at a time).
pub const SEGMENT_FRAMES: usize = 200;
/// Frames before a segment's first one that its lane solves first (cold-started at the first of
/// them) and does not hand on, so that the segment starts warm, from a tracked pose, as the frame
/// would in an uncut trial. Measured against the same trials solved uncut (BENCHMARKS.md,
/// 2026-12-03, `cold3`): with 10 frames a segment's frames differ from the uncut solve's by at most
/// 1e-12° on synthetic walks and pirouettes (as with 20), with 5 by up to 1e-9°.
pub const SEGMENT_RUN_IN: usize = 10;

/// How many [`segments`] a trial of `n` frames has: `max(1, n / SEGMENT_FRAMES)`.
pub fn segment_count(n: usize) -> usize {
    (n / SEGMENT_FRAMES).max(1)
}

/// The segments of a trial of `n` frames: `[a, b)` ranges covering `0..n`, a function of `n`
/// alone (see [`SEGMENT_FRAMES`]).
pub fn segments(n: usize) -> Vec<(usize, usize)> {
    let k = segment_count(n);
    (0..k).map(|i| (i * n / k, (i + 1) * n / k)).collect()
}

/// Solves every frame of `trial` like [`crate::pipeline::running::stream::solve_trial_with`], handing each frame to `sink`
/// in frame order as soon as it is known. An error from `sink` stops the solve
/// ([`TrialError::Output`]). [`solve_trials_streaming`] with one trial.
#[allow(clippy::too_many_arguments)]
pub fn solve_trial_streaming(
    ctx: &Context,
    name: &str,
    trial: &dyn TrialFrames,
    calibration: &Calibration,
    threads: usize,
    lanes: usize,
    backend: Option<&mut (dyn BatchBackend + '_)>,
    sink: &mut FrameSink<'_>,
) -> Result<StreamedTrial, TrialError> {
    let one = vec![TrialStream { name, trial, sink }];
    solve_trials_streaming(ctx, one, calibration, threads, lanes, backend).pop().expect("one result per trial")
}

/// One trial of [`solve_trials_streaming`]: its name, its frames and where its solved frames go.
pub struct TrialStream<'a, 's> {
    pub name: &'a str,
    pub trial: &'a dyn TrialFrames,
    pub sink: &'a mut FrameSink<'s>,
}

/// A trial being solved by [`solve_trials_streaming`].
struct Job<'a, 's, 'c> {
    /// Index of the trial in the caller's list.
    index: usize,
    name: &'a str,
    trial: &'a dyn TrialFrames,
    sink: &'a mut FrameSink<'s>,
    runs: GapRuns,
    n: usize,
    /// Its segments, and the runs of them read together (one window each).
    bounds: Vec<(usize, usize)>,
    groups: Vec<(usize, usize)>,
    order: Orderer<'c>,
    /// `auto` pre-solve: every solved frame, held until the pass ([`resolve_outliers_above`]).
    held: Vec<Option<FrameResult>>,
    presolved: Vec<usize>,
    /// Why it stopped (its frames still in flight are then dropped).
    failed: Option<TrialError>,
}

/// Solves several trials of one subject (one calibration, one evaluator, one `backend`) together,
/// each like [`solve_trial_streaming`]: the segments of all of them go into one lane scheduler
/// ([`run_lanes_across`]), so that every batched evaluation holds lanes of several trials, and
/// each trial's frames go to its own sink in frame order. Returns one result per trial, in
/// order; a trial whose sink fails, or whose file cannot be read, fails alone (its frames still in
/// flight are solved and dropped), a backend error fails every trial it was solving.
///
/// Every segment is walked as when its trial is solved alone, so each trial's frames are the
/// same, bit for bit, however trials are grouped and whatever `lanes` and `threads` are. What is
/// held is one window of each trial at a time: long trials (more than
/// [`TrialFrames::window_frames`]) are solved a window after another, the windows of all trials
/// at step `k` together; with `auto` pre-solve each trial also holds its solved frames (proxies
/// and statistics) until its pass, as [`solve_trial_streaming`] does, the passes of the trials
/// running in parallel once every lane has finished.
pub fn solve_trials_streaming(
    ctx: &Context,
    trials: Vec<TrialStream<'_, '_>>,
    calibration: &Calibration,
    threads: usize,
    lanes: usize,
    backend: Option<&mut (dyn BatchBackend + '_)>,
) -> Vec<Result<StreamedTrial, TrialError>> {
    let start = Instant::now();
    // One morphology: every frame is solved at the calibrated scales and marker offsets.
    let pinned = ctx.pinned_to(calibration);
    let ctx = &pinned;
    let settings = &ctx.settings;
    let auto = settings.presolve == Presolve::Auto;
    let mut results: Vec<Option<Result<StreamedTrial, TrialError>>> = trials.iter().map(|_| None).collect();
    let mut matches = Vec::new();
    let mut jobs = Vec::new();
    for (index, TrialStream { name, trial, sink }) in trials.into_iter().enumerate() {
        match prepare(ctx, name, trial) {
            Ok((matched, runs)) => {
                let n = trial.header().n_frames();
                let bounds = segments(n);
                let groups = segment_groups(&bounds, trial.window_frames());
                matches.push(matched);
                jobs.push(Job {
                    index,
                    name,
                    trial,
                    sink,
                    runs,
                    n,
                    bounds,
                    groups,
                    order: Orderer::new(ctx, &calibration.proxies),
                    held: if auto { vec![None; n] } else { Vec::new() },
                    presolved: Vec::new(),
                    failed: None,
                });
            }
            Err(e) => results[index] = Some(Err(e)),
        }
    }
    if jobs.is_empty() {
        return results.into_iter().map(|r| r.expect("one result per trial")).collect();
    }
    let eval = ctx.evaluator();

    // Segments, one lane each at a time: fixed by the frame count alone, so that the result does
    // not depend on the lane or thread count. Consecutive segments are read together, as many as
    // fit in a window of the trial (all of them when it is held whole); each segment is solved
    // as it would be in the whole trial, so the result does not depend on the window either.
    let threads = threads.max(1);
    let lanes = lanes.max(1);
    let shared = SubjectInputs::new(ctx, calibration);
    let base = &shared;
    // One thread and one lane run on the caller's thread: no pool to start, and no waiting on
    // one during which a caller's rayon worker would take up other work (e.g. another trial).
    let pool =
        (threads > 1 || lanes > 1).then(|| rayon::ThreadPoolBuilder::new().num_threads(threads).build().ok()).flatten();
    let parallel = pool.is_some();
    let mut backend = backend;
    let mut run = || {
        let mut cpu = None;
        let steps = jobs.iter().map(|j| j.groups.len()).max().unwrap_or(0);
        for step in 0..steps {
            // Group `step` of every trial still going: its window and its segments in it.
            let mut wins = Vec::new();
            let mut segs = Vec::new();
            for (j, job) in jobs.iter_mut().enumerate() {
                let Some(&(g0, g1)) = job.groups.get(step).filter(|_| job.failed.is_none()) else { continue };
                let trial = job.trial;
                match window(trial, &job.bounds[g0..g1]) {
                    Ok((w0, w, rel)) => {
                        segs.extend(rel.into_iter().map(|s| (wins.len(), s)));
                        wins.push((j, w0, w));
                    }
                    Err(why) => job.failed = Some(TrialError::Read { trial: job.name.into(), why }),
                }
            }
            if wins.is_empty() {
                continue;
            }
            let inputs: Vec<TrialInputs<'_>> = wins
                .iter()
                .map(|(j, _, w)| base.inputs(FrameObservations { trial: w, map: &matches[*j].columns }))
                .collect();
            let mut done = |k: usize, f: usize, r: FrameResult| -> Result<(), Stop> {
                let (j, w0, _) = wins[k];
                let job = &mut jobs[j];
                if job.failed.is_some() {
                    return Ok(());
                }
                if auto {
                    job.held[f + w0] = Some(r);
                    return Ok(());
                }
                if let Err(e) = job.order.push(f + w0, r, (&inputs[k].observed, w0), job.sink) {
                    job.failed = Some(e.into_error(job.name));
                    // Nothing left to solve for: stop at once (a trial solved alone stops so).
                    if wins.iter().all(|(j, ..)| jobs[*j].failed.is_some()) {
                        return Err(Stop::AllFailed);
                    }
                }
                Ok(())
            };
            let b: &mut dyn BatchBackend = match backend.as_deref_mut() {
                Some(b) => b,
                None => cpu.get_or_insert_with(|| CpuBackend::new(eval.clone())),
            };
            match run_lanes_across(&eval, settings, &inputs, &segs, SEGMENT_RUN_IN, lanes, b, &mut done) {
                Ok(()) | Err(Stop::AllFailed) => {}
                Err(e) => {
                    for &(j, ..) in &wins {
                        let job = &mut jobs[j];
                        if job.failed.is_none() {
                            job.failed = Some(e.copy().into_error(job.name));
                        }
                    }
                }
            }
        }
        if auto {
            let pass = |(job, m): (&mut Job<'_, '_, '_>, &MarkerMatch)| {
                if job.failed.is_none() {
                    if let Err(e) = presolve_pass(job, m, &eval, settings, base) {
                        job.failed = Some(e.into_error(job.name));
                    }
                }
            };
            // In parallel on the run's pool; without one, on the caller's thread.
            if parallel {
                jobs.par_iter_mut().zip(matches.par_iter()).for_each(pass);
            } else {
                jobs.iter_mut().zip(&matches).for_each(pass);
            }
        }
    };
    match &pool {
        Some(pool) => pool.install(run),
        None => run(),
    }
    for (job, matched) in jobs.into_iter().zip(&matches) {
        let index = job.index;
        results[index] = Some(finish(ctx, job, matched, start, threads));
    }
    results.into_iter().map(|r| r.expect("one result per trial")).collect()
}

/// What every trial of a subject shares in its [`TrialInputs`].
/// What every frame of a subject's trials is solved against, on `ctx` pinned to its calibration:
/// tracking (scales toward the calibration, coordinates weakly toward the warm start, coordinate
/// targets folded into the pose prior's reference: the same objective up to a constant), the
/// cold-start pose, the calibration's proxies.
pub struct SubjectInputs<'a> {
    marker_weights: &'a [f64],
    reference: Vec<f64>,
    tracking_weights: Vec<f64>,
    coordinate_targets: Vec<f64>,
    coordinate_weights: Vec<f64>,
    tracking_weights_all: Vec<f64>,
    /// Neutral pose at the calibrated morphology.
    neutral: Vec<f64>,
    calibrated: &'a [f64],
}

impl<'a> SubjectInputs<'a> {
    pub fn new(ctx: &'a Context, calibration: &'a Calibration) -> Self {
        let settings = &ctx.settings;
        let mut tracking_weights = vec![0.0; ctx.model.ny()];
        for t in &ctx.proxy.terms {
            let kind = ctx.proxy.proxies[t.proxy].kind;
            tracking_weights[t.y_index] =
                if kind == ProxyKind::Scale { settings.scale_tracking_weight } else { settings.pose_prior_weight };
        }
        let (coordinate_targets, coordinate_weights) = ctx.coordinate_tracking();
        let tracking_weights_all = tracking_weights.iter().zip(&coordinate_weights).map(|(a, b)| a + b).collect();
        let mut neutral = ctx.proxy.default_proxies();
        for (k, px) in ctx.proxy.proxies.iter().enumerate() {
            if px.kind == ProxyKind::Scale {
                neutral[k] = calibration.proxies[k];
            }
        }
        SubjectInputs {
            marker_weights: &ctx.marker_weights,
            reference: ctx.proxy.state(&calibration.proxies),
            tracking_weights,
            coordinate_targets,
            coordinate_weights,
            tracking_weights_all,
            neutral,
            calibrated: &calibration.proxies,
        }
    }

    /// The inputs of a trial (or a window of it) observed as `observed`.
    pub fn inputs<'b>(&'b self, observed: FrameObservations<'b>) -> TrialInputs<'b> {
        TrialInputs {
            observed,
            marker_weights: self.marker_weights,
            reference: &self.reference,
            tracking_weights: &self.tracking_weights,
            coordinate_targets: &self.coordinate_targets,
            coordinate_weights: &self.coordinate_weights,
            tracking_weights_all: &self.tracking_weights_all,
            neutral: &self.neutral,
            calibrated: self.calibrated,
        }
    }
}

/// A trial's markers matched to the model's, and one pass over its frames before solving: each
/// column's gaps, and an error when no frame has enough markers.
fn prepare(ctx: &Context, name: &str, trial: &dyn TrialFrames) -> Result<(MarkerMatch, GapRuns), TrialError> {
    let header = trial.header();
    let matched = match_markers(ctx, name, header)?;
    let map = &matched.columns;
    if map.iter().all(Option::is_none) {
        return Err(no_match(ctx, name, header));
    }
    if header.n_frames() == 0 {
        return Err(TrialError::Empty { trial: name.into() });
    }
    let mut solvable = 0;
    let mut runs = GapRuns::new(header.n_markers());
    for_each_window(trial, |_, w| {
        solvable += crate::pipeline::input::trial::solvable_frames(ctx, w, map);
        runs.add(w);
    })
    .map_err(|why| TrialError::Read { trial: name.into(), why })?;
    if solvable == 0 {
        return Err(TrialError::NothingSolvable { trial: name.into(), min: ctx.settings.min_markers });
    }
    Ok((matched, runs))
}

/// Frames `[w0, b)` of `trial` for the segments `segs`, and those segments within it.
type Window<'a> = (usize, Cow<'a, MarkerTrial>, Vec<(usize, usize)>);

fn window<'a>(trial: &'a dyn TrialFrames, segs: &[(usize, usize)]) -> Result<Window<'a>, String> {
    let (a, b) = (segs[0].0, segs[segs.len() - 1].1);
    let w0 = a.saturating_sub(SEGMENT_RUN_IN);
    let rel: Vec<(usize, usize)> = segs.iter().map(|&(a, b)| (a - w0, b - w0)).collect();
    trial.window(w0..b).map(|w| (w0, w, rel))
}

/// The `auto` pre-solve pass of a trial whose lanes have all finished (its window by window),
/// handing every frame on in order.
fn presolve_pass(
    job: &mut Job<'_, '_, '_>,
    matched: &MarkerMatch,
    eval: &Evaluator<'_>,
    settings: &SolverSettings,
    base: &SubjectInputs<'_>,
) -> Result<(), Stop> {
    let threshold = outlier_threshold_of(&job.held);
    let fits: Vec<Option<(&[f64], f64)>> = job
        .held
        .iter()
        .map(|r| r.as_ref().filter(|r| r.1.status != FrameStatus::TooFewMarkers).map(|r| (&r.0[..], r.1.rmse_m)))
        .collect();
    let limits = JumpLimits::of(eval.proxy, job.trial.header().rate_hz, &fits);
    for &(g0, g1) in &job.groups {
        let (w0, w, rel) = window(job.trial, &job.bounds[g0..g1]).map_err(Stop::Read)?;
        let obs = FrameObservations { trial: &w, map: &matched.columns };
        let inputs = base.inputs(obs);
        let end = job.bounds[g1 - 1].1;
        let mut kept = resolve_outliers_above(eval, settings, &inputs, &rel, threshold, &mut job.held[w0..end]);
        kept.extend(crate::pipeline::running::jumps::resolve_unfittable_jumps(
            eval,
            settings,
            &inputs,
            &limits,
            &mut job.held[w0..end],
        ));
        kept.extend(resolve_flips(eval, settings, &inputs, &mut job.held[w0..end]));
        kept.sort_unstable();
        kept.dedup();
        job.presolved.extend(kept.into_iter().map(|f| f + w0));
        for f in job.bounds[g0].0..end {
            let r = job.held[f].take().expect("every frame lies in one segment");
            job.order.push(f, r, (&obs, w0), job.sink)?;
        }
    }
    Ok(())
}

/// A trial's result once all its frames are solved: the last bridged frames handed on, and what
/// is known of it.
fn finish(
    ctx: &Context,
    mut job: Job<'_, '_, '_>,
    matched: &MarkerMatch,
    start: Instant,
    threads: usize,
) -> Result<StreamedTrial, TrialError> {
    if let Some(e) = job.failed.take() {
        return Err(e);
    }
    debug_assert!(job.order.early.is_empty() && job.order.next == job.n, "every frame lies in one segment");
    job.order.finish(job.sink).map_err(|e| e.into_error(job.name))?;
    let header = job.trial.header();
    let names: Vec<&str> = ctx.model.markers.iter().map(|m| m.name.as_str()).collect();
    let renamed = matched.renamed(&names, &header.labels).into_iter().map(|(a, b)| (a.into(), b.into())).collect();
    let bridged = job.order.bridged;
    let gaps = job.runs.stats(ctx, &matched.columns, job.n, bridged);
    Ok(StreamedTrial {
        name: job.name.into(),
        frames: job.n,
        bridged,
        unmatched_model: matched.unmatched_model.clone(),
        unmatched_trial: matched.unmatched_trial.clone(),
        renamed,
        gaps,
        presolved: std::mem::take(&mut job.presolved),
        wall_seconds: start.elapsed().as_secs_f64(),
        threads,
    })
}

/// Consecutive runs `[g0, g1)` of `segments` whose frames fit in `window` frames (at least one
/// segment each), covering them all.
fn segment_groups(segments: &[(usize, usize)], window: usize) -> Vec<(usize, usize)> {
    let mut groups = Vec::new();
    let mut g0 = 0;
    for (i, &(_, b)) in segments.iter().enumerate() {
        let next_end = segments.get(i + 1).map(|s| s.1);
        let a = segments[g0].0.saturating_sub(SEGMENT_RUN_IN);
        if next_end.is_none_or(|e| e - a > window) {
            groups.push((g0, i + 1));
            g0 = i + 1;
        }
        let _ = b;
    }
    groups
}

/// The `auto` pre-solve's outlier threshold over the frames solved (not bridged).
fn outlier_threshold_of(held: &[Option<FrameResult>]) -> f64 {
    let rmse: Vec<f64> = held
        .iter()
        .filter_map(|r| r.as_ref().filter(|r| r.1.status != FrameStatus::TooFewMarkers).map(|r| r.1.rmse_m))
        .collect();
    crate::pipeline::running::unfittable::presolve_threshold(&rmse)
}

/// Solves every frame of `trial` for a subject calibrated as `calibration` on the CPU backend,
/// with `threads` worker threads and as many lanes.
pub fn solve_trial(
    ctx: &Context,
    name: &str,
    trial: &MarkerTrial,
    calibration: &Calibration,
    threads: usize,
) -> Result<TrialResult, TrialError> {
    solve_trial_with(ctx, name, trial, calibration, threads, threads, None)
}

/// Solves every frame of `trial` with the lane scheduler ([`crate::pipeline::running::lanes`]): the trial is cut
/// into [`segments`] of at least [`SEGMENT_FRAMES`] frames (whatever `lanes` and `threads`), each
/// walked by one lane from [`SEGMENT_RUN_IN`] frames before its start; evaluations go to `backend` (the CPU backend when `None`), the QPs to a pool of
/// `threads` threads. Collects what [`solve_trial_streaming`] hands on frame by frame.
pub fn solve_trial_with(
    ctx: &Context,
    name: &str,
    trial: &MarkerTrial,
    calibration: &Calibration,
    threads: usize,
    lanes: usize,
    backend: Option<&mut (dyn BatchBackend + '_)>,
) -> Result<TrialResult, TrialError> {
    let n = trial.n_frames();
    let mut proxies = Vec::with_capacity(n);
    let mut stats = Vec::with_capacity(n);
    let mut frame_seconds = Vec::with_capacity(n);
    let mut bridged = Vec::new();
    let mut errors = crate::pipeline::running::marker_errors::MarkerErrors::new(ctx, calibration);
    let mut sink = |f: SolvedFrame| -> Result<(), SinkError> {
        errors.frame(f.index, &f.proxies, &f.observed, f.bridged || f.stats.status == FrameStatus::TooFewMarkers);
        if f.bridged {
            bridged.push(f.index);
        }
        proxies.push(f.proxies);
        stats.push(f.stats);
        frame_seconds.push(f.seconds);
        Ok(())
    };
    let s = solve_trial_streaming(ctx, name, trial, calibration, threads, lanes, backend, &mut sink)?;
    Ok(TrialResult {
        name: s.name,
        proxies,
        stats,
        frame_seconds,
        calibration: calibration.clone(),
        bridged,
        presolved: s.presolved,
        unmatched_model: s.unmatched_model,
        unmatched_trial: s.unmatched_trial,
        renamed: s.renamed,
        gaps: s.gaps,
        wall_seconds: s.wall_seconds,
        threads: s.threads,
        marker_errors: errors.finish(),
    })
}
