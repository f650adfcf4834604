//! The lane scheduler: many frames in flight, one batched evaluation per trust-region round.
//!
//! Each lane walks the frames of one segment in order, warm-starting every frame from the
//! previous solution, exactly as a per-segment loop over [`FrameSolver::solve`] would. A round
//! is: one batched `(H, g, E)` evaluation of every lane that needs one, each lane's follow-up QP
//! solved as its model is handed over (read where the backend left it: a CPU workspace or the
//! mapped read-back buffer, [`BatchBackend::linearize_into`]), then one batched `E` evaluation of every trial point and the
//! accept/reject decisions on the pool. Lanes whose frame is done start their next frame (a cold
//! start, on the CPU, at the beginning of a segment); lanes whose segment ends take the next
//! segment from the queue. The solver never knows which [`BatchBackend`] evaluated.
//!
//! The queue may hold segments of several trials of one subject ([`run_lanes_across`]): each
//! segment carries its trial's [`TrialInputs`], so that a round's batch holds lanes of several
//! trials and short trials together fill a GPU batch. A lane's result depends only on its
//! segment, so it is the same whatever else is in the queue.

use crate::io::MarkerTrial;
use crate::kinematics::assembly::{fold_tracking_reference, Evaluator, FrameProblem};
use crate::kinematics::backend::{BackendError, BatchBackend, EnergyEval, GnSink, GnView};
use crate::pipeline::running::continuity::{max_jump, FLIP_RAD};
use crate::solve::init::multi_start_with;
use crate::solve::trqp::{FrameIteration, Next};
use crate::solve::{make_qp, FrameSolver, FrameStats, FrameStatus, Presolve, Presolver, SolverSettings, WarmStart};
use rayon::prelude::*;
use std::collections::VecDeque;
use std::time::Instant;

/// What every frame of the trial shares.
#[derive(Clone, Copy, Debug)]
pub struct TrialInputs<'a> {
    /// Observations, read frame by frame as lanes reach them.
    pub observed: FrameObservations<'a>,
    pub marker_weights: &'a [f64],
    /// Tracking reference `y_ref` for the scales (the pose part is reset to each warm start).
    pub reference: &'a [f64],
    pub tracking_weights: &'a [f64],
    /// Soft coordinate targets (IK coordinate tasks, length ny) and their weights, folded into
    /// the reference each frame ([`fold_tracking_reference`]); `tracking_weights_all` is
    /// `tracking_weights + coordinate_weights`.
    pub coordinate_targets: &'a [f64],
    pub coordinate_weights: &'a [f64],
    pub tracking_weights_all: &'a [f64],
    /// Cold-start proxies (neutral pose at the calibrated morphology).
    pub neutral: &'a [f64],
    /// The calibration's proxies: one more start for a segment's first frame.
    pub calibrated: &'a [f64],
}

/// A trial's observations in model-marker order, read one frame at a time (so that a trial's
/// observations are never copied whole).
#[derive(Clone, Copy, Debug)]
pub struct FrameObservations<'a> {
    pub trial: &'a MarkerTrial,
    /// Trial column of each model marker.
    pub map: &'a [Option<usize>],
}

impl FrameObservations<'_> {
    /// Frame `f` as `3·marker + axis` (m), NaN where unobserved; as [`crate::pipeline::input::trial::observations`].
    pub fn fill(&self, f: usize, out: &mut [f64]) {
        out.fill(f64::NAN);
        for (m, col) in self.map.iter().enumerate() {
            if let Some(p) = col.and_then(|c| self.trial.position(f, c)) {
                out[3 * m..3 * m + 3].copy_from_slice(&p);
            }
        }
    }
}

/// One solved frame: proxies, statistics, seconds from its start to its end (wall).
pub type FrameResult = (Vec<f64>, FrameStats, f64);

pub(crate) struct Lane<'e> {
    pub(crate) solver: FrameSolver<'e>,
    /// The trial (index into the inputs) of the current segment.
    trial: usize,
    /// Current segment `[a, b)` and frame.
    seg: Option<(usize, usize)>,
    frame: usize,
    /// First frame of the segment handed on (frames before it are its run-in).
    emit_from: usize,
    pub(crate) p: Vec<f64>,
    prev: Option<Vec<f64>>,
    prev2: Option<Vec<f64>>,
    reference: Vec<f64>,
    it: Option<FrameIteration>,
    next: Next,
    started: Instant,
    y_warm: Vec<f64>,
    dphi: Vec<f64>,
    /// The current frame's observations.
    obs: Vec<f64>,
    presolver: Presolver,
    /// The cold start's sweeps ([`Presolver::cold`]).
    cold: Presolver,
}

