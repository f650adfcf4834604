//! The per-frame screen: each marker's misfit to its rigid partners, and — only in frames where
//! a marker is flagged — the exchanges of two labels that explain the misfit, then the markers
//! that must be masked for what is left. Allocation-free per frame once built.

use super::rigid::{body_distances, distance, median, Pair};
use crate::model::Model;

/// What one frame's screen found.
#[derive(Clone, Debug, Default)]
pub(crate) struct Findings {
    /// `(a, b, before, after)`: labels `a < b` exchanged; the mean score (m) of the two before and
    /// after the exchange.
    pub swaps: Vec<(usize, usize, f64, f64)>,
    /// `(m, score)`: marker masked, its score (m) before.
    pub masks: Vec<(usize, f64)>,
}

/// The screen of one trial.
pub(crate) struct Screen {
    pairs: Vec<Pair>,
    /// Per marker: the indices of its rigid pairs.
    partners: Vec<Vec<usize>>,
    /// Per marker: the markers whose label it may have exchanged with (its left/right mirror,
    /// markers on its body or bodies up to two joints away).
    candidates: Vec<Vec<usize>>,
    threshold: f64,
    work: Vec<[f64; 3]>,
    flagged: Vec<usize>,
    considered: Vec<usize>,
    /// Every marker's score in the frame screened last, and in the frame before.
    pub(crate) scores: Vec<f64>,
    pub(crate) previous: Vec<f64>,
    /// The previous frame as screened (exchanges applied, masks as gaps).
    last: Vec<[f64; 3]>,
    /// Per pair: its distance (m) in the last frame where both its markers were observed and
    /// kept (NaN before): the reference of the step test.
    local: Vec<f64>,
    /// A marker whose distances to its partners differ from their last kept values by more than
    /// this (m, median over the partners) has stepped away from its body.
    step_threshold: f64,
    scratch: Vec<f64>,
    /// Per pair: its distance (m) in the frame being screened (or in `work` in the step test),
    /// computed once per frame and shared by every marker of the pair.
    dist: Vec<f64>,
    /// Per pair: its excess ([`Self::excess`]) in the frame being screened.
    pair_excess: Vec<f64>,
    pub(crate) findings: Findings,
}

impl Screen {
    pub(crate) fn new(model: &Model, used: &[bool], pairs: Vec<Pair>, threshold_m: f64, step_m: f64) -> Screen {
        let nm = used.len();
        let np = pairs.len();
        let mut partners = vec![Vec::new(); nm];
        for (k, p) in pairs.iter().enumerate() {
            partners[p.a].push(k);
            partners[p.b].push(k);
        }
        let (nb, joints) = (model.bodies.len(), body_distances(model));
        let candidates = (0..nm)
            .map(|a| {
                if !used[a] || partners[a].is_empty() {
                    return Vec::new();
                }
                let mirror = mirror_of(model, a);
                (0..nm)
                    .filter(|&b| b != a && used[b])
                    .filter(|&b| Some(b) == mirror || joints[model.markers[a].body * nb + model.markers[b].body] <= 1)
                    .collect()
            })
            .collect();
        Screen {
            pairs,
            partners,
            candidates,
            threshold: threshold_m,
            work: vec![[f64::NAN; 3]; nm],
            flagged: Vec::with_capacity(nm),
            considered: Vec::with_capacity(nm),
            scores: vec![0.0; nm],
            previous: vec![0.0; nm],
            last: vec![[f64::NAN; 3]; nm],
            local: vec![f64::NAN; np],
            step_threshold: step_m,
            scratch: Vec::with_capacity(nm),
            dist: vec![f64::NAN; np],
            pair_excess: vec![f64::NAN; np],
            findings: Findings::default(),
        }
    }

    /// Rigid pairs in use.
    pub(crate) fn pair_count(&self) -> usize {
        self.pairs.len()
    }

