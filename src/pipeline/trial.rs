//! One trial's inputs and results: matching its markers, its observations and gaps, calibrating
//! the subject (from a static trial or frames of the motion). The frames themselves are solved in
//! [`super::stream`]: warm-started from the previous one, long trials cut into segments solved in
//! parallel (each cold-started), frames with too few markers reported and bridged from their
//! neighbours.

use super::matching::{match_names, MarkerMatch, MatchError};
use super::stats::{GapStats, MarkerGaps};
use super::Context;
use crate::io::MarkerTrial;
use crate::kinematics::assembly::FrameProblem;
use crate::kinematics::backend::BackendError;
use crate::solve::calibrate::track;
use crate::solve::placement::place_markers;
use crate::solve::{calibrate, make_qp, Calibration, FrameSolver, FrameStats};

/// An error from a frame sink (e.g. writing the frame failed).
pub type SinkError = Box<dyn std::error::Error + Send + Sync>;

/// Why a trial could not be solved.
#[derive(Debug, thiserror::Error)]
pub enum TrialError {
    #[error("trial '{trial}': none of its markers matches the model's (trial has: {trial_labels}; model has: {model_labels})")]
    NoMarkerMatch { trial: String, trial_labels: String, model_labels: String },
    #[error("trial '{trial}': {source}")]
    Matching { trial: String, source: MatchError },
    #[error("trial '{trial}' has no frames")]
    Empty { trial: String },
    #[error("trial '{trial}': no frame has at least {min} observed markers with a weight above 0, nothing to solve")]
    NothingSolvable { trial: String, min: usize },
    #[error("trial '{trial}': no frame has at least {min} observed markers, nothing to calibrate on")]
    NothingToCalibrate { trial: String, min: usize },
    #[error("trial '{trial}': evaluation backend failed: {source}")]
    Backend { trial: String, source: BackendError },
    #[error("trial '{trial}': frame {frame}: {source}")]
    Output { trial: String, frame: usize, source: SinkError },
}

/// Result of one trial.
#[derive(Clone, Debug)]
pub struct TrialResult {
    pub name: String,
    /// Proxies per frame.
    pub proxies: Vec<Vec<f64>>,
    /// Per-frame statistics (bridged frames have status `TooFewMarkers`).
    pub stats: Vec<FrameStats>,
    /// Per-frame solve time (s), I/O excluded: wall time from the frame's start to its end in its
    /// lane, which includes waiting for the other frames of its batched evaluations.
    pub frame_seconds: Vec<f64>,
    pub calibration: Calibration,
    /// Frames bridged from neighbours because too few markers were observed.
    pub bridged: Vec<usize>,
    /// Frames whose result came from the `auto` pre-solve pass (outliers solved again).
    pub presolved: Vec<usize>,
    /// Model markers the trial does not provide, and trial labels the model lacks.
    pub unmatched_model: Vec<String>,
    pub unmatched_trial: Vec<String>,
    /// `(file label, model marker)` for markers matched other than exactly.
    pub renamed: Vec<(String, String)>,
    /// Missing data of the matched markers.
    pub gaps: GapStats,
    /// Wall time of all frames (s), calibration excluded.
    pub wall_seconds: f64,
    pub threads: usize,
}

/// For each model marker, the trial column that observes it (see [`super::matching`]); `name`
/// names the trial in errors.
pub fn match_markers(ctx: &Context, name: &str, trial: &MarkerTrial) -> Result<MarkerMatch, TrialError> {
    let names: Vec<&str> = ctx.model.markers.iter().map(|m| m.name.as_str()).collect();
    match_names(&names, &trial.labels).map_err(|source| TrialError::Matching { trial: name.into(), source })
}

/// Missing data of the matched markers; `below_min` frames had too few markers to solve.
pub fn gap_stats(ctx: &Context, trial: &MarkerTrial, map: &[Option<usize>], below_min: usize) -> GapStats {
    let n = trial.n_frames().max(1) as f64;
    let markers: Vec<MarkerGaps> = ctx
        .model
        .markers
        .iter()
        .zip(map)
        .filter_map(|(m, c)| c.map(|c| (m, trial.gaps_and_longest(c))))
        .map(|(m, (missing, longest_gap))| MarkerGaps {
            marker: m.name.clone(),
            missing,
            missing_fraction: missing as f64 / n,
            longest_gap,
        })
        .collect();
    GapStats { missing_samples: markers.iter().map(|m| m.missing).sum(), frames_below_min_markers: below_min, markers }
}

/// Observations in model-marker order, frame-major (`frame · 3M + 3·marker + axis`), NaN gaps.
pub fn observations(trial: &MarkerTrial, map: &[Option<usize>]) -> Vec<f64> {
    let nm = map.len();
    let mut out = vec![f64::NAN; trial.n_frames() * nm * 3];
    for f in 0..trial.n_frames() {
        for (m, col) in map.iter().enumerate() {
            if let Some(p) = col.and_then(|c| trial.position(f, c)) {
                out[(f * nm + m) * 3..(f * nm + m) * 3 + 3].copy_from_slice(&p);
            }
        }
    }
    out
}

