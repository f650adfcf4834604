//! The trial's rigid marker pairs: markers on one body or on bodies one or two joints apart
//! whose distance stays the same over the trial (robust spread at most `rigid_sd_mm`), with
//! that distance and spread measured on frames sampled evenly over the trial.

use crate::model::Model;
use crate::solve::settings::LabelQcSettings;

/// One rigid pair: model markers `a < b`, their distance (m) and tolerance (m): `noise_sds`
/// robust standard deviations.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pair {
    pub a: usize,
    pub b: usize,
    pub reference: f64,
    pub tolerance: f64,
}

/// Joints between two bodies of the tree (`usize::MAX` when they share no root). Walks up
/// from both to their common ancestor, without allocating.
pub(crate) fn tree_distance(model: &Model, a: usize, b: usize) -> usize {
    let parent = |x: usize| model.bodies[x].parent;
    let depth = |mut x: usize| {
        let mut d = 0;
        while let Some(p) = parent(x) {
            x = p;
            d += 1;
        }
        d
    };
    let (mut x, mut y, mut dx, mut dy) = (a, b, depth(a), depth(b));
    let mut joints = 0;
    while dx > dy {
        x = parent(x).expect("deeper than its depth");
        (dx, joints) = (dx - 1, joints + 1);
    }
    while dy > dx {
        y = parent(y).expect("deeper than its depth");
        (dy, joints) = (dy - 1, joints + 1);
    }
    while x != y {
        match (parent(x), parent(y)) {
            (Some(px), Some(py)) => (x, y, joints) = (px, py, joints + 2),
            _ => return usize::MAX,
        }
    }
    joints
}

/// [`tree_distance`] between every two bodies, row-major (`nb × nb`): computed once per trial
/// rather than once per marker pair.
pub(crate) fn body_distances(model: &Model) -> Vec<usize> {
    let nb = model.bodies.len();
    (0..nb * nb).map(|k| tree_distance(model, k / nb, k % nb)).collect()
}

/// Candidate pairs among the `used` markers: on one body or bodies at most two joints apart.
pub(crate) fn candidate_pairs(model: &Model, used: &[bool]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let markers = &model.markers;
    let (nb, joints) = (model.bodies.len(), body_distances(model));
    for (a, ma) in markers.iter().enumerate().filter(|(a, _)| used[*a]) {
        for (b, mb) in markers.iter().enumerate().skip(a + 1).filter(|(b, _)| used[*b]) {
            if joints[ma.body * nb + mb.body] <= 2 {
                out.push((a, b));
            }
        }
    }
    out
}

/// Collects each candidate pair's distances on sampled frames, then keeps the rigid ones.
pub(crate) struct PairSampler {
    pairs: Vec<(usize, usize)>,
    samples: Vec<Vec<f64>>,
    stride: usize,
}

impl PairSampler {
    pub(crate) fn new(pairs: Vec<(usize, usize)>, frames: usize, settings: &LabelQcSettings) -> PairSampler {
        let stride = frames.div_ceil(settings.sample_frames.max(1)).max(1);
        // Each pair's samples reserved once (no growth by reallocation, frame after frame).
        let samples = pairs.iter().map(|_| Vec::with_capacity(frames.div_ceil(stride))).collect();
        PairSampler { pairs, samples, stride }
    }

    /// Frame `f` of the trial, positions in model-marker order (NaN where not observed).
    pub(crate) fn frame(&mut self, f: usize, x: &[[f64; 3]]) {
        if !f.is_multiple_of(self.stride) {
            return;
        }
        for (k, &(a, b)) in self.pairs.iter().enumerate() {
            let d = distance(&x[a], &x[b]);
            if d.is_finite() {
                self.samples[k].push(d);
            }
        }
    }

    /// The rigid pairs: sampled in at least 10 frames, robust spread at most `rigid_sd_mm`.
    pub(crate) fn rigid(mut self, settings: &LabelQcSettings) -> Vec<Pair> {
        let mut out = Vec::new();
        let mut keys = Vec::new();
        for (k, &(a, b)) in self.pairs.iter().enumerate() {
            let s = &mut self.samples[k];
            if s.len() < 10 {
                continue;
            }
            // Distances and their deviations are finite and at least +0.
            let med = median_nonnegative(s.iter().copied(), &mut keys);
            // Most candidate pairs are far from rigid: when fewer than half the deviations are
            // within a hair above the limit, their median is above it, and so is `sd`; the
            // pair is left without selecting the median deviation.
            let limit = settings.rigid_sd_mm * 1e-3;
            let within = limit / 1.4826 * (1.0 + 1e-9);
            if limit >= 0.0 && s.iter().filter(|d| (*d - med).abs() <= within).count() < s.len() / 2 {
                continue;
            }
            let sd = 1.4826 * median_nonnegative(s.iter().map(|d| (d - med).abs()), &mut keys);
            if sd <= settings.rigid_sd_mm * 1e-3 {
                out.push(Pair { a, b, reference: med, tolerance: settings.noise_sds * sd.max(1e-3) });
            }
        }
        out
    }
}

/// Distance between two points (NaN when either is missing).
pub(crate) fn distance(p: &[f64; 3], q: &[f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

pub(crate) use crate::solve::median;

/// The [`median`] of `values`, all of them +0 or more and not NaN (`keys`: scratch). The same
/// value as [`median`] gives: on such values the order of their bit patterns as integers is
/// their order as numbers (and [`f64::total_cmp`]'s), and integers select several times faster
/// than floats compared by `total_cmp` (the reference distances' medians were ~1.6 % of a
/// synthetic conversion's CPU).
pub(crate) fn median_nonnegative(values: impl Iterator<Item = f64>, keys: &mut Vec<u64>) -> f64 {
    keys.clear();
    keys.extend(values.map(|v| {
        debug_assert!(v.is_sign_positive() && !v.is_nan(), "{v} is not +0 or more");
        v.to_bits()
    }));
    let n = keys.len();
    if n == 0 {
        return f64::NAN;
    }
    let (lower, mid, _) = keys.select_nth_unstable(n / 2);
    let mid = f64::from_bits(*mid);
    if n % 2 == 1 {
        mid
    } else {
        let below = lower.iter().copied().max().map_or(mid, f64::from_bits);
        0.5 * (below + mid)
    }
}
