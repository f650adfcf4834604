//! A marker file whose frames are read a window at a time and brought into the model's
//! conventions as they are read ([`crate::pipeline::input::frames::TrialFrames`] over [`MarkerFile`]).

use crate::io::{MarkerFile, MarkerTrial};
use crate::pipeline::input::convention::Conform;
use crate::pipeline::input::frames::TrialFrames;
use std::borrow::Cow;
use std::ops::Range;

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
        crate::io::mask_beyond(&mut t, self.mask_beyond_m);
        Ok(Cow::Owned(t))
    }

    fn window_frames(&self) -> usize {
        self.window
    }
}
