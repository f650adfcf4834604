//! `Motion`: a solved trial: coordinates and solver statistics per frame as DataFrames, its
//! report entry, and its OpenSim motion written by the command line's writer.

use crate::errors::{to_py, SolveError};
use numpy::PyArray1;
use pyo3::prelude::*;
use smocap::io::MarkerTrial;
use smocap::pipeline::results::report::TrialReport;
use smocap::pipeline::session::Calibrated;
use smocap::pipeline::TrialResult;
use std::path::PathBuf;
use std::sync::Arc;

/// A trial solved for a calibrated subject.
#[pyclass(module = "smocap", frozen)]
pub struct Motion {
    pub cal: Arc<Calibrated>,
    /// The trial as solved (in the model's units and up axis).
    pub trial: Arc<MarkerTrial>,
    pub result: TrialResult,
    pub report: TrialReport,
    pub notes: Vec<String>,
}

/// Solver status names, as in `/smocap/stats` and `Trial.stats`.
fn status_name(s: smocap::solve::FrameStatus) -> &'static str {
    smocap::archive::proto::STATUS_NAMES[smocap::archive::mcap_out::status_code(s) as usize]
}

#[pymethods]
impl Motion {
    /// Every coordinate per frame (rad or m), columns in model order, indexed by frame time (s).
    #[getter]
    fn q<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let ctx = &self.cal.ctx;
        let q = py
            .detach(|| smocap::pipeline::results::export::coordinates(ctx, &self.result.proxies))
            .map_err(to_py::<SolveError>)?;
        let names = ctx.model.coordinates.iter().map(|c| c.name.clone()).collect();
        crate::table(py, q.concat(), names, self.trial.times.clone())
    }

    /// Per frame: `rmse` (the solver's marker RMSE, m, as the report's `marker_rmse_mm`),
    /// `iterations`, `accepted_steps`, `energy`, `markers_used`, `status` (`Converged`,
    /// `MaxIterations`, `TooFewMarkers`, `QpFailed`, `Stalled`), `bridged`, `solve_s` (s).
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let (st, r) = (&self.result.stats, &self.result);
        let col = |v: Vec<f64>| PyArray1::from_vec(py, v).into_any();
        let int = |v: Vec<i64>| PyArray1::from_vec(py, v).into_any();
        let bridged: Vec<bool> = (0..st.len()).map(|f| r.bridged.binary_search(&f).is_ok()).collect();
        let status: Vec<&str> = st.iter().map(|s| status_name(s.status)).collect();
        crate::columns(
            py,
            vec![
                ("rmse", col(st.iter().map(|s| s.rmse_m).collect())),
                ("iterations", int(st.iter().map(|s| i64::from(s.iterations)).collect())),
                ("accepted_steps", int(st.iter().map(|s| i64::from(s.accepted)).collect())),
                ("energy", col(st.iter().map(|s| s.energy).collect())),
                ("markers_used", int(st.iter().map(|s| s.markers_used as i64).collect())),
                ("status", status.into_pyobject(py)?.into_any()),
                ("bridged", PyArray1::from_vec(py, bridged).into_any()),
                ("solve_s", col(r.frame_seconds.clone())),
            ],
            self.trial.times.clone(),
        )
    }

    /// The trial's report entry (as in `smocap solve --report-json`'s `trials`).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::to_python(py, &self.report)
    }

    /// `'ok'`, or `'suspect'` (the report's `error` says why).
    #[getter]
    fn status(&self) -> String {
        self.report.status.clone()
    }

    /// The trial's name (its path, or the `Markers`' name).
    #[getter]
    fn name(&self) -> String {
        self.report.trial.clone()
    }

    /// Frame times (s), as in the trial.
    #[getter]
    fn times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.trial.times.clone())
    }

    /// Lines worth reading: bridged frames, pre-solved outliers, why it is suspect.
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }

    /// Writes the motion as OpenSim's `.mot` (every coordinate, rotations in degrees), byte for
    /// byte as `smocap solve --mot-dir` writes it for the same inputs and settings.
    fn to_mot(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| smocap::pipeline::results::export::write_mot(&self.cal.ctx, &self.result, &self.trial, &path))
            .map_err(to_py::<SolveError>)
    }

    fn __len__(&self) -> usize {
        self.result.proxies.len()
    }

    fn __repr__(&self) -> String {
        let rmse = self.report.marker_rmse_mm.as_ref().map_or(String::new(), |r| format!(", RMSE p50 {:.2} mm", r.p50));
        format!("Motion({:?}: {} frames{rmse}, {})", self.report.trial, self.result.proxies.len(), self.report.status)
    }
}
