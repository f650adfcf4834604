//! Continuous angles along a trial: a rotational proxy that can take any value modulo 2π (a
//! root heading) is handed on as the representative nearest the previous frame's, so that no
//! output (`.mot`, CSV, MCAP state, Python's `q`) jumps by a turn between neighbouring frames
//! from wrapping alone. Frames solved from a cold start (a segment's first) wrap the heading into
//! (−π, π]; warm-started ones follow it continuously.
//!
//! A true flip (a limb solved about 180° round between neighbours) is not a wrap:
//! [`max_jump`] finds it, and the `auto` pre-solve pass retries such a frame from its
//! neighbour's pose ([`crate::pipeline::running::lanes::resolve_flips`]) before it is reported.

use crate::model::math::wrap_angle;
use crate::model::proxy::{ProxyKind, ProxyMap};
use std::f64::consts::TAU;

/// A jump beyond this between neighbouring frames (rad, 90°) in a rotational proxy, wrapping
/// aside, is a flip (as the trial's plausibility judges it).
pub const FLIP_RAD: f64 = std::f64::consts::FRAC_PI_2;

/// The rotational proxies whose range spans at least a full turn: those a solver may return in
/// another turn than its neighbour's.
pub fn periodic_proxies(proxy: &ProxyMap) -> Vec<usize> {
    proxy
        .proxies
        .iter()
        .enumerate()
        .filter(|(_, p)| p.kind == ProxyKind::Rotation && p.range.1 - p.range.0 >= TAU)
        .map(|(k, _)| k)
        .collect()
}

/// Moves each of `periodic` in `p` by whole turns to the value nearest `prev`'s (rad).
pub fn unwrap_towards(p: &mut [f64], prev: &[f64], periodic: &[usize]) {
    for &k in periodic {
        // Whole turns added only (a frame already nearest is left bit for bit as solved).
        let turns = ((prev[k] - p[k]) / TAU).round();
        if turns.is_finite() && turns != 0.0 {
            p[k] += TAU * turns;
        }
    }
}

/// The largest change (rad) of a rotational proxy of `proxy` between `a` and `b`, whole turns
/// aside, and that proxy.
pub fn max_jump(proxy: &ProxyMap, a: &[f64], b: &[f64]) -> (f64, Option<usize>) {
    let mut out = (0.0, None);
    for (k, px) in proxy.proxies.iter().enumerate() {
        if px.kind != ProxyKind::Rotation {
            continue;
        }
        let d = wrap_angle(b[k] - a[k]).abs();
        if d > out.0 {
            out = (d, Some(k));
        }
    }
    out
}

/// Slowest joint speed (rad/s, 500°/s) a frame may reach before its jump is weighed, whatever the
/// trial's own motion: the floor of [`JumpLimits::bound_rad`].
pub const SPEED_FLOOR_RAD_S: f64 = 500.0 * std::f64::consts::PI / 180.0;
/// How many times the trial's 99th percentile of frame-to-frame changes (between frames that fit)
/// a frame of an unfittable run may move: once, as far as the trial's own frames move.
pub const TRIAL_JUMP_FACTOR: f64 = 1.0;
/// A run's continued (bounded) poses are taken when their RMS marker RMSE is at most this many
/// times the free poses' (or its markers were displaced): no pose fits such frames, so the one
/// continuing the motion is as good.
pub const CONTINUED_FIT_RATIO: f64 = 1.5;

/// What the continuity of unfittable frames ([`crate::pipeline::running::jumps::resolve_unfittable_jumps`])
/// allows a trial (`docs/KINEMATICS.md`, "Jumps in unfittable frames").
#[derive(Clone, Debug)]
pub struct JumpLimits {
    /// Per proxy, the largest change (rad) from the course of the motion a frame may take in a
    /// rotational proxy: `max(TRIAL_JUMP_FACTOR × P99 of that proxy's changes between neighbouring
    /// frames that both fit (RMSE at most `unfittable_m`), SPEED_FLOOR_RAD_S / rate)`; infinite
    /// for the others.
    pub bound_rad: Vec<f64>,
    /// A frame's marker RMSE above this (m) is unfittable ([`crate::pipeline::running::unfittable`]).
    pub unfittable_m: f64,
    /// The trial's median frame RMSE (m).
    pub median_m: f64,
}

impl JumpLimits {
    /// The limits of a trial at `rate_hz` from its solved frames' proxies and RMSEs (m), in frame
    /// order (`None`: not solved).
    pub fn of(proxy: &ProxyMap, rate_hz: f64, frames: &[Option<(&[f64], f64)>]) -> JumpLimits {
        use crate::pipeline::running::unfittable::{RMSE_FACTOR, RMSE_FLOOR_MM};
        let mut rmse: Vec<f64> = frames.iter().flatten().map(|f| f.1).filter(|r| r.is_finite()).collect();
        let median = crate::solve::median(&mut rmse);
        let unfittable_m = if median.is_finite() { (RMSE_FACTOR * median).max(RMSE_FLOOR_MM * 1e-3) } else { f64::NAN };
        let rate = if rate_hz.is_finite() && rate_hz > 0.0 { rate_hz } else { 100.0 };
        let floor = SPEED_FLOOR_RAD_S / rate;
        // The trial's own motion is measured between frames that both fit: the jumps of the
        // unfittable frames themselves would otherwise widen the bound that is to hold them.
        let fits = |f: &(&[f64], f64)| f.1 <= unfittable_m;
        let mut steps = Vec::with_capacity(frames.len());
        let bound_rad = (0..proxy.np())
            .map(|k| {
                if proxy.proxies[k].kind != ProxyKind::Rotation {
                    return f64::INFINITY;
                }
                steps.clear();
                steps.extend(frames.windows(2).filter_map(|w| match (w[0], w[1]) {
                    (Some(a), Some(b)) if fits(&a) && fits(&b) => {
                        Some(wrap_angle(b.0[k] - a.0[k]).abs()).filter(|d| d.is_finite())
                    }
                    _ => None,
                }));
                steps.sort_by(f64::total_cmp);
                let p99 =
                    if steps.is_empty() { 0.0 } else { steps[((steps.len() - 1) as f64 * 0.99).round() as usize] };
                (TRIAL_JUMP_FACTOR * p99).max(floor)
            })
            .collect();
        JumpLimits { bound_rad, unfittable_m, median_m: median }
    }

