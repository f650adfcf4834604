//! Solving one trial frame by frame: each frame goes to a sink as soon as it and the frames before
//! it are solved, so a writer can stream results out without holding the trial's results.
//!
//! Frames leave in frame order. Frames with too few markers wait until the next solved frame
//! (they are bridged between their solved neighbours, see [`super::trial`]); with several lanes,
//! frames of later segments wait for the earlier segments. With one lane (what `smocap convert`
//! uses), what is held beyond the input trial is the current gap of unsolved frames.

use super::frames::{for_each_window, TrialFrames};
use super::lanes::{resolve_outliers_above, run_lanes, FrameObservations, FrameResult, TrialInputs};
use super::stats::GapStats;
use super::trial::{match_markers, no_match, GapRuns, SinkError, TrialError, TrialResult};
use super::Context;
use crate::io::MarkerTrial;
use crate::kinematics::backend::{BackendError, BatchBackend, CpuBackend};
use crate::model::proxy::ProxyKind;
use crate::solve::init::wrap_angle;
use crate::solve::{Calibration, FrameStats, FrameStatus, Presolve};
use std::collections::BTreeMap;
use std::time::Instant;

/// Where solved frames go.
pub type FrameSink<'a> = dyn FnMut(SolvedFrame) -> Result<(), SinkError> + Send + 'a;

/// One solved frame.
#[derive(Clone, Debug)]
pub struct SolvedFrame {
    /// Frame index in the trial (0-based).
    pub index: usize,
    pub proxies: Vec<f64>,
    /// Statistics (a bridged frame has status `TooFewMarkers`).
    pub stats: FrameStats,
    /// Solve time (s, wall), as [`super::TrialResult::frame_seconds`].
    pub seconds: f64,
    /// Bridged from its neighbours because too few markers were observed.
    pub bridged: bool,
    /// The frame's observed markers in model-marker order (3 per marker, m, NaN where not
    /// observed), as the solver read them.
    pub observed: Vec<f64>,
}

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
    /// Wall time of all frames (s), calibration excluded, sink included.
    pub wall_seconds: f64,
    pub threads: usize,
}

enum Stop {
    Backend(BackendError),
    Sink(usize, SinkError),
    Read(String),
}

impl From<BackendError> for Stop {
    fn from(e: BackendError) -> Stop {
        Stop::Backend(e)
    }
}

/// Puts frames in order and bridges frames with too few markers before handing them on.
struct Orderer<'a> {
    ctx: &'a Context,
    calibrated: &'a [f64],
    next: usize,
    /// Finished ahead of `next` (several lanes), with their observations.
    early: BTreeMap<usize, (FrameResult, Vec<f64>)>,
    /// The last solved frame handed on.
    last: Option<(usize, Vec<f64>)>,
    /// Frames with too few markers waiting for the next solved frame.
    gap: Vec<(usize, FrameResult, Vec<f64>)>,
    bridged: usize,
}

impl Orderer<'_> {
    /// Takes frame `f`'s result; `obs` is the window it lies in, frame `f` at `f - first`.
    fn push(
        &mut self,
        f: usize,
        r: FrameResult,
        obs: (&FrameObservations<'_>, usize),
        sink: &mut FrameSink<'_>,
    ) -> Result<(), Stop> {
        let mut observed = vec![0.0; 3 * obs.0.map.len()];
        obs.0.fill(f - obs.1, &mut observed);
        self.early.insert(f, (r, observed));
        while let Some((r, observed)) = self.early.remove(&self.next) {
            let f = self.next;
            self.next += 1;
            if r.1.status == FrameStatus::TooFewMarkers {
                self.gap.push((f, r, observed));
                continue;
            }
            self.flush(Some((f, r.0.as_slice())), sink)?;
            self.last = Some((f, r.0.clone()));
            let (proxies, stats, seconds) = r;
            sink(SolvedFrame { index: f, proxies, stats, seconds, bridged: false, observed })
                .map_err(|e| Stop::Sink(f, e))?;
        }
        Ok(())
    }

    /// Bridges the waiting frames between the last solved frame and `after`, and hands them on.
    fn flush(&mut self, after: Option<(usize, &[f64])>, sink: &mut FrameSink<'_>) -> Result<(), Stop> {
        let before = self.last.as_ref().map(|(g, p)| (*g, p.as_slice()));
        for (f, (_, stats, seconds), observed) in std::mem::take(&mut self.gap) {
            let proxies = bridge(self.ctx, f, before, after, self.calibrated);
            self.bridged += 1;
            sink(SolvedFrame { index: f, proxies, stats, seconds, bridged: true, observed })
                .map_err(|e| Stop::Sink(f, e))?;
        }
        Ok(())
    }
}

