//! A trial's frames a window at a time: held whole ([`MarkerTrial`]) or read from its file on
//! demand ([`FileFrames`]), so that what a long trial holds does not grow with its length.
//!
//! Every consumer walks a trial through [`TrialFrames::window`]; a trial held whole gives
//! itself as its one window, so the two give the same frames, and results do not depend on
//! the window size.

use super::convention::Conform;
use crate::io::{MarkerFile, MarkerTrial};
use std::borrow::Cow;
use std::ops::Range;

/// A trial's frames, a window at a time.
pub trait TrialFrames: Sync {
    /// The trial: labels, rate, times and frame numbers of every frame, units, warnings; its
    /// `positions` are empty unless the trial is held whole.
    fn header(&self) -> &MarkerTrial;
    /// Frames `range` (clamped to the trial) as a trial of their own, whose frame 0 is
    /// `range.start`: positions in metres in the model's conventions, NaN gaps.
    fn window(&self, range: Range<usize>) -> Result<Cow<'_, MarkerTrial>, String>;
    /// Frames per window that bound what a window holds (`usize::MAX` when held whole).
    fn window_frames(&self) -> usize;
    /// The label quality control applied to the frames, if any ([`super::label_qc::Screened`]).
    fn label_qc(&self) -> Option<&super::label_qc::LabelQc> {
        None
    }
}

impl TrialFrames for MarkerTrial {
    fn header(&self) -> &MarkerTrial {
        self
    }

    fn window(&self, range: Range<usize>) -> Result<Cow<'_, MarkerTrial>, String> {
        if range.start == 0 && range.end >= self.n_frames() {
            Ok(Cow::Borrowed(self))
        } else {
            Ok(Cow::Owned(self.select_frames(range)))
        }
    }

    fn window_frames(&self) -> usize {
        usize::MAX
    }
}

/// Calls `f(first, window)` for consecutive windows of [`TrialFrames::window_frames`] frames
/// covering the trial, in order; `first` is the window's first frame in the trial.
pub fn for_each_window<T: TrialFrames + ?Sized>(
    frames: &T,
    mut f: impl FnMut(usize, &MarkerTrial),
) -> Result<(), String> {
    let n = frames.header().n_frames();
    let step = frames.window_frames().max(1);
    let mut a = 0;
    while a < n {
        let b = a.saturating_add(step).min(n);
        let w = frames.window(a..b)?;
        f(a, &w);
        a = b;
    }
    Ok(())
}

/// A marker file whose frames are read a window at a time and brought into the model's
/// conventions as they are read (units, up axis, implausible values masked).
pub struct FileFrames {
    file: MarkerFile,
    /// The file's trial with its times as decided (a rate override applied), no positions.
    header: MarkerTrial,
    conform: Conform,
    /// Values beyond this (m, any axis, after conforming) are gaps.
    mask_beyond_m: f64,
    window: usize,
}

impl FileFrames {
    /// Frames of `file` (not held) read `window` at a time, conformed by `conform`, with values
    /// beyond `mask_beyond_m` masked; `header` is the file's trial without positions.
    pub fn new(file: MarkerFile, header: MarkerTrial, conform: Conform, mask_beyond_m: f64, window: usize) -> Self {
        FileFrames { file, header, conform, mask_beyond_m, window: window.max(1) }
    }

    /// The same file with another header, conforming and masking.
    pub fn reconform(self, header: MarkerTrial, conform: Conform, mask_beyond_m: f64) -> Self {
        FileFrames { header, conform, mask_beyond_m, ..self }
    }
}

impl TrialFrames for FileFrames {
    fn header(&self) -> &MarkerTrial {
        &self.header
    }

    fn window(&self, range: Range<usize>) -> Result<Cow<'_, MarkerTrial>, String> {
        let h = &self.header;
        let n = h.n_frames();
        let range = range.start.min(n)..range.end.min(n).max(range.start.min(n));
        let mut t = MarkerTrial {
            labels: h.labels.clone(),
            rate_hz: h.rate_hz,
            times: h.times[range.clone()].to_vec(),
            frame_numbers: h.frame_numbers.get(range.clone()).map(<[i64]>::to_vec).unwrap_or_default(),
            positions: self.file.read(range).map_err(|e| e.to_string())?,
            source_units: h.source_units.clone(),
            warnings: Vec::new(),
        };
        self.conform.apply(&mut t);
        crate::pipeline::verdict::mask_beyond(&mut t, self.mask_beyond_m);
        Ok(Cow::Owned(t))
    }

    fn window_frames(&self) -> usize {
        self.window
    }
}
