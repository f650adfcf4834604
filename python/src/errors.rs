//! Python exceptions: `SmocapError` and its subclasses, carrying the message the command line
//! prints (file, line, what was expected); `SmocapWarning` for results to use with care.

use pyo3::exceptions::{PyException, PyUserWarning};
use pyo3::prelude::*;

pyo3::create_exception!(smocap, SmocapError, PyException, "An error from smocap; the message says what and where.");
pyo3::create_exception!(
    smocap,
    MarkerFileError,
    SmocapError,
    "A marker file (TRC, C3D) or marker arrays that cannot be read."
);
pyo3::create_exception!(
    smocap,
    ModelError,
    SmocapError,
    "A model, marker set, profile, OpenSim setup or solver setting that cannot be used."
);
pyo3::create_exception!(smocap, CalibrationError, SmocapError, "The subject could not be calibrated.");
pyo3::create_exception!(smocap, SolveError, SmocapError, "A trial could not be solved (no result).");
pyo3::create_exception!(
    smocap,
    ArchiveError,
    SmocapError,
    "A converted (.mcap) file or an archive conversion that failed."
);
pyo3::create_exception!(
    smocap,
    SmocapWarning,
    PyUserWarning,
    "A result that is not to be trusted as it is (e.g. a `suspect` trial or calibration)."
);

pub fn register(py: Python<'_>, m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SmocapError", py.get_type::<SmocapError>())?;
    m.add("MarkerFileError", py.get_type::<MarkerFileError>())?;
    m.add("ModelError", py.get_type::<ModelError>())?;
    m.add("CalibrationError", py.get_type::<CalibrationError>())?;
    m.add("SolveError", py.get_type::<SolveError>())?;
    m.add("ArchiveError", py.get_type::<ArchiveError>())?;
    m.add("SmocapWarning", py.get_type::<SmocapWarning>())?;
    Ok(())
}

/// `e` on one line as the command line says it: its message, then each cause it does not
/// already quote.
pub fn message(e: &(dyn std::error::Error + 'static)) -> String {
    let mut said = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let c_msg = c.to_string();
        if !said.contains(&c_msg) {
            said = format!("{said}: {c_msg}");
        }
        cause = c.source();
    }
    said
}

/// Converts a library error into the Python exception `E` with its message.
pub fn to_py<E: pyo3::PyTypeInfo>(e: impl std::error::Error + 'static) -> PyErr {
    PyErr::new::<E, _>(message(&e))
}

/// Emits `SmocapWarning(msg)`.
pub fn warn(py: Python<'_>, msg: &str) -> PyResult<()> {
    let msg = std::ffi::CString::new(msg.replace('\0', " ")).unwrap_or_default();
    PyErr::warn(py, &py.get_type::<SmocapWarning>(), &msg, 1)
}