/// Proxies of frame `f` interpolated between the solved frames `before` and `after` (the nearer
/// one's when only one exists; the calibration's when neither does).
fn bridge(
    ctx: &Context,
    f: usize,
    before: Option<(usize, &[f64])>,
    after: Option<(usize, &[f64])>,
    calibrated: &[f64],
) -> Vec<f64> {
    match (before, after) {
        (Some((g0, a)), Some((g1, b))) => {
            let w = (f - g0) as f64 / (g1 - g0) as f64;
            (0..a.len())
                .map(|k| {
                    // Unbounded angles (a root heading) go the short way round.
                    let px = &ctx.proxy.proxies[k];
                    let unbounded = px.range.0 == f64::NEG_INFINITY && px.range.1 == f64::INFINITY;
                    let d = b[k] - a[k];
                    let d = if px.kind == ProxyKind::Rotation && unbounded { wrap_angle(d) } else { d };
                    a[k] + w * d
                })
                .collect()
        }
        (Some((_, p)), None) | (None, Some((_, p))) => p.to_vec(),
        (None, None) => calibrated.to_vec(),
    }
}

/// Frames per segment (at least; a trial of `n` frames has `max(1, n / SEGMENT_FRAMES)`
/// segments of equal length ± 1). Segments are solved in parallel (one lane each at a time).
pub const SEGMENT_FRAMES: usize = 200;
/// Frames before a segment's first one that its lane solves first (cold-started at the first of
/// them) and does not hand on, so that the segment starts warm, from a tracked pose, as the frame
/// would in an uncut trial.
pub const SEGMENT_RUN_IN: usize = 20;

/// The segments of a trial of `n` frames: `[a, b)` ranges covering `0..n`, a function of `n`
/// alone (see [`SEGMENT_FRAMES`]).
pub fn segments(n: usize) -> Vec<(usize, usize)> {
    let k = (n / SEGMENT_FRAMES).max(1);
    (0..k).map(|i| (i * n / k, (i + 1) * n / k)).collect()
}

