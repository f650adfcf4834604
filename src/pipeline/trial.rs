//! One trial's inputs and results: matching its markers, its observations and gaps, calibrating
//! the subject (from a static trial or frames of the motion). The frames themselves are solved in
//! [`super::stream`]: warm-started from the previous one, long trials cut into segments solved in
//! parallel (each cold-started), frames with too few markers reported and bridged from their
//! neighbours.

use super::matching::{match_names_with, MarkerMatch, MatchError};
use super::stats::{GapStats, MarkerGaps};
use super::Context;
use crate::io::MarkerTrial;
use crate::kinematics::backend::BackendError;
use crate::solve::{Calibration, FrameStats};

pub use super::calibration::calibrate_subject;

/// An error from a frame sink (e.g. writing the frame failed).
pub type SinkError = Box<dyn std::error::Error + Send + Sync>;

/// Why a trial could not be solved.
#[derive(Debug, thiserror::Error)]
pub enum TrialError {
    #[error("trial '{trial}': none of its markers matches the model's (trial has: {trial_labels}; model has: {model_labels})")]
    NoMarkerMatch { trial: String, trial_labels: String, model_labels: String },
    #[error("trial '{trial}': {source}")]
    Matching { trial: String, source: MatchError },
    #[error("trial '{trial}': reading its frames: {why}")]
    Read { trial: String, why: String },
    #[error("trial '{trial}' is unlabelled: its {markers} markers have no names (an unlabelled export, named M001… on reading); label it (e.g. in the capture software) before solving")]
    Unlabelled { trial: String, markers: usize },
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
    #[error("trial '{trial}': {message}")]
    Implausible { trial: String, message: String },
    #[error(transparent)]
    Anthropometry(#[from] crate::model::anthropometry::AnthropometryError),
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
    /// Per-marker RMSE and maximum, and the worst frames ([`super::marker_errors`]).
    pub marker_errors: super::marker_errors::MarkerErrorTable,
}

/// For each model marker, the trial column that observes it (see [`super::matching`]); `name`
/// names the trial in errors.
pub fn match_markers(ctx: &Context, name: &str, trial: &MarkerTrial) -> Result<MarkerMatch, TrialError> {
    let unnamed = trial.labels.iter().all(|l| crate::io::trc::is_unnamed_label(l));
    if unnamed && !trial.labels.is_empty() {
        return Err(TrialError::Unlabelled { trial: name.into(), markers: trial.labels.len() });
    }
    let names: Vec<&str> = ctx.model.markers.iter().map(|m| m.name.as_str()).collect();
    match_names_with(&names, &trial.labels, &ctx.synonyms())
        .map_err(|source| TrialError::Matching { trial: name.into(), source })
}

/// Missing data of the matched markers; `below_min` frames had too few markers to solve.
pub fn gap_stats(ctx: &Context, trial: &MarkerTrial, map: &[Option<usize>], below_min: usize) -> GapStats {
    let mut runs = GapRuns::new(trial.n_markers());
    runs.add(trial);
    runs.stats(ctx, map, trial.n_frames(), below_min)
}

/// Each trial column's missing frames, longest run of them and current run, accumulated window
/// by window ([`gap_stats`] of a trial read a window at a time).
pub(crate) struct GapRuns(Vec<(usize, usize, usize)>);

impl GapRuns {
    pub(crate) fn new(columns: usize) -> Self {
        GapRuns(vec![(0, 0, 0); columns])
    }

    /// Adds the frames of `w`, the next window.
    pub(crate) fn add(&mut self, w: &MarkerTrial) {
        for f in 0..w.n_frames() {
            for (c, r) in self.0.iter_mut().enumerate() {
                if w.position(f, c).is_none() {
                    r.0 += 1;
                    r.2 += 1;
                    r.1 = r.1.max(r.2);
                } else {
                    r.2 = 0;
                }
            }
        }
    }

    /// The gap statistics of the matched markers of a trial of `n` frames; `below_min` frames had
    /// too few markers to solve.
    pub(crate) fn stats(&self, ctx: &Context, map: &[Option<usize>], n: usize, below_min: usize) -> GapStats {
        let n = n.max(1) as f64;
        let markers: Vec<MarkerGaps> = ctx
            .model
            .markers
            .iter()
            .zip(map)
            .filter_map(|(m, c)| c.map(|c| (m, self.0[c])))
            .map(|(m, (missing, longest_gap, _))| MarkerGaps {
                marker: m.name.clone(),
                missing,
                missing_fraction: missing as f64 / n,
                longest_gap,
            })
            .collect();
        GapStats {
            missing_samples: markers.iter().map(|m| m.missing).sum(),
            frames_below_min_markers: below_min,
            markers,
        }
    }
}

/// Observations in model-marker order, frame-major (`frame · 3M + 3·marker + axis`), NaN gaps.
pub fn observations(trial: &MarkerTrial, map: &[Option<usize>]) -> Vec<f64> {
    let stride = 3 * map.len();
    let mut out = vec![f64::NAN; trial.n_frames() * stride];
    for (f, row) in out.chunks_exact_mut(stride.max(1)).enumerate() {
        observation_row(trial, map, f, row);
    }
    out
}

/// Frame `f`'s observations in model-marker order (`3·marker + axis`) into `row`, NaN gaps: one
/// row of [`observations`] without building the others.
pub fn observation_row(trial: &MarkerTrial, map: &[Option<usize>], f: usize, row: &mut [f64]) {
    for (col, o) in map.iter().zip(row.chunks_exact_mut(3)) {
        match col.and_then(|c| trial.position(f, c)) {
            Some(p) => o.copy_from_slice(&p),
            None => o.fill(f64::NAN),
        }
    }
}

pub(crate) fn no_match(ctx: &Context, name: &str, trial: &MarkerTrial) -> TrialError {
    TrialError::NoMarkerMatch {
        trial: name.into(),
        trial_labels: trial.labels.join(", "),
        model_labels: ctx.model.markers.iter().map(|m| m.name.clone()).collect::<Vec<_>>().join(", "),
    }
}
