//! Writing a marker trial as a TRC file.

use super::TrcError;
use crate::io::markers::{per_metre, units_to_metres, MarkerTrial};
use std::path::Path;

/// Writes `trial` as a TRC file with positions in `units` (mm, cm, m, in).
pub fn write_trc(path: &Path, trial: &MarkerTrial, units: &str) -> Result<(), TrcError> {
    let file = path.display().to_string();
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let text = to_trc_string(trial, units, &name).map_err(|e| match e {
        TrcError::Unwritable { what, .. } => TrcError::Unwritable { file: file.clone(), what },
        other => other,
    })?;
    std::fs::write(path, text).map_err(|source| TrcError::Io { file, source })
}

/// The TRC text for `trial` with positions in `units`; `name` goes on line 1.
/// Positions carry 9 significant decimals of a metre (6 in mm, 9 in m); times 6
/// decimals; gaps (any non-finite axis) are written as empty cells.
pub fn to_trc_string(trial: &MarkerTrial, units: &str, name: &str) -> Result<String, TrcError> {
    use std::fmt::Write as _;
    let bad = |what: String| TrcError::Unwritable { file: name.to_string(), what };
    let scale = units_to_metres(units).ok_or_else(|| bad(format!("unknown units {units:?}")))?;
    trial.check_consistent().map_err(bad)?;
    if let Some(l) =
        trial.labels.iter().find(|l| l.is_empty() || l.trim() != l.as_str() || l.contains(['\t', '\n', '\r']))
    {
        return Err(bad(format!("marker label {l:?} is empty or has tabs, line breaks or edge spaces")));
    }
    if trial.times.is_empty() {
        return Err(bad("trial has no frames".into()));
    }
    if let Some(t) = trial.times.iter().find(|t| !t.is_finite()) {
        return Err(bad(format!("time {t} is not finite")));
    }
    let units = units.trim();
    let per_m = per_metre(scale);
    let decimals = (9.0 + scale.log10() - 1e-9).ceil().clamp(0.0, 12.0) as usize;
    let (nf, nm) = (trial.n_frames(), trial.n_markers());
    let first_frame = trial.frame_numbers.first().copied().unwrap_or(1);
    let rate = trial.rate_hz;
    let mut s = String::new();
    // Writing into a String cannot fail; the results are ignored.
    let _ = writeln!(s, "PathFileType\t4\t(X/Y/Z)\t{name}");
    let _ = writeln!(
        s,
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames"
    );
    let _ = writeln!(s, "{rate}\t{rate}\t{nf}\t{nm}\t{units}\t{rate}\t{first_frame}\t{nf}");
    s.push_str("Frame#\tTime");
    for l in &trial.labels {
        let _ = write!(s, "\t{l}\t\t");
    }
    s.push_str("\n\t");
    for m in 1..=nm {
        let _ = write!(s, "\tX{m}\tY{m}\tZ{m}");
    }
    s.push_str("\n\n");
    for f in 0..nf {
        let _ = write!(s, "{}\t{:.6}", trial.frame_numbers[f], trial.times[f]);
        for m in 0..nm {
            match trial.position(f, m) {
                Some(p) => {
                    for v in p {
                        let _ = write!(s, "\t{:.*}", decimals, v * per_m);
                    }
                }
                None => s.push_str("\t\t\t"),
            }
        }
        s.push('\n');
    }
    Ok(s)
}