    /// How far pair `k`'s distance in `x` is from its reference beyond its tolerance (NaN when
    /// a marker is missing).
    fn excess(&self, k: usize, x: &[[f64; 3]]) -> f64 {
        let p = &self.pairs[k];
        let d = distance(&x[p.a], &x[p.b]);
        ((d - p.reference).abs() - p.tolerance).max(0.0)
    }

    /// Marker `m`'s score in `x`: the median excess over its observed rigid partners (0 with
    /// none, or when `m` is missing).
    pub(crate) fn score(&mut self, m: usize, x: &[[f64; 3]]) -> f64 {
        if !x[m][0].is_finite() {
            return 0.0;
        }
        let mut s = std::mem::take(&mut self.scratch);
        s.clear();
        for &k in &self.partners[m] {
            let e = self.excess(k, x);
            if !e.is_nan() {
                s.push(e);
            }
        }
        let out = if s.is_empty() { 0.0 } else { median(&mut s) };
        self.scratch = s;
        out
    }

    /// Sum of marker `m`'s pair excesses in `x`.
    fn load(&self, m: usize, x: &[[f64; 3]]) -> f64 {
        self.partners[m].iter().map(|&k| self.excess(k, x)).filter(|e| !e.is_nan()).sum()
    }

    /// Every pair's distance and excess in `x`, into `self.dist` and `self.pair_excess` (the
    /// same values as [`Self::excess`] gives, each pair computed once rather than once per
    /// marker and once more for [`Self::touched`]).
    fn measure(&mut self, x: &[[f64; 3]]) {
        for (k, p) in self.pairs.iter().enumerate() {
            let d = distance(&x[p.a], &x[p.b]);
            self.dist[k] = d;
            self.pair_excess[k] = ((d - p.reference).abs() - p.tolerance).max(0.0);
        }
    }

    /// On the frame `x` just measured ([`Self::measure`]): the markers whose score is above the
    /// threshold into `self.flagged` (with `record`, every marker's score into `self.scores`),
    /// and the markers of the pairs whose excess is above it into `self.considered` (sorted).
    fn flag_measured(&mut self, x: &[[f64; 3]], record: bool) {
        let mut flagged = std::mem::take(&mut self.flagged);
        let mut s = std::mem::take(&mut self.scratch);
        flagged.clear();
        for m in 0..x.len() {
            let score = if self.partners[m].is_empty() || !x[m][0].is_finite() {
                0.0
            } else {
                // Excesses are +0 or more: with more than half of them 0 (a frame that fits),
                // the median is 0, found without selecting.
                let (mut observed, mut zeros) = (0, 0);
                for &k in &self.partners[m] {
                    let e = self.pair_excess[k];
                    observed += usize::from(!e.is_nan());
                    zeros += usize::from(e == 0.0);
                }
                if observed == 0 || zeros > observed / 2 {
                    0.0
                } else {
                    s.clear();
                    s.extend(self.partners[m].iter().map(|&k| self.pair_excess[k]).filter(|e| !e.is_nan()));
                    median(&mut s)
                }
            };
            if record {
                self.scores[m] = score;
            }
            if score > self.threshold {
                flagged.push(m);
            }
        }
        self.scratch = s;
        self.flagged = flagged;
        let mut t = std::mem::take(&mut self.considered);
        t.clear();
        for (k, p) in self.pairs.iter().enumerate() {
            if self.pair_excess[k] > self.threshold {
                t.push(p.a);
                t.push(p.b);
            }
        }
        t.sort_unstable();
        t.dedup();
        self.considered = t;
    }