impl<'e> Lane<'e> {
    pub(crate) fn new(eval: &'e Evaluator<'e>, settings: &SolverSettings) -> Lane<'e> {
        let (np, ny) = (eval.proxy.np(), eval.model.ny());
        Lane {
            solver: FrameSolver::new(eval, settings.clone(), make_qp(settings.qp)),
            trial: 0,
            seg: None,
            frame: 0,
            emit_from: 0,
            p: vec![0.0; np],
            prev: None,
            prev2: None,
            reference: vec![0.0; ny],
            it: None,
            next: Next::Done(idle_stats()),
            started: Instant::now(),
            y_warm: vec![0.0; ny],
            dphi: vec![0.0; eval.proxy.terms.len()],
            obs: vec![f64::NAN; 3 * eval.model.markers.len()],
            presolver: Presolver::new(eval, settings, false),
            cold: Presolver::cold(eval, settings),
        }
    }

    fn frame_problem<'a>(&'a self, inp: &TrialInputs<'a>) -> FrameProblem<'a> {
        FrameProblem {
            observed: &self.obs,
            marker_weights: inp.marker_weights,
            tracking_ref: &self.reference,
            tracking_weights: inp.tracking_weights_all,
        }
    }

    /// Solves frame `f` again, alone, from `(prev, prev2)` (a warm start, or with `presolve` the
    /// frame's pre-solve), after `prepare` on the solver (bounds, say): the statistics and the
    /// time spent (s). The pose is left in `self.p`.
    pub(crate) fn solve_again(
        &mut self,
        inp: &TrialInputs<'_>,
        f: usize,
        (prev, prev2): (Vec<f64>, Option<Vec<f64>>),
        presolve: bool,
        prepare: impl FnOnce(&mut FrameSolver<'e>),
    ) -> (FrameStats, f64) {
        self.prev = Some(prev);
        self.prev2 = prev2;
        self.frame = f;
        self.start_frame(inp, presolve);
        prepare(&mut self.solver);
        let frame = FrameProblem {
            observed: &self.obs,
            marker_weights: inp.marker_weights,
            tracking_ref: &self.reference,
            tracking_weights: inp.tracking_weights_all,
        };
        let stats = self.solver.solve(&frame, &mut self.p);
        self.it = None;
        (stats, self.started.elapsed().as_secs_f64())
    }

    /// Prepares `self.frame`: warm start, pose prior, cold start at a segment's beginning, and
    /// with `presolve` the pre-solve of a warm-started frame (a cold start already places the root
    /// and sweeps, [`multi_start_with`]). The pose prior stays at the warm start.
    fn start_frame(&mut self, inp: &TrialInputs<'_>, presolve: bool) {
        let eval = self.solver.eval;
        let nq = eval.model.nq();
        self.started = Instant::now();
        inp.observed.fill(self.frame, &mut self.obs);
        match (&self.prev, &self.prev2, self.solver.settings.warm_start) {
            (Some(p1), Some(p2), WarmStart::Extrapolate) => {
                for (k, v) in self.p.iter_mut().enumerate() {
                    *v = 2.0 * p1[k] - p2[k];
                }
            }
            (Some(p1), _, _) => self.p.copy_from_slice(p1),
            (None, _, _) => self.p.copy_from_slice(inp.neutral),
        }
        self.solver.clamp(&mut self.p);
        // Pose prior toward the warm start (scales keep the calibrated reference).
        eval.proxy.apply(&self.p, &mut self.y_warm, &mut self.dphi);
        self.reference.copy_from_slice(inp.reference);
        self.reference[..nq].copy_from_slice(&self.y_warm[..nq]);
        fold_tracking_reference(
            &mut self.reference,
            inp.tracking_weights,
            inp.coordinate_targets,
            inp.coordinate_weights,
        );
        if self.prev.is_none() {
            let frame = FrameProblem {
                observed: &self.obs,
                marker_weights: inp.marker_weights,
                tracking_ref: &self.reference,
                tracking_weights: inp.tracking_weights_all,
            };
            // A segment's first frame: several starts, the best kept; the iteration below then
            // only confirms it.
            multi_start_with(&mut self.cold, &mut self.solver, &frame, &mut self.p, inp.calibrated);
        } else if presolve {
            let frame = FrameProblem {
                observed: &self.obs,
                marker_weights: inp.marker_weights,
                tracking_ref: &self.reference,
                tracking_weights: inp.tracking_weights_all,
            };
            self.presolver.run(eval, &mut self.solver, &frame, &mut self.p);
        }
        self.it = Some(self.solver.begin(&mut self.p));
        self.next = Next::Linearize;
    }
}

