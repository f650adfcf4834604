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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unwrapping_moves_by_whole_turns_toward_the_previous_frame() {
        let mut p = vec![-3.1, 0.5];
        unwrap_towards(&mut p, &[3.1 + 2.0 * TAU, 0.0], &[0]);
        assert!((p[0] - (-3.1 + 3.0 * TAU)).abs() < 1e-12);
        assert_eq!(p[1], 0.5);
    }
}
