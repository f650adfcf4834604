//! In-memory marker trajectories shared by all trial readers (TRC, later C3D).
//!
//! Positions are in metres, in the lab frame of the file they came from; a gap
//! (marker not seen in a frame) is stored as NaN on all three axes.

use std::ops::Range;

/// Marker trajectories of one trial, in metres, in the file's lab frame.
#[derive(Debug, Clone, Default)]
pub struct MarkerTrial {
    /// Marker names, as in the file.
    pub labels: Vec<String>,
    /// Sampling rate in Hz (TRC `DataRate`).
    pub rate_hz: f64,
    /// Time of each frame in seconds.
    pub times: Vec<f64>,
    /// Frame numbers as in the file (usually 1-based).
    pub frame_numbers: Vec<i64>,
    /// Positions in metres, frame-major: `data[(f * labels.len() + m) * 3 + axis]`;
    /// NaN on all three axes marks a gap.
    pub positions: Vec<f64>,
    /// Units as written in the file ("mm", "m", ...); `positions` are always metres.
    pub source_units: String,
    /// Non-fatal oddities met while reading (header counts disagreeing with the
    /// data, unnamed markers, ...), one human-readable line each.
    pub warnings: Vec<String>,
}

/// Metres per unit for a length unit name (`mm`, `cm`, `m`, `in` and their long
/// forms), case-insensitively; `None` for anything else.
pub fn units_to_metres(units: &str) -> Option<f64> {
    match units.trim().to_ascii_lowercase().as_str() {
        "mm" | "millimeter" | "millimeters" | "millimetre" | "millimetres" => Some(1e-3),
        "cm" | "centimeter" | "centimeters" | "centimetre" | "centimetres" => Some(1e-2),
        "m" | "meter" | "meters" | "metre" | "metres" => Some(1.0),
        "in" | "inch" | "inches" => Some(0.0254),
        _ => None,
    }
}

/// Units per metre for a unit of `scale` metres, made whole when it nearly is (1000 for mm), so
/// that dividing reads `9 mm` as exactly `0.009` m: how every reader brings positions into metres.
pub fn per_metre(scale: f64) -> f64 {
    let p = 1.0 / scale;
    if (p - p.round()).abs() < 1e-9 * p {
        p.round()
    } else {
        p
    }
}

impl MarkerTrial {
    /// Number of frames.
    pub fn n_frames(&self) -> usize {
        self.times.len()
    }

    /// Overrides the sampling rate (Hz): frame times become `t₀ + (n − n₀) / rate_hz` from the
    /// first frame's time `t₀` and number `n₀` (so skipped frame numbers keep their gap).
    pub fn set_rate(&mut self, rate_hz: f64) {
        let t0 = self.times.first().copied().unwrap_or(0.0);
        let n0 = self.frame_numbers.first().copied().unwrap_or(0);
        for (i, t) in self.times.iter_mut().enumerate() {
            let n = self.frame_numbers.get(i).map_or(i as i64, |n| n - n0);
            *t = t0 + n as f64 / rate_hz;
        }
        self.rate_hz = rate_hz;
    }

    /// Number of markers (labels).
    pub fn n_markers(&self) -> usize {
        self.labels.len()
    }

    /// Position of marker `m` in frame `f`, in metres; `None` for a gap or an
    /// index out of range.
    pub fn position(&self, f: usize, m: usize) -> Option<[f64; 3]> {
        if m >= self.n_markers() {
            return None;
        }
        let i = (f.checked_mul(self.n_markers())? + m) * 3;
        let p = self.positions.get(i..i + 3)?;
        if p.iter().any(|v| !v.is_finite()) {
            return None;
        }
        Some([p[0], p[1], p[2]])
    }

    /// All coordinates of frame `f` (`n_markers() * 3` values, metres, NaN = gap).
    ///
    /// # Panics
    /// If `f >= n_frames()` or `positions` is shorter than the frame count implies.
    pub fn frame(&self, f: usize) -> &[f64] {
        let w = self.n_markers() * 3;
        &self.positions[f * w..(f + 1) * w]
    }

    /// Index of the marker called `name` (exact match).
    pub fn label_index(&self, name: &str) -> Option<usize> {
        self.labels.iter().position(|l| l == name)
    }

    /// Trajectory of marker `m` over all frames (metres; `None` = gap).
    pub fn trajectory(&self, m: usize) -> Vec<Option<[f64; 3]>> {
        (0..self.n_frames()).map(|f| self.position(f, m)).collect()
    }

    /// Number of gap frames for each marker, in label order.
    pub fn gap_counts(&self) -> Vec<usize> {
        (0..self.n_markers()).map(|m| (0..self.n_frames()).filter(|&f| self.position(f, m).is_none()).count()).collect()
    }

