//! `smocap._smocap`: the Python binding of smocap (PyO3). The Rust library is the one
//! implementation: every function here converts its arguments, releases the GIL, calls the same
//! library functions as the `smocap` command line (`smocap::pipeline::session`, `::export`,
//! `::archive`), and converts the results (NumPy arrays, pandas DataFrames, dicts). The public
//! API and its documentation are in `python/smocap/__init__.pyi`.

mod archive;
mod convert;
mod errors;
mod markers;
mod model;
mod motion;
mod render;
mod subject;

use pyo3::prelude::*;

#[pymodule]
fn _smocap(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(py, m)?;
    m.add_class::<markers::Markers>()?;
    m.add_class::<model::Model>()?;
    m.add_class::<subject::Subject>()?;
    m.add_class::<motion::Motion>()?;
    m.add_class::<archive::Trial>()?;
    m.add_function(wrap_pyfunction!(markers::read_markers, m)?)?;
    m.add_function(wrap_pyfunction!(subject::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(archive::read_trial, m)?)?;
    m.add_function(wrap_pyfunction!(convert::convert, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    Ok(())
}

/// A serializable value (a report) as Python objects (dicts, lists, numbers, strings).
pub(crate) fn to_python<'py>(py: Python<'py>, v: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(v).map_err(|e| errors::SmocapError::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// A pandas DataFrame of `rows` (row-major, `index.len()` rows of `columns.len()` values),
/// indexed by frame time `index` (s, named `time_s`).
pub(crate) fn table<'py>(
    py: Python<'py>,
    rows: Vec<f64>,
    columns: Vec<String>,
    index: Vec<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    use numpy::{PyArray1, PyArrayMethods};
    let shape = [index.len(), columns.len()];
    let data = PyArray1::from_vec(py, rows).reshape(shape)?;
    let pd = py.import("pandas")?;
    let kw = pyo3::types::PyDict::new(py);
    kw.set_item("columns", columns)?;
    kw.set_item("index", time_index(py, index)?)?;
    pd.getattr("DataFrame")?.call((data,), Some(&kw))
}

/// A pandas DataFrame of named columns (each a NumPy array or list), indexed by frame time.
pub(crate) fn columns<'py>(
    py: Python<'py>,
    cols: Vec<(&str, Bound<'py, PyAny>)>,
    index: Vec<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let d = pyo3::types::PyDict::new(py);
    for (k, v) in cols {
        d.set_item(k, v)?;
    }
    let kw = pyo3::types::PyDict::new(py);
    kw.set_item("index", time_index(py, index)?)?;
    py.import("pandas")?.getattr("DataFrame")?.call((d,), Some(&kw))
}

/// `pandas.Index(times, name="time_s")`.
fn time_index<'py>(py: Python<'py>, times: Vec<f64>) -> PyResult<Bound<'py, PyAny>> {
    let kw = pyo3::types::PyDict::new(py);
    kw.set_item("name", "time_s")?;
    py.import("pandas")?.getattr("Index")?.call((numpy::PyArray1::from_vec(py, times),), Some(&kw))
}
