//! What solving one trial gives: its poses, per-frame statistics and timings, the calibration it
//! was solved with, the frames bridged or solved again, its matching and gaps, and its marker
//! errors.

use crate::pipeline::stats::GapStats;
use crate::solve::{Calibration, FrameStats};

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
    /// Per-marker RMSE and maximum, and the worst frames ([`crate::pipeline::running::marker_errors`]).
    pub marker_errors: crate::pipeline::running::marker_errors::MarkerErrorTable,
}