/// Solves the frames of `segments` (ranges of frame indices of one trial) with `lanes` lanes,
/// evaluating through `backend`, handing each frame to `done` (with its index) as soon as it is
/// solved: in frame order within a segment, segments interleaved when several lanes run. A
/// segment `[a, b)` is walked from `a − run_in` (cold-started there, warm-started from then on)
/// and its frames from `a` are handed on, so that its first frame continues a tracked motion as
/// the previous segment's last one does. Each lane's result depends only on its segment, not on
/// the lane count or on which lane walked it. An error from `done` stops the run and is
/// returned. Runs on the current rayon pool. [`run_lanes_across`] with one trial.
#[allow(clippy::too_many_arguments)]
pub fn run_lanes<E: From<BackendError>>(
    eval: &Evaluator<'_>,
    settings: &SolverSettings,
    inp: &TrialInputs<'_>,
    segments: &[(usize, usize)],
    run_in: usize,
    lanes: usize,
    backend: &mut dyn BatchBackend,
    done: &mut dyn FnMut(usize, FrameResult) -> Result<(), E>,
) -> Result<(), E> {
    let segments: Vec<(usize, (usize, usize))> = segments.iter().map(|&s| (0, s)).collect();
    let mut done = |_: usize, f: usize, r: FrameResult| done(f, r);
    run_lanes_across(eval, settings, std::slice::from_ref(inp), &segments, run_in, lanes, backend, &mut done)
}