    /// Missing frames of marker `m` and its longest run of consecutive missing frames.
    pub fn gaps_and_longest(&self, m: usize) -> (usize, usize) {
        let (mut gaps, mut run, mut longest) = (0, 0, 0);
        for f in 0..self.n_frames() {
            if self.position(f, m).is_none() {
                gaps += 1;
                run += 1;
                longest = longest.max(run);
            } else {
                run = 0;
            }
        }
        (gaps, longest)
    }

    /// Time from the first to the last frame in seconds (0 with fewer than two frames).
    pub fn duration(&self) -> f64 {
        match (self.times.first(), self.times.last()) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }

    /// A copy holding only the frames in `range` (clamped to the trial).
    pub fn select_frames(&self, range: Range<usize>) -> MarkerTrial {
        let n = self.n_frames();
        let (lo, hi) = (range.start.min(n), range.end.min(n).max(range.start.min(n)));
        let w = self.n_markers() * 3;
        let pos_hi = (hi * w).min(self.positions.len());
        let pos_lo = (lo * w).min(pos_hi);
        MarkerTrial {
            labels: self.labels.clone(),
            rate_hz: self.rate_hz,
            times: self.times[lo..hi].to_vec(),
            frame_numbers: self.frame_numbers.get(lo..hi).map(<[i64]>::to_vec).unwrap_or_default(),
            positions: self.positions[pos_lo..pos_hi].to_vec(),
            source_units: self.source_units.clone(),
            warnings: self.warnings.clone(),
        }
    }

    /// Checks that the array lengths agree with each other and the rate is a
    /// positive finite number; the message says what disagrees.
    pub fn check_consistent(&self) -> Result<(), String> {
        let (nf, nm) = (self.n_frames(), self.n_markers());
        if self.frame_numbers.len() != nf {
            return Err(format!("{} frame numbers for {nf} times", self.frame_numbers.len()));
        }
        if self.positions.len() != nf * nm * 3 {
            return Err(format!(
                "{} position values, expected {nf} frames x {nm} markers x 3 = {}",
                self.positions.len(),
                nf * nm * 3
            ));
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0) {
            return Err(format!("sampling rate {} Hz is not positive", self.rate_hz));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> MarkerTrial {
        MarkerTrial {
            labels: vec!["A".into(), "B".into()],
            rate_hz: 100.0,
            times: vec![0.0, 0.01, 0.02],
            frame_numbers: vec![1, 2, 3],
            positions: vec![
                0.0,
                1.0,
                2.0,
                3.0,
                4.0,
                5.0, //
                f64::NAN,
                f64::NAN,
                f64::NAN,
                6.0,
                7.0,
                8.0, //
                0.5,
                1.5,
                2.5,
                f64::NAN,
                f64::NAN,
                f64::NAN,
            ],
            source_units: "m".into(),
            warnings: Vec::new(),
        }
    }

    #[test]
    fn helpers_index_frame_major_positions() {
        let t = tiny();
        assert_eq!((t.n_frames(), t.n_markers()), (3, 2));
        assert_eq!(t.position(0, 1), Some([3.0, 4.0, 5.0]));
        assert_eq!(t.position(1, 0), None);
        assert_eq!(t.position(9, 0), None);
        assert_eq!(t.position(0, 2), None);
        assert_eq!(t.frame(1)[3..], [6.0, 7.0, 8.0]);
        assert_eq!(t.label_index("B"), Some(1));
        assert_eq!(t.gap_counts(), vec![1, 1]);
        assert_eq!((t.gaps_and_longest(0), t.gaps_and_longest(1)), ((1, 1), (1, 1)));
        assert!((t.duration() - 0.02).abs() < 1e-15);
        assert!(t.check_consistent().is_ok());
        let s = t.select_frames(1..10);
        assert_eq!(s.n_frames(), 2);
        assert_eq!(s.frame_numbers, vec![2, 3]);
        assert_eq!(s.position(1, 0), Some([0.5, 1.5, 2.5]));
        #[allow(clippy::reversed_empty_ranges)]
        let e = t.select_frames(2..1);
        assert_eq!(e.n_frames(), 0);
        assert!(e.positions.is_empty());
    }

    #[test]
    fn units_are_case_insensitive() {
        assert_eq!(units_to_metres("MM"), Some(1e-3));
        assert_eq!(units_to_metres(" m "), Some(1.0));
        assert_eq!(units_to_metres("cm"), Some(1e-2));
        assert_eq!(units_to_metres("In"), Some(0.0254));
        assert_eq!(units_to_metres("furlong"), None);
    }
}
