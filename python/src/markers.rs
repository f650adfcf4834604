//! `Markers`: a marker trial as read from a file (TRC, C3D) or built from arrays, and how the
//! binding takes trials given as paths or `Markers`.

use crate::errors::{to_py, MarkerFileError};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use smocap::io::markers::{per_metre, units_to_metres};
use smocap::io::MarkerTrial;
use smocap::pipeline::input::convention::{InputConventions, InputOptions, Units, UpAxis};
use smocap::pipeline::{session, Context};
use std::path::PathBuf;
use std::sync::Arc;

/// Marker trajectories of one trial: labels, rate, frame times and positions (frames × markers
/// × 3, NaN for gaps), in the file's lab frame and units.
///
/// Built by `read_markers`, or from arrays so that data that never was a file can be solved:
/// `Markers(labels, xyz, rate_hz, units="m")`, `xyz` of shape (frames, markers, 3) with NaN for
/// gaps; `times` (s) default to `i / rate_hz`; `up` is the data's up axis ('x', 'y', 'z';
/// detected when solving if None).
#[pyclass(module = "smocap", frozen)]
pub struct Markers {
    /// As read: positions in metres, in the file's lab frame (`MarkerTrial`'s convention).
    pub trial: Arc<MarkerTrial>,
    /// The units and up axis given (`None`: from the file header / detected when solving).
    pub opt: InputOptions,
    pub name: String,
}

/// `--units` values: the units of the numbers, overriding a file's header.
fn parse_units(u: Option<&str>) -> PyResult<Option<Units>> {
    u.map(|u| match u.trim().to_ascii_lowercase().as_str() {
        "mm" => Ok(Units::Mm),
        "cm" => Ok(Units::Cm),
        "m" => Ok(Units::M),
        other => Err(PyValueError::new_err(format!("units {other:?}: expected 'mm', 'cm' or 'm'"))),
    })
    .transpose()
}

/// `--up` values: the data's up axis.
fn parse_up(u: Option<&str>) -> PyResult<Option<UpAxis>> {
    u.map(|u| match u.trim().to_ascii_lowercase().as_str() {
        "x" => Ok(UpAxis::X),
        "y" => Ok(UpAxis::Y),
        "z" => Ok(UpAxis::Z),
        other => Err(PyValueError::new_err(format!("up {other:?}: expected 'x', 'y' or 'z'"))),
    })
    .transpose()
}

/// `a` as a C-contiguous float64 NumPy array, copied out.
fn f64_array(a: &Bound<'_, PyAny>) -> PyResult<(Vec<usize>, Vec<f64>)> {
    let np = a.py().import("numpy")?;
    let arr = np.call_method1("ascontiguousarray", (a, "float64"))?;
    let arr: PyReadonlyArrayDyn<'_, f64> = arr.extract()?;
    let shape = arr.shape().to_vec();
    let data = match arr.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => arr.as_array().iter().copied().collect(),
    };
    Ok((shape, data))
}

