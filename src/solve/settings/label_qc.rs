//! Label quality control settings (part of the solver settings, so that they go into every
//! report's provenance and can be set in a profile's `[solver]` table or with
//! `--set 'label_qc={mode="flag"}'`).

use serde::{Deserialize, Serialize};

/// What label quality control does with what it finds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum QcMode {
    /// No screening.
    Off,
    /// Screen and report; the data are solved as they are, and a trial with events is `suspect`.
    Flag,
    /// Screen, exchange swapped labels back and mask what cannot be repaired (default).
    #[default]
    Repair,
}

impl QcMode {
    pub fn as_str(self) -> &'static str {
        match self {
            QcMode::Off => "off",
            QcMode::Flag => "flag",
            QcMode::Repair => "repair",
        }
    }
}

/// Label quality control: thresholds of the screen ([`super`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LabelQcSettings {
    /// Default `repair`.
    pub mode: QcMode,
    /// A marker is flagged in a frame when the median, over its rigid partners, of how far their
    /// distance is from the trial's (beyond `noise_sds` of that pair's spread) exceeds this (mm).
    /// Default 30: ten times the spread of skin-marker distances on one body, a third of the
    /// smallest left/right or neighbour exchange that changes anything (heels, knees ≈ 150 mm).
    pub threshold_mm: f64,
    /// A marker is flagged in a frame when the median, over its rigid partners, of how far their
    /// distance is from its value in the last frame where both were kept exceeds this (mm): a
    /// jump in any direction. Default 20: rigid distances change by a few millimetres between
    /// frames (soft tissue), a label error by a large part of its size.
    pub step_mm: f64,
    /// Pairs of markers on one body or on bodies one or two joints apart whose distance varies
    /// over the trial by more than this robust standard deviation (mm, 1.4826 · MAD) are not
    /// rigid and not used. Default 8.
    pub rigid_sd_mm: f64,
    /// A pair's distance error counts beyond this many of its robust standard deviations (floor
    /// 1 mm). Default 5.
    pub noise_sds: f64,
    /// Detections of the same swap or jump this many frames apart or fewer are one span (a swap
    /// is not seen while the two markers are close, e.g. feet side by side; the frames between
    /// are checked again before a span is repaired). Default 10.
    pub max_gap_frames: usize,
    /// Spans detected in fewer frames than this are not events (a labelling error lasts; a
    /// single frame's or two's misfit is noise). Default 3.
    pub min_frames: usize,
    /// Frames sampled (evenly over the trial) for the reference distances. Default 2000.
    pub sample_frames: usize,
    /// The trial is `suspect` when more than this share of its frames had a marker masked.
    /// Default 0.05.
    pub suspect_masked_share: f64,
}

impl Default for LabelQcSettings {
    fn default() -> Self {
        LabelQcSettings {
            mode: QcMode::Repair,
            threshold_mm: 30.0,
            step_mm: 40.0,
            rigid_sd_mm: 8.0,
            noise_sds: 5.0,
            max_gap_frames: 10,
            min_frames: 3,
            sample_frames: 2000,
            suspect_masked_share: 0.05,
        }
    }
}
