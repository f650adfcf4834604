//! Jumps in unfittable frames (issue 32; `docs/KINEMATICS.md`, "Jumps in unfittable frames"):
//! through a run of frames no pose fits, the motion is continued (each frame bounded near the
//! course of the motion and one bounded step from the frame before) instead of letting the free
//! solve turn a limb to reach misplaced markers.

use crate::kinematics::assembly::Evaluator;
use crate::pipeline::running::continuity::{JumpLimits, CONTINUED_FIT_RATIO};
use crate::pipeline::running::lanes::{solved, FrameResult, Lane, TrialInputs};
use crate::pipeline::running::unfittable::misfit_steps;
use crate::solve::{FrameSolver, FrameStatus, SolverSettings};

/// In each run of solved frames whose marker RMSE exceeds `limits.unfittable_m` (bridged frames
/// inside it neither end nor break it), every frame whose pose leaves its reach
/// ([`JumpLimits::reach`]: within `limits.bound_rad` of the course of the motion, the linear
/// interpolation between the solved frames just before and after the run or the one there is,
/// one bounded step from the frame before as continued, and as many bounded steps from the
/// solved frame after the run as lie between them) is solved again from the course
/// with its rotational proxies bounded to that reach. The run's continued poses are kept, all
/// together (a run half continued would jump where it switches), when its markers were displaced
/// (the misfit steps in or out within one frame, [`misfit_steps`]: a pose fitting them better is
/// no better), or else when their RMS marker RMSE over the run is at most
/// [`CONTINUED_FIT_RATIO`] times the free poses' (no pose fits, so the one continuing the motion
/// is as good). Fittable frames are never
/// touched (a clean fast swing is followed), except those right after a kept run, which are
/// solved again from it ([`carry_on`]). Deterministic, in frame order, on the CPU. Returns the
/// frames whose continued or re-solved pose was kept.
pub fn resolve_unfittable_jumps(
    eval: &Evaluator<'_>,
    settings: &SolverSettings,
    inp: &TrialInputs<'_>,
    limits: &JumpLimits,
    results: &mut [Option<FrameResult>],
) -> Vec<usize> {
    let mut kept = Vec::new();
    let n = results.len();
    let bad = |r: &Option<FrameResult>| solved(r).is_some_and(|r| r.1.rmse_m > limits.unfittable_m);
    let mut lane: Option<Lane<'_>> = None;
    let mut f = 0;
    while f < n {
        if !bad(&results[f]) {
            f += 1;
            continue;
        }
        let a = f;
        while f < n && (bad(&results[f]) || solved(&results[f]).is_none()) {
            f += 1;
        }
        let lane = lane.get_or_insert_with(|| Lane::new(eval, settings));
        kept.extend(continue_run(lane, inp, limits, results, a, f));
    }
    kept
}

/// [`resolve_unfittable_jumps`] on the run `results[a..b]`.
fn continue_run(
    lane: &mut Lane<'_>,
    inp: &TrialInputs<'_>,
    limits: &JumpLimits,
    results: &mut [Option<FrameResult>],
    a: usize,
    b: usize,
) -> Vec<usize> {
    let np = lane.p.len();
    let before = (0..a).rev().find(|&g| solved(&results[g]).is_some());
    let after = (b..results.len()).find(|&g| solved(&results[g]).is_some());
    let (mut course, mut mid, mut half) = (vec![0.0; np], vec![0.0; np], vec![0.0; np]);
    // Per frame of the run: the continued result, where solved again; the pose it goes on from.
    let mut continued: Vec<Option<FrameResult>> = vec![None; b - a];
    let mut last: Option<(Vec<f64>, usize)> = before.map(|x| (results[x].as_ref().expect("solved").0.clone(), x));
    let (mut free_sq, mut cont_sq, mut spent) = (0.0, 0.0, vec![0.0; b - a]);
    for g in a..b {
        let Some((p, old, _)) = solved(&results[g]) else { continue };
        if !course_at(results, (before, after), g, &mut course) {
            return Vec::new();
        }
        let next = after.map(|y| (&results[y].as_ref().expect("a solved frame").0[..], y - g));
        limits.reach(&course, last.as_ref().map(|(q, h)| (&q[..], g - h)), next, &mut mid, &mut half);
        free_sq += old.rmse_m * old.rmse_m;
        if !JumpLimits::outside(&mid, &half, p) {
            cont_sq += old.rmse_m * old.rmse_m;
            last = Some((p.clone(), g));
            continue;
        }
        // The course, clamped into the reach, is the warm start.
        for (k, c) in course.iter_mut().enumerate() {
            if half[k].is_finite() {
                *c = c.clamp(mid[k] - half[k], mid[k] + half[k]);
            }
        }
        let bound = |s: &mut FrameSolver<'_>| s.bound_rotations(&mid, &half);
        let (stats, secs) = lane.solve_again(inp, g, (course.clone(), None), false, bound);
        lane.solver.reset_ranges();
        spent[g - a] = secs;
        if stats.status == FrameStatus::TooFewMarkers {
            return charge(results, a, &spent, Vec::new());
        }
        cont_sq += stats.rmse_m * stats.rmse_m;
        last = Some((lane.p.clone(), g));
        continued[g - a] = Some((lane.p.clone(), stats, 0.0));
    }
    // Markers displaced (the misfit steps in or out within a frame: the data is bad here): a
    // pose that fits them better is no better. Otherwise the continued poses must fit about as well.
    let rmse = |g: usize| solved(&results[g]).map(|r| r.1.rmse_m);
    let run: Vec<f64> = (a..b).filter_map(rmse).collect();
    let edge = |g: Option<usize>, h: usize| g.filter(|&g| g.abs_diff(h) == 1).and_then(rmse);
    let data = misfit_steps(edge(before, a), &run, edge(after, b - 1), limits.median_m);
    let keep = data || cont_sq <= CONTINUED_FIT_RATIO * CONTINUED_FIT_RATIO * free_sq;
    let mut kept = Vec::new();
    for (i, c) in continued.into_iter().enumerate() {
        if let (true, Some((p, stats, _))) = (keep, c) {
            let r = results[a + i].as_mut().expect("a solved frame");
            *r = (p, stats, r.2);
            kept.push(a + i);
        }
    }
    let mut kept = charge(results, a, &spent, kept);
    if !kept.is_empty() {
        kept.extend(carry_on(lane, inp, limits, results, b));
    }
    kept
}

