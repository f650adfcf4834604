//! Unfittable frames explained (issue 32, item 2): runs of frames whose marker RMSE is far above
//! the trial's, with the markers that misfit most and whether the data or the model is to blame
//! (`docs/KINEMATICS.md`, "Unfittable frames").
//!
//! A solved frame is *unfittable* when its marker RMSE exceeds [`RMSE_FACTOR`] × the trial's
//! median RMSE and [`RMSE_FLOOR_MM`]; consecutive such frames (bridged frames neither join nor
//! break a run) form one run. A run is blamed on the **data** when its markers moved against
//! their rigid partners (the observed distance of its worst marker to another observed marker on
//! the same body differs from the model's, which is rigid, by more than [`RIGID_MOVE_MM`]), or
//! when its misfit appears or vanishes within one frame interval (the RMSE steps by more than
//! half the run's excess over the median between the run's edge frame and its neighbour: a
//! marker or a segment's markers displaced, not a pose the model cannot take); otherwise on the
//! **model** (it cannot reach the markers). Such frames make no trial `failed`.

use serde::{Deserialize, Serialize};

/// A frame's RMSE above this multiple of the trial's median RMSE (and [`RMSE_FLOOR_MM`]) is unfittable.
pub const RMSE_FACTOR: f64 = 3.0;
/// ... and above this absolute floor (mm): clean trials' noise never flags a frame.
pub const RMSE_FLOOR_MM: f64 = 10.0;

/// The `auto` pre-solve's outlier threshold ([`crate::solve::presolve::outlier_threshold`]) over
/// the frames that fit: unfittable frames (bad data, reported on their own) are left out of its
/// median and MAD, so a trial with a few knocked markers re-solves the same outliers elsewhere
/// as it would without them (frames of `rmse`, m; NaN where none).
pub fn presolve_threshold(rmse: &[f64]) -> f64 {
    let mut v: Vec<f64> = rmse.iter().copied().filter(|x| x.is_finite()).collect();
    let limit = (RMSE_FACTOR * crate::solve::median(&mut v)).max(RMSE_FLOOR_MM * 1e-3);
    let fitting: Vec<f64> = rmse.iter().copied().filter(|x| x.is_finite() && *x <= limit).collect();
    crate::solve::presolve::outlier_threshold(&fitting)
}
/// A marker whose distance to an observed marker on its own body differs from the model's by
/// more than this (mm) moved against its rigid partners.
pub const RIGID_MOVE_MM: f64 = 10.0;
/// Markers listed per run.
pub const RUN_MARKERS: usize = 5;

/// The fit of one solved frame, as [`crate::pipeline::running::marker_errors::MarkerErrors`]
/// records it: RMSE (m), its three worst markers with their errors (m; `usize::MAX` where
/// fewer), and how far the worst one moved against its rigid partners (m).
#[derive(Clone, Copy, Debug)]
pub struct FrameFit {
    pub frame: usize,
    pub rmse: f64,
    pub top: [(usize, f64); 3],
    pub rigid_move: f64,
}

/// One run of unfittable frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Unfittable {
    /// First and last frame of the run (0-based, inclusive).
    pub first: usize,
    pub last: usize,
    /// Solved frames in the run.
    pub frames: usize,
    /// The run's largest frame RMSE, and the limit it passed (mm).
    pub peak_rmse_mm: f64,
    pub limit_mm: f64,
    /// Markers with the largest errors over the run (largest first), with their largest error (mm).
    pub markers: Vec<(String, f64)>,
    /// Largest move of a worst marker against its rigid partners (mm).
    pub rigid_move_mm: f64,
    /// "data" (the markers moved: the data is bad here) or "model" (it cannot reach them).
    pub cause: String,
    /// One sentence saying so.
    pub why: String,
}

/// The unfittable runs of a trial's solved frames `fits` (in frame order); `names`: the model's markers.
pub fn unfittable_runs(fits: &[FrameFit], names: &[String]) -> Vec<Unfittable> {
    let mut rmse: Vec<f64> = fits.iter().map(|f| f.rmse).filter(|r| r.is_finite()).collect();
    let median = crate::solve::median(&mut rmse);
    if !median.is_finite() {
        return Vec::new();
    }
    let limit = (RMSE_FACTOR * median).max(RMSE_FLOOR_MM * 1e-3);
    let bad = |k: usize| fits[k].rmse > limit;
    let mut out = Vec::new();
    let mut k = 0;
    while k < fits.len() {
        if !bad(k) {
            k += 1;
            continue;
        }
        let a = k;
        while k < fits.len() && bad(k) {
            k += 1;
        }
        out.push(run(fits, a, k, median, limit, names));
    }
    out
}

/// The verdict's reason text for `runs`: "the data is bad here: …" over the runs blamed on the
/// data (none when there are none).
pub fn reason(runs: &[Unfittable]) -> Option<String> {
    let data: Vec<String> =
        runs.iter()
            .filter(|u| u.cause == "data")
            .map(|u| {
                if u.first == u.last {
                    format!("frame {}", u.first)
                } else {
                    format!("frames {}–{}", u.first, u.last)
                }
            })
            .collect();
    (!data.is_empty()).then(|| format!("the data is bad here: {} (markers moved; not a failed solve)", data.join(", ")))
}

