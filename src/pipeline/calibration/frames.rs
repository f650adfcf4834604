//! Choosing a subject's calibration frames over the range of its poses rather than over time
//! (docs/CALIBRATION.md, "Stages"): a frame joins the calibration when its pose differs from every
//! frame chosen before it by more than a coverage radius, so a repetitive archive (walk after
//! walk) gives few frames, all early in its trials, and a varied one many.
//!
//! A frame's pose is read from its markers alone (no solve): the markers that every candidate of
//! the group observes, about their centroid, rotated onto the group's first candidate (Kabsch);
//! two frames differ by the RMS distance of those markers.

use crate::pipeline::input::frames::{for_each_window, TrialFrames};
use crate::pipeline::input::trial::observation_row;
use nalgebra::{Matrix3, Vector3};

/// Markers observed in a frame that the solver uses (weight > 0).
fn observed_count(obs: &[f64], weights: &[f64]) -> usize {
    obs.chunks_exact(3).zip(weights).filter(|(c, &w)| w > 0.0 && c.iter().all(|v| !v.is_nan())).count()
}

/// One trial's frames as calibration's first pass saw them.
pub struct TrialScan {
    /// Observed weighted markers per frame.
    pub counts: Vec<usize>,
    /// Candidate frames (ascending): frames with enough markers, at most one per track step.
    pub candidates: Vec<usize>,
    /// Each candidate's observations (`3 × markers` values, NaN gaps); empty when not asked for.
    pub rows: Vec<f64>,
}

impl TrialScan {
    /// Trial `t`'s scan with its markers `map` and the first stage's `weights`: candidates one
    /// per `step` frames at least among the good frames (`min` markers), with their observations
    /// when `rows` (a second pass over the trial: the candidates need the whole trial's counts);
    /// also every (n / 20)th frame's observations, for the units check.
    pub fn of<T: TrialFrames + ?Sized>(
        t: &T,
        map: &[Option<usize>],
        weights: &[f64],
        step: usize,
        min: usize,
        rows: bool,
    ) -> Result<(TrialScan, Vec<f64>), String> {
        let stride = 3 * map.len();
        let n = t.header().n_frames();
        let every = (n / 20).max(1);
        let (mut counts, mut sample) = (Vec::with_capacity(n), Vec::new());
        let mut row = vec![f64::NAN; stride];
        for_each_window(t, |first, w| {
            for f in 0..w.n_frames() {
                observation_row(w, map, f, &mut row);
                counts.push(observed_count(&row, weights));
                if (first + f) % every == 0 {
                    sample.extend_from_slice(&row);
                }
            }
        })?;
        let mut candidates: Vec<usize> = Vec::new();
        let ok = TrialScan::good(&counts, min);
        for f in 0..n {
            if ok(f) && candidates.last().is_none_or(|&l| f >= l + step) {
                candidates.push(f);
            }
        }
        drop(ok);
        let mut kept = Vec::new();
        if rows {
            kept.reserve(candidates.len() * stride);
            let mut next = candidates.iter().copied().peekable();
            for_each_window(t, |first, w| {
                for f in 0..w.n_frames() {
                    if next.peek() == Some(&(first + f)) {
                        next.next();
                        observation_row(w, map, f, &mut row);
                        kept.extend_from_slice(&row);
                    }
                }
            })?;
        }
        Ok((TrialScan { counts, candidates, rows: kept }, sample))
    }

    /// Whether frame `f` (of `counts`) is good enough to calibrate on: at least `min` observed
    /// markers and within two of the trial's best frame.
    pub fn good(counts: &[usize], min: usize) -> impl Fn(usize) -> bool + '_ {
        let best = counts.iter().copied().max().unwrap_or(0);
        move |f| counts[f] >= min && counts[f] + 2 >= best
    }
}

/// Up to `k` frames spread evenly over those with the most observed markers (`counts`: observed
/// weighted markers per frame; every good frame when `k` is 0).
pub fn spread(counts: &[usize], k: usize, min: usize) -> Vec<usize> {
    let ok = TrialScan::good(counts, min);
    let good: Vec<usize> = (0..counts.len()).filter(|&f| ok(f)).collect();
    if good.is_empty() || k == 0 {
        return good;
    }
    let n = good.len().min(k);
    (0..n).map(|i| good[(i * good.len()) / n + good.len() / (2 * n)]).collect()
}