    /// Screens frame `x` (model-marker order, NaN where missing): fills [`Self::findings`], and
    /// every marker's score in [`Self::scores`] (the previous frame's in [`Self::previous`]).
    pub(crate) fn frame(&mut self, x: &[[f64; 3]]) {
        self.findings.swaps.clear();
        self.findings.masks.clear();
        std::mem::swap(&mut self.scores, &mut self.previous);
        self.measure(x);
        self.flag_measured(x, true);
        let mut work = std::mem::take(&mut self.work);
        work.copy_from_slice(x);
        if self.considered.is_empty() {
            // `work` is `x`, whose distances are measured.
            self.steps(&mut work, true);
            self.last.copy_from_slice(&work);
            self.work = work;
            return;
        }
        // Exchanges, best first, of a marker of a pair that does not fit with a candidate (its
        // left/right mirror, a marker on its body or the next): the exchange that removes the
        // most misfit from the pairs it touches (more than twice the threshold, three quarters
        // of it at least) and leaves both within the threshold.
        for _ in 0..4 {
            let mut best: Option<(usize, usize, f64, f64, f64)> = None;
            let considered = std::mem::take(&mut self.considered);
            let candidates = std::mem::take(&mut self.candidates);
            for &a in &considered {
                if !work[a][0].is_finite() {
                    continue;
                }
                for &b in &candidates[a] {
                    if !work[b][0].is_finite() || (b < a && considered.binary_search(&b).is_ok()) {
                        continue;
                    }
                    let before = self.score(a, &work) + self.score(b, &work);
                    let load = self.load(a, &work) + self.load(b, &work);
                    work.swap(a, b);
                    let (sa, sb) = (self.score(a, &work), self.score(b, &work));
                    let left = self.load(a, &work) + self.load(b, &work);
                    // How far the exchanged labels are from where the previous frame had them:
                    // of two exchanges that fit alike (a mirror-symmetric marker set), the one
                    // that keeps the labels' paths continuous.
                    let step = |m: usize| {
                        let d = distance(&work[m], &self.last[m]);
                        if d.is_finite() {
                            d
                        } else {
                            0.0
                        }
                    };
                    let jumps = step(a) + step(b);
                    work.swap(a, b);
                    let gain = load - left;
                    let rank = gain - jumps;
                    if sa <= self.threshold
                        && sb <= self.threshold
                        && gain > 2.0 * self.threshold
                        && left <= 0.25 * load
                        && best.is_none_or(|bst| rank > bst.2)
                    {
                        best = Some((a.min(b), a.max(b), rank, before / 2.0, (sa + sb) / 2.0));
                    }
                }
            }
            self.considered = considered;
            self.candidates = candidates;
            let Some((a, b, _, before, after)) = best else { break };
            work.swap(a, b);
            self.findings.swaps.push((a, b, before, after));
            self.measure(&work);
            self.flag_measured(&work, false);
            if self.considered.is_empty() {
                break;
            }
        }
        // What no exchange explains: mask the marker that carries the most misfit, while one
        // scores above the threshold.
        for _ in 0..6 {
            self.measure(&work);
            self.flag_measured(&work, false);
            if self.flagged.is_empty() {
                break;
            }
            let mut pick = (self.flagged[0], f64::NEG_INFINITY);
            for &m in &self.flagged {
                let l = self.load(m, &work);
                if l > pick.1 {
                    pick = (m, l);
                }
            }
            let score = self.score(pick.0, &work);
            self.findings.masks.push((pick.0, score));
            work[pick.0] = [f64::NAN; 3];
        }
        self.steps(&mut work, false);
        self.last.copy_from_slice(&work);
        self.work = work;
    }

    /// Marker `m`'s step in `x` (whose pair distances are in `self.dist`): the median, over its
    /// partners observed now and with a kept distance, of how far their distance is from that
    /// (0 with none).
    fn step(&self, m: usize, x: &[[f64; 3]]) -> f64 {
        if !x[m][0].is_finite() {
            return 0.0;
        }
        // The second largest: a jump changes most of its marker's distances, a partner's jump
        // one of them (masked first, as the larger step).
        let (mut first, mut second) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        for &k in &self.partners[m] {
            let c = (self.dist[k] - self.local[k]).abs();
            if !c.is_finite() {
                continue;
            }
            if c > first {
                (first, second) = (c, first);
            } else if c > second {
                second = c;
            }
        }
        second.max(0.0)
    }