/// [`run_lanes`] over segments of several trials solved with one evaluator (one subject's trials
/// at its calibrated morphology): `segments` are `(trial, [a, b))`, `trial` indexing `trials`,
/// handed out to the lanes in this order, and `done` receives `(trial, frame, result)`. Each
/// round's batch holds the lanes of whichever trials they walk, so that trials too short to fill
/// a batch fill it together. Each frame's result depends only on its own segment (its trial's
/// inputs and frames): the same whether its trial is solved alone or with others, whatever the
/// order of the queue and the lane count.
#[allow(clippy::too_many_arguments)]
pub fn run_lanes_across<E: From<BackendError>>(
    eval: &Evaluator<'_>,
    settings: &SolverSettings,
    trials: &[TrialInputs<'_>],
    segments: &[(usize, (usize, usize))],
    run_in: usize,
    lanes: usize,
    backend: &mut dyn BatchBackend,
    done: &mut dyn FnMut(usize, usize, FrameResult) -> Result<(), E>,
) -> Result<(), E> {
    let mut queue: VecDeque<(usize, (usize, usize))> =
        segments.iter().copied().filter(|(t, (a, b))| b > a && *t < trials.len()).collect();
    let n_lanes = lanes.max(1).min(queue.len().max(1));
    let mut lanes: Vec<Lane<'_>> = (0..n_lanes).map(|_| Lane::new(eval, settings)).collect();
    let presolve = settings.presolve == Presolve::Always;
    let mut energies = vec![EnergyEval::default(); n_lanes];
    let mut px: Vec<f64> = Vec::with_capacity(n_lanes * eval.proxy.np());
    loop {
        // Record finished frames; hand out segments (in queue order); start next frames.
        for lane in lanes.iter_mut() {
            let Next::Done(stats) = lane.next else { continue };
            if lane.it.take().is_some() {
                if lane.frame >= lane.emit_from {
                    done(lane.trial, lane.frame, (lane.p.clone(), stats, lane.started.elapsed().as_secs_f64()))?;
                }
                if stats.status != FrameStatus::TooFewMarkers {
                    let old = lane.prev2.take();
                    lane.prev2 = lane.prev.take();
                    let mut p = old.unwrap_or_default();
                    p.clone_from(&lane.p);
                    lane.prev = Some(p);
                }
                lane.frame += 1;
            }
            if lane.seg.is_none_or(|(_, b)| lane.frame >= b) {
                let next = queue.pop_front();
                lane.seg = next.map(|(_, s)| s);
                lane.prev = None;
                lane.prev2 = None;
                if let Some((t, (a, _))) = next {
                    lane.trial = t;
                    lane.frame = a.saturating_sub(run_in);
                    lane.emit_from = a;
                }
            }
        }
        lanes
            .par_iter_mut()
            .filter(|l| l.seg.is_some() && l.it.is_none())
            .for_each(|l| l.start_frame(&trials[l.trial], presolve));
        if lanes.iter().all(|l| l.seg.is_none()) {
            break;
        }

        // One batched linearisation; each lane's QP reads its model where the backend left it.
        linearize_round(&mut lanes, trials, &mut px, backend)?;
        // One batched energy evaluation of the trial points, then accept or reject.
        let k = batch(
            &lanes,
            |n| matches!(n, Next::Energy),
            trials,
            &mut px,
            |l| l.solver.trial(),
            |f, p| backend.energy(f, p, &mut energies[..f.len()]),
        )?;
        if k > 0 {
            let mut active: Vec<&mut Lane<'_>> = lanes.iter_mut().filter(|l| matches!(l.next, Next::Energy)).collect();
            active.par_iter_mut().zip(energies[..k].par_iter()).for_each(|(l, e)| {
                let it = l.it.as_mut().expect("a lane that needs an evaluation is iterating");
                l.next = l.solver.evaluated(it, &mut l.p, *e);
            });
        }
    }
    Ok(())
}

/// `auto` pre-solve: frames whose marker RMSE exceeds the trial's median + 6 MAD
/// ([`super::unfittable::presolve_threshold`]) are solved again from their warm start (the previous solved frame of
/// their segment, as updated by this pass) with pre-solve, and the result with the lower energy
/// is kept; the time spent is added to the frame's. Segments' first frames (cold-started from
/// several starts, [`multi_start_with`]) and bridged frames are left. Frames are visited in order on
/// the CPU, so the result does not depend on the lane count or backend. Returns the frames
/// whose re-solved result was kept.
pub fn resolve_outliers(
    eval: &Evaluator<'_>,
    settings: &SolverSettings,
    inp: &TrialInputs<'_>,
    segments: &[(usize, usize)],
    results: &mut [Option<FrameResult>],
) -> Vec<usize> {
    let rmse: Vec<f64> = results.iter().filter_map(|r| solved(r).map(|r| r.1.rmse_m)).collect();
    resolve_outliers_above(eval, settings, inp, segments, super::unfittable::presolve_threshold(&rmse), results)
}

/// [`resolve_outliers`] with the threshold given (m): the trial's, when `results` and
/// `segments` are a part of it (indices relative to that part).
pub fn resolve_outliers_above(
    eval: &Evaluator<'_>,
    settings: &SolverSettings,
    inp: &TrialInputs<'_>,
    segments: &[(usize, usize)],
    threshold: f64,
    results: &mut [Option<FrameResult>],
) -> Vec<usize> {
    let mut kept = Vec::new();
    if threshold.is_nan() {
        return kept;
    }
    let mut lane: Option<Lane<'_>> = None;
    for &(a, b) in segments {
        for f in a + 1..b.min(results.len()) {
            let Some((_, old, _)) = solved(&results[f]) else { continue };
            if old.rmse_m.is_nan() || old.rmse_m <= threshold {
                continue;
            }
            let old_energy = old.energy;
            let mut warm = (a..f).rev().filter_map(|g| solved(&results[g]).map(|r| r.0.clone()));
            let Some(prev) = warm.next() else { continue };
            let lane = lane.get_or_insert_with(|| Lane::new(eval, settings));
            let (stats, spent) = lane.solve_again(inp, f, (prev, warm.next()), true, |_| {});
            let r = results[f].as_mut().expect("a solved frame");
            if stats.status != FrameStatus::TooFewMarkers && stats.energy < old_energy {
                *r = (lane.p.clone(), stats, r.2 + spent);
                kept.push(f);
            } else {
                r.2 += spent;
            }
        }
    }
    kept
}

/// True flips ([`crate::pipeline::running::continuity`]): a solved frame whose rotational proxies differ from the
/// previous solved frame's by more than [`FLIP_RAD`] (whole turns aside) is solved again from
/// that neighbour's pose; the re-solve is kept when it is continuous and fits the markers about
/// as well (RMSE within 10 % or 0.5 mm of the flipped one's), and the next frames are retried
/// the same way while they still jump. Frames are visited in order on the CPU (deterministic);
/// the time spent is added to the frame's. Returns the frames whose re-solve was kept.
pub fn resolve_flips(
    eval: &Evaluator<'_>,
    settings: &SolverSettings,
    inp: &TrialInputs<'_>,
    results: &mut [Option<FrameResult>],
) -> Vec<usize> {
    let mut kept = Vec::new();
    let mut lane: Option<Lane<'_>> = None;
    let mut prev: Option<usize> = None;
    for f in 0..results.len() {
        let Some((p, old, _)) = solved(&results[f]) else { continue };
        let Some(g) = prev.replace(f) else { continue };
        let neighbour = results[g].as_ref().expect("a solved frame").0.clone();
        if max_jump(eval.proxy, &neighbour, p).0 <= FLIP_RAD || old.rmse_m.is_nan() {
            continue;
        }
        let old_rmse = old.rmse_m;
        let lane = lane.get_or_insert_with(|| Lane::new(eval, settings));
        let (stats, spent) = lane.solve_again(inp, f, (neighbour.clone(), None), false, |_| {});
        let r = results[f].as_mut().expect("a solved frame");
        let continuous = max_jump(eval.proxy, &neighbour, &lane.p).0 <= FLIP_RAD;
        let fits = stats.rmse_m <= (1.1 * old_rmse).max(old_rmse + 5e-4);
        if stats.status != FrameStatus::TooFewMarkers && continuous && fits {
            *r = (lane.p.clone(), stats, r.2 + spent);
            kept.push(f);
        } else {
            r.2 += spent;
        }
    }
    kept
}

/// The result of a frame that was solved (not bridged).
pub(crate) fn solved(r: &Option<FrameResult>) -> Option<&FrameResult> {
    r.as_ref().filter(|r| r.1.status != FrameStatus::TooFewMarkers)
}

/// The part of a lane that takes its Gauss–Newton model and solves the step QP from it.
struct LaneSink<'a, 'e> {
    solver: &'a mut FrameSolver<'e>,
    it: &'a mut Option<FrameIteration>,
    next: &'a mut Next,
    p: &'a [f64],
}

impl GnSink for LaneSink<'_, '_> {
    fn take(&mut self, view: &GnView<'_>) {
        let it = self.it.as_mut().expect("a lane that needs an evaluation is iterating");
        *self.next = self.solver.linearized_view(it, self.p, view);
    }
}

/// One batched `(H, g, E)` of every lane that needs one, each lane's step QP solved as its model
/// is handed over ([`BatchBackend::linearize_into`]).
fn linearize_round(
    lanes: &mut [Lane<'_>],
    trials: &[TrialInputs<'_>],
    px: &mut Vec<f64>,
    backend: &mut dyn BatchBackend,
) -> Result<(), BackendError> {
    px.clear();
    let mut frames = Vec::new();
    let mut sinks = Vec::new();
    for l in lanes.iter_mut().filter(|l| matches!(l.next, Next::Linearize)) {
        let Lane { solver, it, next, p, obs, reference, trial, .. } = l;
        let inp = &trials[*trial];
        frames.push(FrameProblem {
            observed: obs,
            marker_weights: inp.marker_weights,
            tracking_ref: reference,
            tracking_weights: inp.tracking_weights_all,
        });
        px.extend_from_slice(p);
        sinks.push(LaneSink { solver, it, next, p });
    }
    if frames.is_empty() {
        return Ok(());
    }
    let mut dyns: Vec<&mut dyn GnSink> = sinks.iter_mut().map(|s| s as &mut dyn GnSink).collect();
    backend.linearize_into(&frames, px, &mut dyns)
}

/// Gathers the lanes that need `what` into one batch and evaluates it; returns its size.
fn batch<'l>(
    lanes: &'l [Lane<'_>],
    what: impl Fn(&Next) -> bool,
    trials: &'l [TrialInputs<'l>],
    px: &mut Vec<f64>,
    point: impl Fn(&'l Lane<'_>) -> &'l [f64],
    mut eval: impl FnMut(&[FrameProblem<'_>], &[f64]) -> Result<(), BackendError>,
) -> Result<usize, BackendError> {
    px.clear();
    let mut frames = Vec::new();
    for l in lanes.iter().filter(|l| what(&l.next)) {
        frames.push(l.frame_problem(&trials[l.trial]));
        px.extend_from_slice(point(l));
    }
    if !frames.is_empty() {
        eval(&frames, px)?;
    }
    Ok(frames.len())
}

fn idle_stats() -> FrameStats {
    FrameStats {
        iterations: 0,
        accepted: 0,
        energy: f64::NAN,
        rmse_m: f64::NAN,
        markers_used: 0,
        status: FrameStatus::TooFewMarkers,
    }
}
