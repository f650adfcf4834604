//! The subject a C3D file names and the measurements Vicon writes with it (`SUBJECTS:NAMES`,
//! `PROCESSING:Height` in mm, `Bodymass` in kg, leg lengths, knee and ankle widths in mm).

use super::params::Params;
use super::C3dError;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// What a C3D file says of its subject; every field optional. Lengths in metres, mass in kg.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct C3dSubject {
    /// `SUBJECTS:NAMES` (blank names left out).
    pub names: Vec<String>,
    /// `PROCESSING:Height` (m).
    pub height_m: Option<f64>,
    /// `PROCESSING:Bodymass` (kg).
    pub mass_kg: Option<f64>,
    /// `PROCESSING:LLegLength`, `RLegLength` (m).
    pub leg_length_m: [Option<f64>; 2],
    /// `PROCESSING:LKneeWidth`, `RKneeWidth` (m).
    pub knee_width_m: [Option<f64>; 2],
    /// `PROCESSING:LAnkleWidth`, `RAnkleWidth` (m).
    pub ankle_width_m: [Option<f64>; 2],
}

impl C3dSubject {
    /// Whether the file says nothing of its subject.
    pub fn is_empty(&self) -> bool {
        *self == C3dSubject::default()
    }
}

/// Reads the subject of the C3D file at `path` (its header and parameter section only).
pub fn read_subject(path: &Path) -> Result<C3dSubject, C3dError> {
    use std::io::Read;
    let file = path.display().to_string();
    let io = |source| C3dError::Io { file: file.clone(), source };
    let mut f = std::fs::File::open(path).map_err(io)?;
    let mut head = vec![0u8; 512];
    let n = f.read(&mut head).map_err(io)?;
    head.truncate(n);
    // The parameter section's blocks (at most 255 of them) after the header.
    let mut rest = Vec::new();
    f.take(512 * 256).read_to_end(&mut rest).map_err(io)?;
    head.extend(rest);
    parse_subject(&head, &file)
}

/// The subject in the bytes of a C3D file (at least its header and parameter section).
pub fn parse_subject(bytes: &[u8], name_for_errors: &str) -> Result<C3dSubject, C3dError> {
    if bytes.len() < 512 {
        let what = "the 512-byte header".to_string();
        return Err(C3dError::Truncated { file: name_for_errors.into(), what, needed: 512, len: bytes.len() });
    }
    let p = Params::parse(bytes, name_for_errors)?;
    Ok(subject_of(&p))
}

/// A positive finite `PROCESSING` value, times `scale`.
fn measure(p: &Params<'_>, name: &str, scale: f64) -> Option<f64> {
    p.float("PROCESSING", name).filter(|v| v.is_finite() && *v > 0.0).map(|v| v * scale)
}

pub(super) fn subject_of(p: &Params<'_>) -> C3dSubject {
    let names = p.strings("SUBJECTS", "NAMES").unwrap_or_default();
    let pair = |l: &str, r: &str| [measure(p, l, 1e-3), measure(p, r, 1e-3)];
    C3dSubject {
        names: names.into_iter().map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect(),
        height_m: measure(p, "HEIGHT", 1e-3),
        mass_kg: measure(p, "BODYMASS", 1.0),
        leg_length_m: pair("LLEGLENGTH", "RLEGLENGTH"),
        knee_width_m: pair("LKNEEWIDTH", "RKNEEWIDTH"),
        ankle_width_m: pair("LANKLEWIDTH", "RANKLEWIDTH"),
    }
}
