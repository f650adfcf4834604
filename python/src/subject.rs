//! `calibrate` and `Subject`: a subject calibrated once from its static trial and its motion
//! trials, then solving trials, through `smocap::pipeline::session` as `smocap solve` does.

use crate::errors::{message, to_py, warn, CalibrationError, MarkerFileError, ModelError, SolveError};
use crate::markers::Input;
use crate::model::Model;
use crate::motion::Motion;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use smocap::model::anthropometry::{Sex, SubjectInfo};
use smocap::pipeline::calibration::subject::{prepare_subject_with, SetupError, SubjectFiles};
use smocap::pipeline::running::device::BackendChoice;
use smocap::pipeline::session::{self, Calibrated};
use smocap::pipeline::Context;
use std::path::PathBuf;
use std::sync::Arc;

/// A calibrated subject: its scales, registered markers and calibration report.
#[pyclass(module = "smocap", frozen)]
pub struct Subject {
    /// The subject before calibration: trials are brought into its conventions.
    pub generic: Arc<Context>,
    pub cal: Arc<Calibrated>,
    /// The model file, rewritten by `write_osim` when it is an `.osim`.
    pub model_file: Option<PathBuf>,
    pub notes: Vec<String>,
}

/// A set-up error as the exception it is: the subject's description (height, mass, sex) or its
/// calibration, else the model's files.
fn setup_error(e: SetupError) -> PyErr {
    match e {
        SetupError::Calibration(_) => to_py::<CalibrationError>(e),
        _ => to_py::<ModelError>(e),
    }
}

/// A Python value as a TOML value (settings overrides).
fn toml_value(v: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    if let Ok(b) = v.extract::<bool>() {
        return Ok(toml::Value::Boolean(b));
    }
    if let Ok(i) = v.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = v.extract::<f64>() {
        return Ok(toml::Value::Float(f));
    }
    if let Ok(s) = v.extract::<String>() {
        return Ok(toml::Value::String(s));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        return Ok(toml::Value::Table(toml_table(d)?));
    }
    if let Ok(l) = v.cast::<PyList>() {
        return Ok(toml::Value::Array(l.iter().map(|x| toml_value(&x)).collect::<PyResult<_>>()?));
    }
    Err(PyValueError::new_err(format!("settings: {v} cannot be a solver setting's value")))
}

fn toml_table(d: &Bound<'_, PyDict>) -> PyResult<toml::Table> {
    d.iter().map(|(k, v)| Ok((k.extract::<String>()?, toml_value(&v)?))).collect()
}

/// The backend named as on the command line.
pub fn parse_backend(s: &str) -> PyResult<BackendChoice> {
    Ok(match s {
        "cpu" => BackendChoice::Cpu,
        "wgpu" => BackendChoice::Wgpu,
        "wgpu-f64" => BackendChoice::WgpuF64,
        "auto" => BackendChoice::Auto,
        _ => return Err(PyValueError::new_err(format!("backend {s:?}: expected 'cpu', 'wgpu', 'wgpu-f64' or 'auto'"))),
    })
}

/// `trials` as a list of inputs (one path or `Markers`, or an iterable of them).
fn inputs(trials: &Bound<'_, PyAny>) -> PyResult<Vec<Input>> {
    if let Ok(one) = Input::extract(trials) {
        return Ok(vec![one]);
    }
    trials.try_iter()?.map(|t| Input::extract(&t?)).collect()
}

/// Calibrates a subject once, from its static trial (when given, or named by the model's Scale
/// setup) and frames of its motion `trials`, as `smocap solve` does.
///
/// Trials are paths (units and up axis from the header / detected) or `Markers`. `height` (m),
/// `mass` (kg) and `sex` ('male'/'female') condition the anthropometric prior; `register=False`
/// keeps the model's marker positions; `place_markers` places them on the static trial
/// (OpenSim's MarkerPlacer); `settings` overrides solver settings (a profile's `[solver]` keys,
/// as `--set KEY=VALUE`). A suspect calibration warns (SmocapWarning). Raises
/// CalibrationError, ModelError, MarkerFileError.
#[pyfunction]
#[pyo3(signature = (model, trials, r#static = None, height = None, mass = None, sex = None, register = true,
    settings = None, place_markers = false))]