/// The calibration frames of each trial of a group (a subject's static trials, or its motion
/// trials): at most `k` in all, chosen over the group's candidates in order (trial by trial, in
/// time) as a net of `radius` m (a candidate joins when it is farther than `radius` from every
/// one chosen before; [`farthest_first`] picks `k` when the net has more). `radius` 0, `k` 0 or
/// fewer than three markers seen in every candidate: `spread` per trial (`k` shared evenly).
pub fn choose(scans: &[&TrialScan], weights: &[f64], min: usize, k: usize, radius: f64) -> Vec<Vec<usize>> {
    let per_trial = || scans.iter().map(|s| spread(&s.counts, k.div_ceil(scans.len().max(1)), min)).collect();
    if k == 0 || radius <= 0.0 {
        return per_trial();
    }
    let stride = weights.len() * 3;
    let rows = || scans.iter().flat_map(|s| s.rows.chunks_exact(stride));
    let common: Vec<usize> = (0..weights.len())
        .filter(|&m| weights[m] > 0.0 && rows().all(|r| r[3 * m..3 * m + 3].iter().all(|v| !v.is_nan())))
        .collect();
    if common.len() < 3 {
        return per_trial();
    }
    let features = features(rows(), &common);
    let d = 3 * common.len();
    let n = features.len() / d.max(1);
    let dist2 = |a: usize, b: usize| -> f64 {
        let (x, y) = (&features[a * d..(a + 1) * d], &features[b * d..(b + 1) * d]);
        x.iter().zip(y).map(|(p, q)| (p - q) * (p - q)).sum::<f64>() / common.len() as f64
    };
    let r2 = radius * radius;
    let mut net: Vec<usize> = Vec::new();
    for c in 0..n {
        if net.iter().all(|&j| dist2(c, j) > r2) {
            net.push(c);
        }
    }
    if net.len() > k {
        net = farthest_first(n, k, dist2);
        net.sort_unstable();
    }
    // Back to (trial, frame).
    let mut out: Vec<Vec<usize>> = scans.iter().map(|_| Vec::new()).collect();
    let (mut trial, mut base) = (0, 0);
    for c in net {
        while c >= base + scans[trial].candidates.len() {
            base += scans[trial].candidates.len();
            trial += 1;
        }
        out[trial].push(scans[trial].candidates[c - base]);
    }
    out
}

/// `k` of `n` points by farthest-first traversal from point 0 (ties to the earlier point).
pub fn farthest_first(n: usize, k: usize, dist2: impl Fn(usize, usize) -> f64) -> Vec<usize> {
    let mut chosen = Vec::with_capacity(k.min(n));
    let mut near = vec![f64::INFINITY; n];
    let mut next = 0;
    while chosen.len() < k.min(n) {
        chosen.push(next);
        let mut far = (f64::NEG_INFINITY, next);
        for (c, d) in near.iter_mut().enumerate() {
            *d = d.min(dist2(c, next));
            if *d > far.0 {
                far = (*d, c);
            }
        }
        if far.0 <= 0.0 {
            break;
        }
        next = far.1;
    }
    chosen
}

/// Each row's `common` markers about their centroid, rotated onto the first row's (Kabsch):
/// `3 × common` values per row.
fn features<'a>(rows: impl Iterator<Item = &'a [f64]>, common: &[usize]) -> Vec<f64> {
    let at = |r: &[f64], m: usize| Vector3::new(r[3 * m], r[3 * m + 1], r[3 * m + 2]);
    let centred = |r: &[f64]| -> Vec<Vector3<f64>> {
        let c = common.iter().fold(Vector3::zeros(), |s, &m| s + at(r, m)) / common.len() as f64;
        common.iter().map(|&m| at(r, m) - c).collect()
    };
    let mut out = Vec::new();
    let mut reference: Option<Vec<Vector3<f64>>> = None;
    for r in rows {
        let x = centred(r);
        let y = reference.get_or_insert_with(|| x.clone());
        let h = x.iter().zip(y.iter()).fold(Matrix3::zeros(), |h, (a, b)| h + a * b.transpose());
        let rot = rotation(&h);
        for p in &x {
            out.extend((rot * p).iter());
        }
    }
    out
}

/// The rotation `R` that maximises `tr(R H)` for `H = Σ x yᵀ` (so `R x ≈ y`), a proper one.
fn rotation(h: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else { return Matrix3::identity() };
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(poses: &[f64]) -> TrialScan {
        // Four markers; the pose moves the fourth along x by `p` metres.
        let mut rows = Vec::new();
        for &p in poses {
            rows.extend_from_slice(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, p, 0.0, 1.0]);
        }
        TrialScan { counts: vec![4; poses.len()], candidates: (0..poses.len()).collect(), rows }
    }

    #[test]
    fn a_repeated_motion_gives_frames_of_its_first_cycle_only() {
        let cycle = [0.0, 0.1, 0.2, 0.1];
        let walk: Vec<f64> = cycle.iter().cycle().take(40).copied().collect();
        let chosen = choose(&[&scan(&walk), &scan(&walk)], &[1.0; 4], 3, 96, 0.01);
        assert_eq!(chosen, vec![vec![0, 1, 2], vec![]]);
    }

    #[test]
    fn a_standing_trial_gives_one_frame() {
        let chosen = choose(&[&scan(&[0.0; 20])], &[1.0; 4], 3, 20, 0.01);
        assert_eq!(chosen, vec![vec![0]]);
    }

    #[test]
    fn more_poses_than_frames_are_thinned_farthest_first() {
        let poses: Vec<f64> = (0..10).map(|i| i as f64).collect();
        let chosen = choose(&[&scan(&poses)], &[1.0; 4], 3, 3, 0.01);
        assert_eq!(chosen, vec![vec![0, 5, 9]]);
    }

    #[test]
    fn radius_zero_spreads_over_time() {
        let chosen = choose(&[&scan(&[0.0; 20])], &[1.0; 4], 3, 4, 0.0);
        assert_eq!(chosen, vec![vec![2, 7, 12, 17]]);
    }
}
