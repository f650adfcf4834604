//! Reading and writing the files smocap meets: marker trials (TRC), models (MJCF, OpenSim
//! `.osim` and marker sets), OpenSim tables (`.sto`/`.mot`).

pub mod c3d;
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

/// Errors reading a marker file of any supported format.
#[derive(Debug, thiserror::Error)]
pub enum MarkerFileError {
    #[error(transparent)]
    Trc(#[from] trc::TrcError),
    #[error(transparent)]
    C3d(#[from] c3d::C3dError),
    #[error("{path}: unsupported marker file type '{extension}' (supported: {supported})")]
    Unsupported { path: String, extension: String, supported: &'static str },
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

/// Absurd values (whatever the units) are gaps before anything looks at the data (with a
/// warning saying how many).
fn mask_absurd(t: &mut MarkerTrial) {
    if let Some(w) = crate::pipeline::verdict::mask_beyond(t, crate::pipeline::verdict::ABSURD_COORDINATE_M) {
        t.warnings.push(w);
    }
}