/// Markers observed in a frame that the solver uses (weight > 0).
fn observed_count(obs: &[f64], weights: &[f64]) -> usize {
    obs.chunks_exact(3).zip(weights).filter(|(c, &w)| w > 0.0 && c.iter().all(|v| !v.is_nan())).count()
}

/// Up to `k` frames spread evenly over those with the most observed markers.
fn calibration_frames(obs: &[f64], weights: &[f64], stride: usize, k: usize, min: usize) -> Vec<usize> {
    let counts: Vec<usize> = obs.chunks(stride).map(|o| observed_count(o, weights)).collect();
    let best = counts.iter().copied().max().unwrap_or(0);
    let good: Vec<usize> = (0..counts.len()).filter(|&f| counts[f] >= min && counts[f] + 2 >= best).collect();
    if good.is_empty() || k == 0 {
        return good;
    }
    let n = good.len().min(k);
    (0..n).map(|i| good[(i * good.len()) / n + good.len() / (2 * n)]).collect()
}

/// Calibrates one subject's morphology from frames pooled over `trials` (a static trial, or
/// the motion trials themselves).
pub fn calibrate_subject(ctx: &Context, trials: &[(&str, &MarkerTrial)]) -> Result<Calibration, TrialError> {
    let settings = &ctx.settings;
    let stride = 3 * ctx.model.markers.len();
    let per_trial = settings.calibration_frames.div_ceil(trials.len().max(1));
    let eval = ctx.evaluator();
    // With placement, markers flagged fixed alone inform the scales when the model flags any.
    let placing = settings.marker_placement;
    let any_fixed = ctx.model.markers.iter().any(|m| m.fixed);
    let weights: Vec<f64> = ctx
        .model
        .markers
        .iter()
        .zip(&ctx.calibration_weights)
        .map(|(m, &w)| if placing && any_fixed && !m.fixed { 0.0 } else { w })
        .collect();
    // Coordinate targets (IK coordinate tasks) hold in calibration too.
    let (coord_ref, coord_w) = ctx.coordinate_tracking();
    let template =
        FrameProblem { observed: &[], marker_weights: &weights, tracking_ref: &coord_ref, tracking_weights: &coord_w };
    let mut solver = FrameSolver::new(&eval, settings.clone(), make_qp(settings.qp));
    let p0 = ctx.proxy.default_proxies();
    let mut pooled: Vec<f64> = Vec::new();
    let mut starts: Vec<Vec<f64>> = Vec::new();
    for (name, t) in trials {
        let map = match_markers(ctx, name, t)?.columns;
        if map.iter().all(Option::is_none) {
            return Err(no_match(ctx, name, t));
        }
        let o = observations(t, &map);
        let chosen = calibration_frames(&o, &weights, stride, per_trial, settings.min_markers);
        let Some(&last) = chosen.last() else { continue };
        // Track from the first frame to the last chosen one so that every chosen frame starts
        // from a pose continuous with the motion (a cold start far into a motion can land in a
        // wrong local minimum).
        let first = (0..=last)
            .find(|&f| observed_count(&o[f * stride..(f + 1) * stride], &weights) >= settings.min_markers)
            .unwrap_or(0);
        let slices: Vec<&[f64]> = (first..=last).map(|f| &o[f * stride..(f + 1) * stride]).collect();
        let tracked = track(&mut solver, &slices, &template, &p0);
        for f in chosen {
            pooled.extend_from_slice(&o[f * stride..(f + 1) * stride]);
            starts.push(tracked[f - first].clone());
        }
    }
    if pooled.is_empty() {
        let trial = trials.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ");
        return Err(TrialError::NothingToCalibrate { trial, min: settings.min_markers });
    }
    let slices: Vec<&[f64]> = pooled.chunks(stride).collect();
    let mut cal = calibrate(&mut solver, &slices, &template, &p0, &starts);
    if placing {
        let movable: Vec<bool> = ctx.model.markers.iter().map(|m| !m.fixed).collect();
        let placed = place_markers(&ctx.model, &ctx.proxy, &slices, &cal.frame_proxies, &movable);
        cal.marker_offsets = Some(placed.iter().zip(&ctx.model.markers).map(|(p, m)| p.unwrap_or(m.offset)).collect());
    }
    Ok(cal)
}

pub(crate) fn no_match(ctx: &Context, name: &str, trial: &MarkerTrial) -> TrialError {
    TrialError::NoMarkerMatch {
        trial: name.into(),
        trial_labels: trial.labels.join(", "),
        model_labels: ctx.model.markers.iter().map(|m| m.name.clone()).collect::<Vec<_>>().join(", "),
    }
}