#[allow(clippy::too_many_arguments)]
pub fn calibrate(
    py: Python<'_>,
    model: Option<Bound<'_, Model>>,
    trials: &Bound<'_, PyAny>,
    r#static: Option<&Bound<'_, PyAny>>,
    height: Option<f64>,
    mass: Option<f64>,
    sex: Option<&str>,
    register: bool,
    settings: Option<&Bound<'_, PyDict>>,
    place_markers: bool,
) -> PyResult<Subject> {
    let trials = inputs(trials)?;
    let static_input = r#static.map(Input::extract).transpose()?;
    let sex = sex.map(str::parse::<Sex>).transpose().map_err(to_py::<CalibrationError>)?;
    let overrides = settings.map(toml_table).transpose()?.unwrap_or_default();
    let mut files = model.map_or_else(SubjectFiles::default, |m| m.get().files.clone());
    files.static_trial = static_input.as_ref().and_then(Input::path).cloned();
    files.subject = SubjectInfo { height_m: height, mass_kg: mass, sex };
    files.no_register = !register;
    files.place_markers = place_markers;
    let static_in_memory = static_input.as_ref().is_some_and(|s| s.path().is_none());
    let model_file = files.model.clone();
    let (generic, cal, notes) = py.detach(move || -> PyResult<_> {
        let s = prepare_subject_with(&files, static_in_memory).map_err(setup_error)?;
        let mut ctx = s.ctx;
        session::apply_overrides(&mut ctx, &overrides)
            .map_err(|e| PyErr::new::<ModelError, _>(format!("settings: {e}")))?;
        // The static trial: given, or named by the Scale setup.
        let static_input = static_input.or_else(|| s.static_path.map(Input::Path));
        let load = |i: &Input| i.load(&ctx).map_err(|e| PyErr::new::<MarkerFileError, _>(message(&e)));
        let mut statics = static_input.as_ref().map(load).transpose()?;
        let mut motions = trials.iter().map(load).collect::<PyResult<Vec<_>>>()?;
        // Labels screened as `smocap solve` screens them (swaps repaired, jumps masked) before
        // they inform the calibration.
        for (n, t, _) in statics.iter_mut().chain(&mut motions) {
            session::screen_labels(&ctx, n, t);
        }
        let statics: Vec<(&str, &_)> = statics.iter().map(|(n, t, _)| (n.as_str(), t)).collect();
        let motions: Vec<(&str, &_)> = motions.iter().map(|(n, t, _)| (n.as_str(), t)).collect();
        if statics.is_empty() && motions.is_empty() {
            return Err(PyErr::new::<CalibrationError, _>("no trial to calibrate on"));
        }
        let cal = session::calibrate(&ctx, &statics, &motions).map_err(setup_error)?;
        Ok((ctx, cal, s.notes))
    })?;
    let suspect = cal.suspect();
    if !suspect.is_empty() {
        warn(py, &format!("suspect calibration: {}", suspect.join("; ")))?;
    }
    Ok(Subject { generic: Arc::new(generic), cal: Arc::new(cal), model_file, notes })
}

#[pymethods]
impl Subject {
    /// Calibrated scale factors `[x, y, z]` of every body, by body name.
    #[getter]
    fn scales(&self) -> PyResult<std::collections::BTreeMap<String, [f64; 3]>> {
        let s = smocap::pipeline::results::export::body_scales(&self.cal.ctx, &self.cal.calibration)
            .map_err(to_py::<CalibrationError>)?;
        Ok(self.cal.ctx.model.bodies.iter().zip(s).map(|(b, v)| (b.name.clone(), [v.x, v.y, v.z])).collect())
    }

    /// The calibrated subject's stature (m), measured on the model's landmarks when it has them.
    #[getter]
    fn stature_m(&self) -> Option<f64> {
        self.cal.report.prior.stature_m
    }

    /// `'ok'`, or `'suspect'` (then `warnings` says why; every trial solved is `suspect`).
    #[getter]
    fn status(&self) -> String {
        self.cal.report.status.clone()
    }