/// A re-solved frame whose every proxy comes out within this of its first solve's (rad, or m
/// and scale for the others) is the same pose: the frames after it are left as they are.
const SAME_POSE: f64 = 1e-3;

/// The frames after a run whose continued poses were kept (from `b` on) were solved from the
/// run's free poses, and their pose prior held them there: a barely observed coordinate
/// (forearm pronation) can stay where those poses left it for many frames. Each is solved again,
/// as the trial's pass solves it, from the frames before it (now the continued ones), and its
/// new pose kept when it fits about as well ([`CONTINUED_FIT_RATIO`] of the first solve's
/// RMSE, and still fittable); this stops at the first frame whose pose comes out the same
/// ([`SAME_POSE`]), or one that does not fit, was not solved or ends the segment. Returns the
/// frames whose pose changed.
fn carry_on(
    lane: &mut Lane<'_>,
    inp: &TrialInputs<'_>,
    limits: &JumpLimits,
    results: &mut [Option<FrameResult>],
    b: usize,
) -> Vec<usize> {
    let presolve = lane.solver.settings.presolve == crate::solve::Presolve::Always;
    let mut kept = Vec::new();
    for g in b..results.len() {
        let pose = |h: usize| solved(&results[h]).map(|r| r.0.clone());
        let (Some(prev), Some(old)) = (pose(g - 1), solved(&results[g])) else { break };
        if old.1.rmse_m > limits.unfittable_m {
            break;
        }
        let (old_rmse, old_p) = (old.1.rmse_m, old.0.clone());
        let prev2 = if g >= 2 { pose(g - 2) } else { None };
        let (stats, secs) = lane.solve_again(inp, g, (prev, prev2), presolve, |_| {});
        let r = results[g].as_mut().expect("a solved frame");
        r.2 += secs;
        let same = lane.p.iter().zip(&old_p).all(|(x, y)| (x - y).abs() <= SAME_POSE);
        let worse = stats.rmse_m > (CONTINUED_FIT_RATIO * old_rmse).min(limits.unfittable_m);
        if stats.status == FrameStatus::TooFewMarkers || same || worse {
            break;
        }
        *r = (lane.p.clone(), stats, r.2);
        kept.push(g);
    }
    kept
}

/// The course of the motion at frame `g` into `course`: the linear interpolation between the
/// solved frames `before` and `after` the run, or the one there is; false when there is none.
fn course_at(
    results: &[Option<FrameResult>],
    (before, after): (Option<usize>, Option<usize>),
    g: usize,
    course: &mut [f64],
) -> bool {
    let pose = |h: usize| &results[h].as_ref().expect("a solved frame").0;
    match (before, after) {
        (Some(x), Some(y)) => {
            let t = (g - x) as f64 / (y - x) as f64;
            for (k, c) in course.iter_mut().enumerate() {
                *c = pose(x)[k] + t * (pose(y)[k] - pose(x)[k]);
            }
        }
        (Some(x), None) | (None, Some(x)) => course.copy_from_slice(pose(x)),
        (None, None) => return false,
    }
    true
}

/// Adds the time spent solving frames `a + i` again (`spent[i]`, s) to theirs; returns `kept`.
fn charge(results: &mut [Option<FrameResult>], a: usize, spent: &[f64], kept: Vec<usize>) -> Vec<usize> {
    for (i, s) in spent.iter().enumerate().filter(|(_, s)| **s > 0.0) {
        if let Some(r) = results[a + i].as_mut() {
            r.2 += s;
        }
    }
    kept
}
