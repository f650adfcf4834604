//! Marker files opened for reading frames on demand, so that a long trial is never held whole.
//!
//! [`MarkerFile::open`] reads the file once (every row is parsed and checked, as
//! [`super::read_markers`] does) and keeps the trial's labels, rate, times and frame numbers; it
//! keeps the positions too when the file has at most `keep` frames, and otherwise reads any
//! range of frames again when asked ([`MarkerFile::read`]): a TRC row by its byte offset, a C3D
//! frame by its block.

use super::{c3d, trc, MarkerFileError, MarkerTrial, MARKER_FORMATS};
use std::ops::Range;
use std::path::Path;

/// A marker file, with its positions held or read on demand.
#[derive(Clone, Debug)]
pub struct MarkerFile {
    /// The trial; `positions` is empty unless [`MarkerFile::held`].
    pub trial: MarkerTrial,
    rows: Rows,
}

#[derive(Clone, Debug)]
enum Rows {
    Trc(trc::TrcRows),
    C3d(c3d::C3dFrames),
}

impl MarkerFile {
    /// Opens `path` (reader by extension, case-insensitive), holding its positions when it has
    /// at most `keep` frames. Absurd values are gaps, as in [`super::read_markers`].
    pub fn open(path: &Path, keep: usize) -> Result<MarkerFile, MarkerFileError> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        let (trial, rows) = match ext.as_str() {
            "trc" => trc::scan_trc(path, keep).map(|(t, r)| (t, Rows::Trc(r)))?,
            "c3d" => c3d::scan_c3d(path, keep).map(|(t, r)| (t, Rows::C3d(r)))?,
            _ => Err(MarkerFileError::Unsupported {
                path: path.display().to_string(),
                extension: ext,
                supported: MARKER_FORMATS,
            })?,
        };
        let mut f = MarkerFile { trial, rows };
        if f.held() {
            super::mask_absurd(&mut f.trial);
        }
        Ok(f)
    }

    /// Whether the positions are held (`trial.positions` is complete).
    pub fn held(&self) -> bool {
        self.trial.positions.len() == self.trial.n_frames() * self.trial.n_markers() * 3
    }

    /// The positions of frames `range` (clamped to the trial; metres, frame-major, absurd values
    /// as gaps), from memory when held, else read from the file.
    pub fn read(&self, range: Range<usize>) -> Result<Vec<f64>, MarkerFileError> {
        let n = self.trial.n_frames();
        let range = range.start.min(n)..range.end.min(n).max(range.start.min(n));
        if self.held() {
            let w = self.trial.n_markers() * 3;
            return Ok(self.trial.positions[range.start * w..range.end * w].to_vec());
        }
        let mut t = MarkerTrial {
            labels: self.trial.labels.clone(),
            positions: match &self.rows {
                Rows::Trc(r) => r.read(range)?,
                Rows::C3d(r) => r.read(range)?,
            },
            ..MarkerTrial::default()
        };
        super::mask_beyond(&mut t, super::ABSURD_COORDINATE_M);
        Ok(t.positions)
    }
}