    /// Why the calibration is suspect, and scales far from their prior, one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.cal.report.warnings.clone()
    }

    /// What setting the subject up noticed (model importer, setups), one line each.
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }

    /// The report's `calibration` section (as `smocap solve --report-json` writes it).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::to_python(py, &self.cal.report)
    }

    /// Coordinate names, in model order (the columns of `Motion.q`).
    #[getter]
    fn coordinates(&self) -> Vec<String> {
        self.cal.ctx.model.coordinates.iter().map(|c| c.name.clone()).collect()
    }

    /// Writes the calibrated subject as an OpenSim model (the `.osim` model file rescaled as
    /// OpenSim's ScaleTool would, or the model generated) and its scale set beside it
    /// (`<stem>.scaleset.xml`), as `smocap solve --scaled-model`; returns the scale set's path.
    fn write_osim(&self, py: Python<'_>, path: PathBuf) -> PyResult<PathBuf> {
        let (cal, model) = (&self.cal, self.model_file.as_deref());
        let (warnings, set) = py
            .detach(|| smocap::pipeline::results::export::write_scaled_model(&cal.ctx, &cal.calibration, model, &path))
            .map_err(to_py::<ModelError>)?;
        // Notes, as the command line prints them (`note: ...`): to the `smocap` logger.
        let log = py.import("logging")?.call_method1("getLogger", ("smocap",))?;
        for w in warnings {
            log.call_method1("info", (w,))?;
        }
        Ok(set)
    }

    /// Solves every frame of `trial` (a path or `Markers`) with the calibrated morphology.
    ///
    /// `threads` (default: the machine's parallelism) and `lanes` change the speed, never the
    /// result; `backend` is 'cpu' (the f64 reference), 'wgpu', 'wgpu-f64' or 'auto'. The GIL is
    /// released while solving. A suspect trial warns (SmocapWarning); a trial with no result
    /// raises SolveError.
    #[pyo3(signature = (trial, threads = None, backend = "cpu", lanes = None))]
    fn solve(
        &self,
        py: Python<'_>,
        trial: &Bound<'_, PyAny>,
        threads: Option<usize>,
        backend: &str,
        lanes: Option<usize>,
    ) -> PyResult<Motion> {
        let input = Input::extract(trial)?;
        let choice = parse_backend(backend)?;
        if let Some(t) = threads.filter(|t| !(1..=4096).contains(t)) {
            return Err(PyValueError::new_err(format!("threads {t}: expected 1 to 4096")));
        }
        if let Some(l) = lanes.filter(|l| !(1..=1 << 20).contains(l)) {
            return Err(PyValueError::new_err(format!("lanes {l}: expected 1 to {}", 1 << 20)));
        }
        let threads = threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
        let (generic, cal) = (self.generic.clone(), self.cal.clone());
        let motion = py.detach(move || -> PyResult<Motion> {
            let (name, mut trial, input) =
                input.load(&generic).map_err(|e| PyErr::new::<MarkerFileError, _>(message(&e)))?;
            let qc = session::screen_labels(&generic, &name, &mut trial);
            let eval = cal.ctx.evaluator();
            let mut chosen =
                smocap::pipeline::running::device::choose(choice, &eval, smocap::kinematics::gpu::DEFAULT_CAP)
                    .map_err(to_py::<SolveError>)?;
            let lanes = lanes.unwrap_or_else(|| chosen.default_lanes(threads));
            let mut notes: Vec<String> = chosen.note().map(|n| format!("note: {n}")).into_iter().collect();
            let mut j = session::solve_judged(&cal, &name, &trial, &input, threads, lanes, chosen.backend(), None)
                .map_err(PyErr::new::<SolveError, _>)?;
            session::attach_label_qc(&mut j, qc);
            notes.extend(j.notes);
            Ok(Motion { cal, trial: Arc::new(trial), result: j.result, report: j.report, notes })
        })?;
        if let Some(why) = motion.report.error.as_deref().filter(|_| motion.report.status == "suspect") {
            warn(py, &format!("{}: suspect: {why}", motion.report.trial))?;
        }
        Ok(motion)
    }

    fn __repr__(&self) -> String {
        let stature = self.cal.report.prior.stature_m.map_or(String::new(), |h| format!(", stature {h:.3} m"));
        format!(
            "Subject({}: {} bodies{stature}, calibration RMSE {:.2} mm, {})",
            self.cal.ctx.model_source,
            self.cal.ctx.model.nb(),
            self.cal.report.rmse_mm,
            self.cal.report.status
        )
    }
}
