//! Robust summary statistics used in reports.

use serde::{Deserialize, Serialize};

/// Percentile `q ∈ [0, 1]` by linear interpolation between order statistics; NaNs ignored.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (i, frac) = (pos.floor() as usize, pos.fract());
    if i + 1 < v.len() {
        v[i] * (1.0 - frac) + v[i + 1] * frac
    } else {
        v[i]
    }
}

/// Mean ignoring NaNs.
pub fn mean(values: &[f64]) -> f64 {
    let v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Median and 90th percentile.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct P50P90 {
    pub p50: f64,
    pub p90: f64,
}

impl P50P90 {
    pub fn of(values: &[f64]) -> P50P90 {
        P50P90 { p50: percentile(values, 0.5), p90: percentile(values, 0.9) }
    }
}

/// Mean, median and 90th percentile.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct MeanP50P90 {
    pub mean: f64,
    pub p50: f64,
    pub p90: f64,
}

impl MeanP50P90 {
    pub fn of(values: &[f64]) -> MeanP50P90 {
        MeanP50P90 { mean: mean(values), p50: percentile(values, 0.5), p90: percentile(values, 0.9) }
    }
}

/// Missing data of one trial, over the model markers that the file provides.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GapStats {
    /// Missing (frame, marker) samples, summed over those markers.
    pub missing_samples: usize,
    /// Frames with fewer than `min_markers` observed weighted markers (bridged).
    pub frames_below_min_markers: usize,
    /// Per model marker found in the file, in model order.
    pub markers: Vec<MarkerGaps>,
}

/// Missing data of one marker.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerGaps {
    /// Model marker name.
    pub marker: String,
    /// Frames where it is missing, as a count and as a fraction of the trial's frames.
    pub missing: usize,
    pub missing_fraction: f64,
    /// Longest run of consecutive missing frames.
    pub longest_gap: usize,
}