#[pymethods]
impl Markers {
    #[new]
    #[pyo3(signature = (labels, xyz, rate_hz, units = "m", up = None, times = None, name = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        labels: Vec<String>,
        xyz: &Bound<'_, PyAny>,
        rate_hz: f64,
        units: &str,
        up: Option<&str>,
        times: Option<&Bound<'_, PyAny>>,
        name: Option<String>,
    ) -> PyResult<Self> {
        let (shape, data) = f64_array(xyz)?;
        if shape.len() != 3 || shape[1] != labels.len() || shape[2] != 3 {
            return Err(PyValueError::new_err(format!(
                "xyz has shape {shape:?}: expected (frames, {}, 3) for {} labels",
                labels.len(),
                labels.len()
            )));
        }
        let times = match times {
            Some(t) => {
                let (s, v) = f64_array(t)?;
                if s != [shape[0]] {
                    return Err(PyValueError::new_err(format!(
                        "times has shape {s:?}: expected ({},) for {} frames",
                        shape[0], shape[0]
                    )));
                }
                Some(v)
            }
            None => None,
        };
        let opt = InputOptions { up: parse_up(up)?, units: None };
        let units = units.to_string();
        let trial = py
            .detach(move || smocap::io::markers_from_arrays(labels, &data, rate_hz, &units, times))
            .map_err(to_py::<MarkerFileError>)?;
        Ok(Markers { trial: Arc::new(trial), opt, name: name.unwrap_or_else(|| "markers".into()) })
    }

    /// Marker labels, as in the file.
    #[getter]
    fn labels(&self) -> Vec<String> {
        self.trial.labels.clone()
    }

    /// Sampling rate (Hz).
    #[getter]
    fn rate_hz(&self) -> f64 {
        self.trial.rate_hz
    }

    /// Units of `xyz`: those given (`read_markers(units=...)`), else the file's.
    #[getter]
    fn units(&self) -> String {
        self.opt.units.map_or_else(|| self.trial.source_units.clone(), |u| u.name().to_string())
    }

    /// The data's up axis when given (`'x'`, `'y'`, `'z'`); `None`: detected when solving.
    #[getter]
    fn up(&self) -> Option<&'static str> {
        self.opt.up.map(|u| match u {
            UpAxis::X => "x",
            UpAxis::Y => "y",
            UpAxis::Z => "z",
        })
    }

    /// Frame times (s), shape (frames,).
    #[getter]
    fn times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.trial.times.clone())
    }

    /// Frame numbers as in the file (usually from 1), shape (frames,).
    #[getter]
    fn frame_numbers<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        PyArray1::from_vec(py, self.trial.frame_numbers.clone())
    }

    /// Positions as read, shape (frames, markers, 3), in `units`, NaN for gaps.
    #[getter]
    fn xyz<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let t = &self.trial;
        let k = per_metre(units_to_metres(&t.source_units).unwrap_or(1.0));
        let v: Vec<f64> = py.detach(|| t.positions.iter().map(|p| p * k).collect());
        Ok(PyArray1::from_vec(py, v).reshape([t.n_frames(), t.n_markers(), 3])?.into_any())
    }

    /// What the reader noticed (header counts, unnamed markers, masked samples), one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.trial.warnings.clone()
    }

    /// Where the markers came from (the file path, or the name given).
    #[getter]
    fn name(&self) -> String {
        self.name.clone()
    }

    fn __len__(&self) -> usize {
        self.trial.n_frames()
    }

    fn __repr__(&self) -> String {
        format!(
            "Markers({:?}: {} frames x {} markers at {} Hz, {})",
            self.name,
            self.trial.n_frames(),
            self.trial.n_markers(),
            self.trial.rate_hz,
            self.units()
        )
    }
}

/// Reads a marker file (TRC or C3D, by extension).
///
/// `units` ('mm', 'cm', 'm') overrides the file header's, `up` ('x', 'y', 'z') gives the data's
/// up axis (as `smocap solve --units/--up`); both apply when the markers are solved. Raises
/// MarkerFileError.
#[pyfunction]
#[pyo3(signature = (path, units = None, up = None))]
pub fn read_markers(py: Python<'_>, path: PathBuf, units: Option<&str>, up: Option<&str>) -> PyResult<Markers> {
    let opt = InputOptions { units: parse_units(units)?, up: parse_up(up)? };
    let trial = py.detach(|| smocap::io::read_markers(&path)).map_err(to_py::<MarkerFileError>)?;
    Ok(Markers { trial: Arc::new(trial), opt, name: path.display().to_string() })
}

/// A trial given to `calibrate` or `solve`: a marker file's path or `Markers`.
#[derive(Clone)]
pub enum Input {
    Path(PathBuf),
    Markers { trial: Arc<MarkerTrial>, opt: InputOptions, name: String },
}

impl Input {
    pub fn extract(obj: &Bound<'_, PyAny>) -> PyResult<Input> {
        if let Ok(m) = obj.cast::<Markers>() {
            let m = m.get();
            return Ok(Input::Markers { trial: m.trial.clone(), opt: m.opt, name: m.name.clone() });
        }
        obj.extract::<PathBuf>().map(Input::Path).map_err(|_| {
            PyValueError::new_err(format!(
                "expected a marker file path or smocap.Markers, got {}",
                obj.get_type().name().map_or_else(|_| "?".into(), |n| n.to_string())
            ))
        })
    }

    /// Whether it is a file (a static trial given as a path is the subject's `static_trial`).
    pub fn path(&self) -> Option<&PathBuf> {
        match self {
            Input::Path(p) => Some(p),
            Input::Markers { .. } => None,
        }
    }

    /// The trial in `ctx`'s units and up axis (as `smocap solve` reads its files), with its name
    /// (the path as given, or the `Markers`' name).
    pub fn load(&self, ctx: &Context) -> Result<(String, MarkerTrial, InputConventions), smocap::io::MarkerFileError> {
        match self {
            Input::Path(p) => {
                let (t, conv) = session::read_input(ctx, p, &InputOptions::default())?;
                Ok((p.display().to_string(), t, conv))
            }
            Input::Markers { trial, opt, name } => {
                let mut t = (**trial).clone();
                let conv = session::conform_input(ctx, &mut t, opt);
                Ok((name.clone(), t, conv))
            }
        }
    }
}