    /// The step test on the screened frame `work`: a marker whose distances to its partners
    /// changed abruptly since they were last kept (a jump in any direction changes them by a
    /// large part of its size, while the trial-wide test above needs them far from the trial's
    /// distances beyond their spread) is masked, the largest step first; then the distances of
    /// the pairs kept in this frame become the next frame's references. `measured`: the pairs'
    /// distances in `work` are in `self.dist` already.
    fn steps(&mut self, work: &mut [[f64; 3]], measured: bool) {
        let mut fresh = measured;
        for _ in 0..6 {
            if !fresh {
                for (k, p) in self.pairs.iter().enumerate() {
                    self.dist[k] = distance(&work[p.a], &work[p.b]);
                }
                fresh = true;
            }
            // A marker's step is the second largest change of its pairs: with fewer than two
            // pairs changed by more than a threshold of 0 or more (a clean frame), none steps.
            let changed = (0..self.pairs.len())
                .filter(|&k| (self.dist[k] - self.local[k]).abs() > self.step_threshold)
                .take(2)
                .count();
            if changed < 2 && self.step_threshold >= 0.0 {
                break;
            }
            let mut pick: Option<(usize, f64)> = None;
            for m in 0..work.len() {
                if self.partners[m].is_empty() {
                    continue;
                }
                let s = self.step(m, work);
                if s > self.step_threshold && pick.is_none_or(|p| s > p.1) {
                    pick = Some((m, s));
                }
            }
            let Some((m, s)) = pick else { break };
            self.findings.masks.push((m, s));
            work[m] = [f64::NAN; 3];
            fresh = false;
        }
        for (k, p) in self.pairs.iter().enumerate() {
            let d = if fresh { self.dist[k] } else { distance(&work[p.a], &work[p.b]) };
            if d.is_finite() {
                self.local[k] = d;
            }
        }
    }

    /// Whether exchanging `a` and `b` in frame `x` leaves both within the threshold (true when
    /// either is missing).
    pub(crate) fn exchange_fits(&mut self, a: usize, b: usize, x: &[[f64; 3]]) -> bool {
        if !x[a][0].is_finite() || !x[b][0].is_finite() {
            return true;
        }
        let mut work = std::mem::take(&mut self.work);
        work.copy_from_slice(x);
        work.swap(a, b);
        let ok = self.score(a, &work) <= self.threshold && self.score(b, &work) <= self.threshold;
        self.work = work;
        ok
    }
}

/// The model marker whose name is `a`'s with left and right exchanged (`LKNE` ↔ `RKNE`,
/// `l.ASIS` ↔ `r.ASIS`, `knee_l` ↔ `knee_r`), if the model has it.
pub(crate) fn mirror_of(model: &Model, a: usize) -> Option<usize> {
    let name = &model.markers[a].name;
    let flip = |c: char| match c {
        'L' => Some('R'),
        'R' => Some('L'),
        'l' => Some('r'),
        'r' => Some('l'),
        _ => None,
    };
    let mut names = Vec::new();
    let mut chars: Vec<char> = name.chars().collect();
    if let Some(f) = chars.first().copied().and_then(flip) {
        chars[0] = f;
        names.push(chars.iter().collect::<String>());
        chars[0] = name.chars().next().unwrap_or(' ');
    }
    if let Some(f) = chars.last().copied().and_then(flip) {
        let n = chars.len();
        if n > 2 && matches!(chars[n - 2], '_' | '.' | '-') {
            chars[n - 1] = f;
            names.push(chars.iter().collect::<String>());
        }
    }
    names.iter().find_map(|n| model.markers.iter().position(|m| &m.name == n)).filter(|&b| b != a)
}
