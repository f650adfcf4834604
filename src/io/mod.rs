//! Reading and writing the files smocap meets: marker trials (TRC), models (MJCF, OpenSim
//! `.osim` and marker sets), OpenSim tables (`.sto`/`.mot`).

pub mod c3d;
pub mod decimal;
pub mod gltf;
pub mod gravity;
pub mod markers;
pub mod mjcf;
pub mod osim;
pub mod source;
pub mod sto;
pub mod trc;

pub use markers::MarkerTrial;
pub use source::MarkerFile;

use std::path::Path;

/// Writes `bytes` to `path` through a temporary file beside it (`<path>.tmp<pid>`) and a rename:
/// a reader never sees a partial file, and a failed write leaves none behind. Creates the
/// parent folder.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)?;
    }
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp{}", std::process::id()));
    let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Errors reading a marker file of any supported format.
#[derive(Debug, thiserror::Error)]
pub enum MarkerFileError {
    #[error(transparent)]
    Trc(#[from] trc::TrcError),
    #[error(transparent)]
    C3d(#[from] c3d::C3dError),
    #[error("{path}: unsupported marker file type '{extension}' (supported: {supported})")]
    Unsupported { path: String, extension: String, supported: &'static str },
    /// Marker positions given in memory ([`markers_from_arrays`]) that do not make a trial.
    #[error("markers from arrays: {0}")]
    Arrays(String),
}

/// Marker file formats understood by [`read_markers`], by extension.
pub const MARKER_FORMATS: &str = "trc, c3d";

/// Reads a marker trial, choosing the reader by the file's extension (case-insensitive).
pub fn read_markers(path: &Path) -> Result<MarkerTrial, MarkerFileError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let mut t: MarkerTrial = match ext.as_str() {
        "trc" => trc::read_trc(path)?,
        "c3d" => c3d::read_c3d(path)?,
        _ => Err(MarkerFileError::Unsupported {
            path: path.display().to_string(),
            extension: ext,
            supported: MARKER_FORMATS,
        })?,
    };
    mask_absurd(&mut t);
    Ok(t)
}

/// A marker trial from positions held in memory rather than read from a file: `xyz` frame-major
/// (`frames × labels × 3`, as [`MarkerTrial::positions`]) in `units` (`mm`, `cm`, `m`, `in`), NaN
/// for gaps; frame times `times` (s; `i / rate_hz` when `None`), frame numbers from 1. The numbers
/// are brought into metres, and absurd ones masked, as [`read_markers`] does with a file's.
pub fn markers_from_arrays(
    labels: Vec<String>,
    xyz: &[f64],
    rate_hz: f64,
    units: &str,
    times: Option<Vec<f64>>,
) -> Result<MarkerTrial, MarkerFileError> {
    let bad = |m: String| MarkerFileError::Arrays(m);
    let scale = markers::units_to_metres(units)
        .ok_or_else(|| bad(format!("unknown units {units:?} (expected mm, cm, m or in)")))?;
    let per_m = markers::per_metre(scale);
    let width = labels.len() * 3;
    if width == 0 || !xyz.len().is_multiple_of(width) {
        return Err(bad(format!("{} values are not frames of {} markers x 3", xyz.len(), labels.len())));
    }
    let n = xyz.len() / width;
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(bad(format!("sampling rate {rate_hz} Hz is not positive")));
    }
    let times = times.unwrap_or_else(|| (0..n).map(|i| i as f64 / rate_hz).collect());
    if times.len() != n {
        return Err(bad(format!("{} frame times for {n} frames", times.len())));
    }
    let mut t = MarkerTrial {
        labels,
        rate_hz,
        times,
        frame_numbers: (1..=n as i64).collect(),
        positions: xyz.iter().map(|v| v / per_m).collect(),
        source_units: units.trim().to_string(),
        warnings: Vec::new(),
    };
    t.check_consistent().map_err(bad)?;
    mask_absurd(&mut t);
    Ok(t)
}

/// Coordinates beyond this (m, in the file's own declared units) are masked as the file is read,
/// before units and up axis are looked at: implausible in any unit a lab file may really be in
/// (a millimetre file declared as metres stays below 1e4).
pub const ABSURD_COORDINATE_M: f64 = 1e6;

/// Masks (sets to NaN, a gap) every marker sample with a coordinate that is not finite or is
/// beyond `limit_m` (in the trial's units); returns a warning saying how many, or `None` when
/// none were.
pub fn mask_beyond(trial: &mut MarkerTrial, limit_m: f64) -> Option<String> {
    let mut masked = 0usize;
    let mut nonfinite = 0usize;
    for p in trial.positions.chunks_exact_mut(3) {
        if p.iter().all(|v| v.is_nan()) {
            continue;
        }
        let bad_value = p.iter().any(|v| !v.is_finite());
        if bad_value || p.iter().any(|v| v.abs() > limit_m) {
            p.fill(f64::NAN);
            masked += 1;
            nonfinite += bad_value as usize;
        }
    }
    (masked > 0).then(|| {
        format!(
            "{masked} marker samples masked as gaps: {nonfinite} not finite, {} beyond {limit_m} m",
            masked - nonfinite
        )
    })
}

/// Absurd values (whatever the units) are gaps before anything looks at the data (with a
/// warning saying how many).
fn mask_absurd(t: &mut MarkerTrial) {
    if let Some(w) = mask_beyond(t, ABSURD_COORDINATE_M) {
        t.warnings.push(w);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markers_from_arrays_read_millimetres_as_the_readers_do() {
        let xyz = [9.0, 1000.0, -2.5, f64::NAN, f64::NAN, f64::NAN, 1.0, 2.0, 3.0, 4.0, 5.0, 6e12];
        let t = markers_from_arrays(vec!["A".into(), "B".into()], &xyz, 50.0, "mm", None).unwrap();
        assert_eq!((t.n_frames(), t.n_markers()), (2, 2));
        assert_eq!(t.position(0, 0), Some([0.009, 1.0, -0.0025]));
        assert_eq!(t.position(0, 1), None);
        // 6e12 mm is beyond any capture volume: masked as a gap, with a warning.
        assert_eq!(t.position(1, 1), None);
        assert!(t.warnings.iter().any(|w| w.contains("1 marker samples masked")), "{:?}", t.warnings);
        assert_eq!(t.times, vec![0.0, 0.02]);
        assert_eq!(t.frame_numbers, vec![1, 2]);
        assert_eq!(t.source_units, "mm");
    }

    #[test]
    fn markers_from_arrays_refuse_what_is_not_a_trial() {
        let one = |xyz: &[f64], rate: f64, units: &str, times: Option<Vec<f64>>| {
            markers_from_arrays(vec!["A".into()], xyz, rate, units, times).unwrap_err().to_string()
        };
        assert!(one(&[0.0; 4], 100.0, "m", None).contains("4 values are not frames of 1 markers x 3"));
        assert!(one(&[0.0; 3], 0.0, "m", None).contains("sampling rate 0 Hz"));
        assert!(one(&[0.0; 3], 100.0, "furlong", None).contains("unknown units \"furlong\""));
        assert!(one(&[0.0; 3], 100.0, "m", Some(vec![0.0, 1.0])).contains("2 frame times for 1 frames"));
    }
}
