//! A trial's frames a window at a time: held whole ([`MarkerTrial`]) or read from its file on
//! demand ([`crate::pipeline::input::file_frames::FileFrames`]), so that what a long trial holds does not grow with its length.
//!
//! Every consumer walks a trial through [`TrialFrames::window`]; a trial held whole gives
//! itself as its one window, so the two give the same frames, and results do not depend on
//! the window size.

use crate::io::MarkerTrial;
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
    /// The label quality control applied to the frames, if any ([`crate::pipeline::input::label_qc::Screened`]).
    fn label_qc(&self) -> Option<&crate::pipeline::input::label_qc::report::LabelQc> {
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
