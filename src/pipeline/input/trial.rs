//! One trial's inputs: matching its markers to the model's, its observations and gaps, masking
//! implausible coordinates, counting the frames there is enough to solve, and the error of a trial
//! that cannot be solved. The frames themselves are solved in [`crate::pipeline::running`].

use crate::io::MarkerTrial;
use crate::kinematics::backend::BackendError;
use crate::pipeline::context::Context;
use crate::pipeline::input::matching::{match_names_with, MarkerMatch, MatchError};
use crate::pipeline::stats::{GapStats, MarkerGaps};

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

/// For each model marker, the trial column that observes it (see [`crate::pipeline::input::matching`]); `name`
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

/// Marker coordinates farther than this from the origin of the data (m, after conversion to
/// the model's units) are masked as gaps: no motion capture volume is a kilometre across, and
/// such values (a `POINT:SCALE` of 3e38, a marker at 1e15 mm) only ruin the frames they are in.
pub const MAX_COORDINATE_M: f64 = 1000.0;

// Masking beyond a limit is the readers' (`crate::io`): re-exported for the pipeline's callers.
pub use crate::io::{mask_beyond, ABSURD_COORDINATE_M};

/// Masks (sets to NaN, a gap) every marker sample with a coordinate that is not finite or is
/// beyond [`MAX_COORDINATE_M`] (the trial in the model's units); returns a warning saying how
/// many, or `None` when none were.
pub fn mask_implausible(trial: &mut MarkerTrial) -> Option<String> {
    mask_beyond(trial, MAX_COORDINATE_M)
}

/// Frames of `trial` with at least `min_markers` markers observed that the solver uses
/// (weight > 0); `map` is the trial column of each model marker.
pub fn solvable_frames(ctx: &Context, trial: &MarkerTrial, map: &[Option<usize>]) -> usize {
    let min = ctx.settings.min_markers;
    (0..trial.n_frames())
        .filter(|&f| {
            let seen = map
                .iter()
                .zip(&ctx.marker_weights)
                .filter(|(c, &w)| w > 0.0 && c.is_some_and(|c| trial.position(f, c).is_some()))
                .count();
            seen >= min.max(1)
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn far_and_non_finite_samples_are_masked_as_gaps() {
        let mut t = MarkerTrial {
            labels: vec!["a".into(), "b".into()],
            rate_hz: 100.0,
            times: vec![0.0],
            frame_numbers: vec![1],
            positions: vec![0.1, 0.2, 0.3, 1e12, 0.0, 0.0],
            source_units: "m".into(),
            warnings: vec![],
        };
        let w = mask_implausible(&mut t).unwrap();
        assert!(w.contains("1 marker samples"), "{w}");
        assert!(t.position(0, 0).is_some() && t.position(0, 1).is_none());
        assert_eq!(mask_implausible(&mut t), None);
    }
}