    /// Where a frame of an unfittable run may go (rad): per rotational proxy, within `bound_rad`
    /// of the `course` of the motion, within `bound_rad × n` of the last solved frame before it
    /// as continued (`prev`, `n` frames earlier: one bounded step per frame) and within
    /// `bound_rad × m` of the solved frame after the run (`next`, `m` frames later: the run must
    /// be able to step back onto the motion where it ends); where these exclude each other (the
    /// course moves faster than that), between the neighbours' reaches. Writes the box's centre
    /// to `mid` and its half-width to `half` (infinite for the other proxies).
    pub fn reach(
        &self,
        course: &[f64],
        prev: Option<(&[f64], usize)>,
        next: Option<(&[f64], usize)>,
        mid: &mut [f64],
        half: &mut [f64],
    ) {
        for (k, b) in self.bound_rad.iter().enumerate() {
            if !b.is_finite() {
                (mid[k], half[k]) = (course[k], *b);
                continue;
            }
            let (mut lo, mut hi) = (course[k] - b, course[k] + b);
            for (pose, n) in [prev, next].into_iter().flatten() {
                // The neighbour's value in the course's turn (periodic proxies).
                let c = course[k] + wrap_angle(pose[k] - course[k]);
                (lo, hi) = (lo.max(c - b * n as f64), hi.min(c + b * n as f64));
            }
            if lo > hi {
                (lo, hi) = (hi, lo);
            }
            (mid[k], half[k]) = (0.5 * (lo + hi), 0.5 * (hi - lo));
        }
    }

    /// Whether `p` lies outside the box `mid ± half` ([`Self::reach`]) in some rotational proxy.
    pub fn outside(mid: &[f64], half: &[f64], p: &[f64]) -> bool {
        half.iter().enumerate().any(|(k, h)| h.is_finite() && wrap_angle(p[k] - mid[k]).abs() > *h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_of_an_unfittable_run_reaches_one_bounded_step_from_the_frame_before() {
        let limits = JumpLimits { bound_rad: vec![0.1, f64::INFINITY], unfittable_m: 0.01, median_m: 0.003 };
        let (mut mid, mut half) = (vec![0.0; 2], vec![0.0; 2]);
        // Course at 0; the frame before at 0.15: [−0.1, 0.1] ∩ [0.05, 0.25] = [0.05, 0.1].
        limits.reach(&[0.0, 3.0], Some((&[0.15, 9.0], 1)), None, &mut mid, &mut half);
        assert!((mid[0] - 0.075).abs() < 1e-12 && (half[0] - 0.025).abs() < 1e-12, "{mid:?} {half:?}");
        assert_eq!((mid[1], half[1]), (3.0, f64::INFINITY));
        assert!(JumpLimits::outside(&mid, &half, &[0.0, 50.0]) && !JumpLimits::outside(&mid, &half, &[0.08, 50.0]));
        // Two frames earlier: two steps. Further than the course allows: between the two.
        limits.reach(&[0.0, 3.0], Some((&[0.5, 9.0], 2)), None, &mut mid, &mut half);
        assert!((mid[0] - 0.2).abs() < 1e-12 && (half[0] - 0.1).abs() < 1e-12, "{mid:?} {half:?}");
    }

    #[test]
    fn the_last_frame_of_an_unfittable_run_stays_one_bounded_step_from_the_frame_after() {
        let limits = JumpLimits { bound_rad: vec![0.1], unfittable_m: 0.01, median_m: 0.003 };
        let (mut mid, mut half) = (vec![0.0], vec![0.0]);
        // Course at 0, the frame before at 0.05 (one step back), the frame after at −0.12 (one
        // step on): [−0.1, 0.1] ∩ [−0.05, 0.15] ∩ [−0.22, −0.02] = [−0.05, −0.02].
        limits.reach(&[0.0], Some((&[0.05], 1)), Some((&[-0.12], 1)), &mut mid, &mut half);
        assert!((mid[0] + 0.035).abs() < 1e-12 && (half[0] - 0.015).abs() < 1e-12, "{mid:?} {half:?}");
        // Three frames before the frame after: three steps of room.
        limits.reach(&[0.0], None, Some((&[-0.12], 3)), &mut mid, &mut half);
        assert!((mid[0] - 0.0).abs() < 1e-12 && (half[0] - 0.1).abs() < 1e-12, "{mid:?} {half:?}");
    }

    #[test]
    fn unwrapping_moves_by_whole_turns_toward_the_previous_frame() {
        let mut p = vec![-3.1, 0.5];
        unwrap_towards(&mut p, &[3.1 + 2.0 * TAU, 0.0], &[0]);
        assert!((p[0] - (-3.1 + 3.0 * TAU)).abs() < 1e-12);
        assert_eq!(p[1], 0.5);
    }
}