/// Whether the misfit of a run with frame RMSEs `run` (m) appears or vanishes within one frame
/// interval: at an edge with a directly neighbouring solved frame (its RMSE `before` or
/// `after`), the RMSE steps by more than half the run's excess over the trial's `median`.
pub fn misfit_steps(before: Option<f64>, run: &[f64], after: Option<f64>, median: f64) -> bool {
    let (Some(first), Some(last)) = (run.first(), run.last()) else { return false };
    let step = 0.5 * (run.iter().copied().fold(0.0, f64::max) - median);
    before.is_some_and(|x| first - x > step) || after.is_some_and(|y| last - y > step)
}

/// The run of `fits[a..b]`.
fn run(fits: &[FrameFit], a: usize, b: usize, median: f64, limit: f64, names: &[String]) -> Unfittable {
    let r = &fits[a..b];
    let peak = r.iter().map(|f| f.rmse).fold(0.0, f64::max);
    let mut markers: Vec<(usize, f64)> = Vec::new();
    for &(m, d) in r.iter().flat_map(|f| f.top.iter()).filter(|t| t.0 != usize::MAX) {
        match markers.iter_mut().find(|x| x.0 == m) {
            Some(x) => x.1 = x.1.max(d),
            None => markers.push((m, d)),
        }
    }
    markers.sort_by(|x, y| y.1.total_cmp(&x.1).then(x.0.cmp(&y.0)));
    markers.truncate(RUN_MARKERS);
    let rigid = r.iter().map(|f| f.rigid_move).filter(|v| v.is_finite()).fold(0.0, f64::max);
    let next = |k: usize, j: usize| (fits[j].frame == fits[k].frame + 1).then_some(fits[j].rmse);
    let before = (a > 0).then(|| next(a - 1, a)).flatten().map(|_| fits[a - 1].rmse);
    let after = (b < fits.len()).then(|| next(b - 1, b)).flatten();
    let rmse: Vec<f64> = r.iter().map(|f| f.rmse).collect();
    let moved = rigid > RIGID_MOVE_MM * 1e-3;
    let data = moved || misfit_steps(before, &rmse, after, median);
    let (first, last) = (r[0].frame, r[r.len() - 1].frame);
    let list: Vec<String> = markers.iter().map(|&(m, d)| format!("{} {:.0} mm", names[m], 1e3 * d)).collect();
    let frames = if first == last { format!("frame {first}") } else { format!("frames {first}–{last}") };
    let why = if data {
        let how = if moved {
            format!("moved {:.0} mm against their rigid partners", 1e3 * rigid)
        } else {
            "jumped away from the motion within one frame".to_string()
        };
        format!(
            "the data is bad here: {frames}, RMSE up to {:.1} mm (limit {:.1} mm): markers {} {how}",
            1e3 * peak,
            1e3 * limit,
            list.join(", ")
        )
    } else {
        format!(
            "the model cannot reach the markers: {frames}, RMSE up to {:.1} mm (limit {:.1} mm): markers {}",
            1e3 * peak,
            1e3 * limit,
            list.join(", ")
        )
    };
    Unfittable {
        first,
        last,
        frames: r.len(),
        peak_rmse_mm: 1e3 * peak,
        limit_mm: 1e3 * limit,
        markers: markers.iter().map(|&(m, d)| (names[m].clone(), 1e3 * d)).collect(),
        rigid_move_mm: 1e3 * rigid,
        cause: if data { "data" } else { "model" }.into(),
        why,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(frame: usize, rmse_mm: f64, rigid_mm: f64) -> FrameFit {
        FrameFit {
            frame,
            rmse: rmse_mm * 1e-3,
            top: [(0, 2.0 * rmse_mm * 1e-3), (1, 1e-3), (usize::MAX, 0.0)],
            rigid_move: rigid_mm * 1e-3,
        }
    }

    #[test]
    fn a_run_far_above_the_median_is_found_and_blamed() {
        let names = vec!["A".to_string(), "B".to_string()];
        // Clean: nothing.
        let clean: Vec<FrameFit> = (0..50).map(|f| fit(f, 2.0 + (f % 3) as f64, 0.0)).collect();
        assert!(unfittable_runs(&clean, &names).is_empty());
        // Frames 20–24 jump to 30 mm and back: data.
        let mut fits = clean.clone();
        for f in &mut fits[20..25] {
            f.rmse = 30e-3;
            f.top[0].1 = 60e-3;
        }
        let runs = unfittable_runs(&fits, &names);
        assert_eq!(runs.len(), 1, "{runs:?}");
        assert_eq!((runs[0].first, runs[0].last, runs[0].frames), (20, 24, 5));
        assert_eq!(runs[0].cause, "data");
        assert_eq!(runs[0].markers[0].0, "A");
        assert!(runs[0].why.starts_with("the data is bad here"), "{}", runs[0].why);
        // A misfit that grows and fades slowly, the markers rigid on their bodies: the model.
        let mut ramp = clean;
        for (k, f) in ramp.iter_mut().enumerate() {
            let x = 1.0 - ((k as f64 - 25.0) / 12.0).abs();
            f.rmse = (3.0 + 30.0 * x.max(0.0)) * 1e-3;
        }
        let runs = unfittable_runs(&ramp, &names);
        assert_eq!(runs.len(), 1, "{runs:?}");
        assert_eq!(runs[0].cause, "model", "{runs:?}");
    }
}
