//! `Model`: the files that describe a subject's model (as `smocap solve`'s `--model`,
//! `--markerset`, `--profile`, `--scale-setup`, `--ik-setup`), loaded once to say what it holds.

use crate::errors::{to_py, ModelError};
use pyo3::prelude::*;
use smocap::model::CoordinateKind;
use smocap::pipeline::calibration::subject::{prepare_subject_with, SubjectFiles};
use smocap::pipeline::Context;
use std::path::PathBuf;
use std::sync::Arc;

/// A model with its marker set, solver profile and OpenSim setups.
#[pyclass(module = "smocap", frozen)]
pub struct Model {
    /// The model's files; `calibrate` adds the static trial and what is known of the subject.
    pub files: SubjectFiles,
    /// The model as set up from them (for its names).
    pub ctx: Arc<Context>,
    pub notes: Vec<String>,
}

#[pymethods]
impl Model {
    #[new]
    #[pyo3(signature = (path = None, markerset = None, profile = None, scale_setup = None, ik_setup = None))]
    fn new(
        py: Python<'_>,
        path: Option<PathBuf>,
        markerset: Option<PathBuf>,
        profile: Option<PathBuf>,
        scale_setup: Option<PathBuf>,
        ik_setup: Option<PathBuf>,
    ) -> PyResult<Self> {
        let files = SubjectFiles { model: path, markerset, profile, scale_setup, ik_setup, ..Default::default() };
        // Set up as for a static calibration: a Scale setup's static file is only looked for
        // when calibrating (where `static=` may replace it).
        let s = py.detach(|| prepare_subject_with(&files, true)).map_err(to_py::<ModelError>)?;
        Ok(Model { files, ctx: Arc::new(s.ctx), notes: s.notes })
    }

    /// The model file (`None`: the shipped full-body model).
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.files.model.clone()
    }

    /// Coordinate names, in model order (the columns of `Motion.q`).
    #[getter]
    fn coordinates(&self) -> Vec<String> {
        self.ctx.model.coordinates.iter().map(|c| c.name.clone()).collect()
    }

    /// Each coordinate's unit: `'rad'` (rotational) or `'m'` (translational).
    #[getter]
    fn coordinate_units(&self) -> Vec<&'static str> {
        let unit = |k: CoordinateKind| if k == CoordinateKind::Rotational { "rad" } else { "m" };
        self.ctx.model.coordinates.iter().map(|c| unit(c.kind)).collect()
    }

    /// Body names, in model order.
    #[getter]
    fn bodies(&self) -> Vec<String> {
        self.ctx.model.bodies.iter().map(|b| b.name.clone()).collect()
    }

    /// Model marker names, in model order.
    #[getter]
    fn markers(&self) -> Vec<String> {
        self.ctx.model.markers.iter().map(|m| m.name.clone()).collect()
    }

    /// What loading the files noticed (importer warnings, the IK setup's tasks), one line each.
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "Model({}: {} bodies, {} coordinates, {} markers)",
            self.ctx.model_source,
            self.ctx.model.nb(),
            self.ctx.model.nq(),
            self.ctx.model.markers.len()
        )
    }
}