/// Solves every frame of `trial` like [`super::solve_trial_with`], handing each frame to `sink`
/// in frame order as soon as it is known. An error from `sink` stops the solve
/// ([`TrialError::Output`]).
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
    let start = Instant::now();
    // One morphology: every frame is solved at the calibrated scales and marker offsets.
    let pinned = ctx.pinned_to(calibration);
    let ctx = &pinned;
    let header = trial.header();
    let matched = match_markers(ctx, name, header)?;
    let map = &matched.columns;
    if map.iter().all(Option::is_none) {
        return Err(no_match(ctx, name, header));
    }
    if header.n_frames() == 0 {
        return Err(TrialError::Empty { trial: name.into() });
    }
    let read_err = |why: String| TrialError::Read { trial: name.into(), why };
    // One pass before solving: frames with enough markers, and each column's gaps.
    let mut solvable = 0;
    let mut runs = GapRuns::new(header.n_markers());
    for_each_window(trial, |_, w| {
        solvable += super::verdict::solvable_frames(ctx, w, map);
        runs.add(w);
    })
    .map_err(read_err)?;
    if solvable == 0 {
        return Err(TrialError::NothingSolvable { trial: name.into(), min: ctx.settings.min_markers });
    }
    let settings = &ctx.settings;
    let eval = ctx.evaluator();
    let ny = ctx.model.ny();

    // Tracking: scales toward the calibration, coordinates weakly toward the warm start.
    let y_cal = ctx.proxy.state(&calibration.proxies);
    let mut track_w = vec![0.0; ny];
    for t in &ctx.proxy.terms {
        let kind = ctx.proxy.proxies[t.proxy].kind;
        track_w[t.y_index] =
            if kind == ProxyKind::Scale { settings.scale_tracking_weight } else { settings.pose_prior_weight };
    }
    // Coordinate targets fold into the pose prior's reference (same objective up to a constant).
    let (coord_ref, coord_w) = ctx.coordinate_tracking();
    let track_w_all: Vec<f64> = track_w.iter().zip(&coord_w).map(|(a, b)| a + b).collect();

    let mut neutral = ctx.proxy.default_proxies();
    for (k, px) in ctx.proxy.proxies.iter().enumerate() {
        if px.kind == ProxyKind::Scale {
            neutral[k] = calibration.proxies[k];
        }
    }
    // Segments, one lane each at a time: fixed by the frame count alone, so that the result does
    // not depend on the lane or thread count. Consecutive segments are read together, as many as
    // fit in a window of the trial (all of them when it is held whole); each segment is solved
    // as it would be in the whole trial, so the result does not depend on the window either.
    let n = header.n_frames();
    let threads = threads.max(1);
    let lanes = lanes.max(1);
    let bounds = segments(n);
    let groups = segment_groups(&bounds, trial.window_frames());
    let base = TrialInputs {
        observed: FrameObservations { trial: header, map },
        marker_weights: &ctx.marker_weights,
        reference: &y_cal,
        tracking_weights: &track_w,
        coordinate_targets: &coord_ref,
        coordinate_weights: &coord_w,
        tracking_weights_all: &track_w_all,
        neutral: &neutral,
        calibrated: &calibration.proxies,
    };
    // Frames `[w0, b)` of the trial for the segments `segs`, and those segments within it.
    let window = |segs: &[(usize, usize)]| {
        let (a, b) = (segs[0].0, segs[segs.len() - 1].1);
        let w0 = a.saturating_sub(SEGMENT_RUN_IN);
        let rel: Vec<(usize, usize)> = segs.iter().map(|&(a, b)| (a - w0, b - w0)).collect();
        trial.window(w0..b).map(|w| (w0, w, rel)).map_err(Stop::Read)
    };
    let mut order = Orderer {
        ctx,
        calibrated: &calibration.proxies,
        next: 0,
        early: BTreeMap::new(),
        last: None,
        gap: Vec::new(),
        bridged: 0,
    };
    // One thread and one lane run on the caller's thread: no pool to start, and no waiting on
    // one during which a caller's rayon worker would take up other work (e.g. another trial).
    let pool =
        (threads > 1 || lanes > 1).then(|| rayon::ThreadPoolBuilder::new().num_threads(threads).build().ok()).flatten();
    // `auto` pre-solve needs the whole trial's RMSE (median + 6 MAD) before any frame leaves, so
    // it holds the solved frames (proxies and statistics, not observations) until its pass ends.
    let auto = settings.presolve == Presolve::Auto;
    let mut presolved = Vec::new();
    let mut backend = backend;
    let mut run = || -> Result<(), Stop> {
        let mut held: Vec<Option<FrameResult>> = if auto { vec![None; n] } else { Vec::new() };
        let mut cpu = None;
        for &(g0, g1) in &groups {
            let (w0, w, rel) = window(&bounds[g0..g1])?;
            let obs = FrameObservations { trial: &w, map };
            let inputs = TrialInputs { observed: obs, ..base };
            let mut done = |f: usize, r: FrameResult| {
                if auto {
                    held[f + w0] = Some(r);
                    Ok(())
                } else {
                    order.push(f + w0, r, (&obs, w0), sink)
                }
            };
            let b: &mut dyn BatchBackend = match backend.as_deref_mut() {
                Some(b) => b,
                None => cpu.get_or_insert_with(|| CpuBackend::new(eval.clone())),
            };
            run_lanes(&eval, settings, &inputs, &rel, SEGMENT_RUN_IN, lanes, b, &mut done)?;
        }
        if auto {
            let threshold = outlier_threshold_of(&held);
            for &(g0, g1) in &groups {
                let (w0, w, rel) = window(&bounds[g0..g1])?;
                let obs = FrameObservations { trial: &w, map };
                let inputs = TrialInputs { observed: obs, ..base };
                let end = bounds[g1 - 1].1;
                let kept = resolve_outliers_above(&eval, settings, &inputs, &rel, threshold, &mut held[w0..end]);
                presolved.extend(kept.into_iter().map(|f| f + w0));
                for f in bounds[g0].0..end {
                    let r = held[f].take().expect("every frame lies in one segment");
                    order.push(f, r, (&obs, w0), sink)?;
                }
            }
        }
        debug_assert!(order.early.is_empty() && order.next == n, "every frame lies in one segment");
        order.flush(None, sink)
    };
    match &pool {
        Some(pool) => pool.install(run),
        None => run(),
    }
    .map_err(|e| match e {
        Stop::Backend(source) => TrialError::Backend { trial: name.into(), source },
        Stop::Sink(frame, source) => TrialError::Output { trial: name.into(), frame, source },
        Stop::Read(why) => read_err(why),
    })?;
    let names: Vec<&str> = ctx.model.markers.iter().map(|m| m.name.as_str()).collect();
    let renamed = matched.renamed(&names, &header.labels).into_iter().map(|(a, b)| (a.into(), b.into())).collect();
    let bridged = order.bridged;
    let gaps = runs.stats(ctx, map, n, bridged);
    Ok(StreamedTrial {
        name: name.into(),
        frames: n,
        bridged,
        unmatched_model: matched.unmatched_model.clone(),
        unmatched_trial: matched.unmatched_trial.clone(),
        renamed,
        gaps,
        presolved,
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
    crate::solve::presolve::outlier_threshold(&rmse)
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

/// Solves every frame of `trial` with the lane scheduler ([`super::lanes`]): the trial is cut
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
    let mut sink = |f: SolvedFrame| -> Result<(), SinkError> {
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
    })
}
