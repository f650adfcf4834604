//! `read_trial` and `Trial`: a trial converted by `smocap convert` read back from its `.mcap`
//! file (`smocap::archive::export::read_trial_record`, as `smocap export` reads it).

use crate::errors::{to_py, ArchiveError, ModelError, SmocapError};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use smocap::archive::export::{body_scales, conversion_model, read_trial_record, write_mot, TrialRecord};
use smocap::archive::proto::{SolverStats, STATUS_NAMES};
use std::path::PathBuf;

/// A converted trial: coordinates, solver statistics and observed markers per frame, and the
/// subject (names, calibrated scales).
#[pyclass(module = "smocap", frozen)]
pub struct Trial {
    rec: TrialRecord,
    path: PathBuf,
}

impl Trial {
    /// Frame times (s) as in the input file: the messages' times plus the first sample's.
    fn time(&self) -> Vec<f64> {
        self.rec.frames.iter().map(|f| f.state.time + self.rec.time_offset).collect()
    }

    /// A frame's time as in `q`'s index (None when that frame was not written).
    fn time_of(&self, frame: u32) -> Option<f64> {
        self.rec.frames.iter().find(|f| f.state.frame == frame as usize).map(|f| f.state.time + self.rec.time_offset)
    }

    /// Coordinate names: the subject's order, else (files of the JSON encoding) by name.
    fn coordinate_names(&self) -> Vec<String> {
        match &self.rec.subject {
            Some(s) => s.coordinates.clone(),
            None => self.rec.frames.first().map(|f| f.state.q.keys().cloned().collect()).unwrap_or_default(),
        }
    }
}

/// Reads a trial converted by `smocap convert` (its MCAP structure checked first).
#[pyfunction]
pub fn read_trial(py: Python<'_>, path: PathBuf) -> PyResult<Trial> {
    let rec = py.detach(|| read_trial_record(&path)).map_err(to_py::<ArchiveError>)?;
    Ok(Trial { rec, path })
}

#[pymethods]
impl Trial {
    /// Every coordinate per frame (rad or m), in the subject's order, indexed by frame time (s,
    /// as in the input file).
    #[getter]
    fn q<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let names = self.coordinate_names();
        let rows: Vec<f64> = self
            .rec
            .frames
            .iter()
            .flat_map(|f| names.iter().map(|n| f.state.q.get(n).copied().unwrap_or(f64::NAN)))
            .collect();
        crate::table(py, rows, names, self.time())
    }

    /// Per frame, from `/smocap/stats`: `iterations`, `accepted_steps`, `energy`, `rmse` (the
    /// solver's weighted marker RMSE, m), `markers_used`, `markers_observed`, `status`,
    /// `bridged`, `marker_rmse` (unweighted RMS of observed − model markers, m; NaN when none is
    /// observed), `solve_s` (0 unless converted with `--timings`).
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let frames = &self.rec.frames;
        if self.rec.stats.is_empty() {
            // Files of the JSON encoding: RMSE and status only.
            let rmse: Vec<f64> = frames.iter().map(|f| f.rmse_m.unwrap_or(f64::NAN)).collect();
            let status: Vec<Option<String>> = frames.iter().map(|f| f.status.clone()).collect();
            let cols = vec![
                ("marker_rmse", PyArray1::from_vec(py, rmse).into_any()),
                ("status", status.into_pyobject(py)?.into_any()),
            ];
            return crate::columns(py, cols, self.time());
        }
        let none = SolverStats::default();
        let st: Vec<&SolverStats> =
            frames.iter().map(|f| self.rec.stats.get(&f.state.frame).unwrap_or(&none)).collect();
        let col = |v: Vec<f64>| PyArray1::from_vec(py, v).into_any();
        let int = |v: Vec<i64>| PyArray1::from_vec(py, v).into_any();
        let status: Vec<&str> = st.iter().map(|s| STATUS_NAMES.get(s.status as usize).copied().unwrap_or("")).collect();
        let cols = vec![
            ("iterations", int(st.iter().map(|s| i64::from(s.iterations)).collect())),
            ("accepted_steps", int(st.iter().map(|s| i64::from(s.accepted_steps)).collect())),
            ("energy", col(st.iter().map(|s| s.energy).collect())),
            ("rmse", col(st.iter().map(|s| s.rmse).collect())),
            ("markers_used", int(st.iter().map(|s| i64::from(s.markers_used)).collect())),
            ("markers_observed", int(st.iter().map(|s| i64::from(s.markers_observed)).collect())),
            ("status", status.into_pyobject(py)?.into_any()),
            ("bridged", PyArray1::from_vec(py, st.iter().map(|s| s.bridged).collect::<Vec<bool>>()).into_any()),
            ("marker_rmse", col(st.iter().map(|s| s.marker_rmse).collect())),
            ("solve_s", col(st.iter().map(|s| f64::from(s.solve_s)).collect())),
        ];
        crate::columns(py, cols, self.time())
    }

    /// Observed markers per frame, shape (frames, markers, 3) (m, in the model's frame, float32
    /// in the file), NaN where not observed; `marker_names` names the second axis.
    #[getter]
    fn markers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let n = self.rec.marker_names.len();
        let mut v = Vec::with_capacity(self.rec.frames.len() * n * 3);
        for f in &self.rec.frames {
            match self.rec.observed.get(&f.state.frame).filter(|p| p.len() == 3 * n) {
                Some(p) => v.extend(p.iter().map(|&x| f64::from(x))),
                None => v.extend(std::iter::repeat_n(f64::NAN, 3 * n)),
            }
        }
        Ok(PyArray1::from_vec(py, v).reshape([self.rec.frames.len(), n, 3])?.into_any())
    }

    /// The model markers, in `/smocap/subject` order (the second axis of `markers`).
    #[getter]
    fn marker_names(&self) -> Vec<String> {
        self.rec.marker_names.clone()
    }

    /// Frame times (s), as in the input file.
    #[getter]
    fn times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.time())
    }

    /// The subject, from `/smocap/subject`: `dataset`, `subject`, `trial`, `coordinates`,
    /// `coordinate_units`, `bodies`, `body_parents`, `markers`, `marker_bodies`, `proxies`,
    /// `scales` (calibrated `[x, y, z]` by body), `world_from_model` (`[x, y, z, w]`).
    #[getter]
    fn subject<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let Some(s) = &self.rec.subject else {
            d.set_item("coordinates", self.coordinate_names())?;
            return Ok(d);
        };
        d.set_item("dataset", &s.dataset)?;
        d.set_item("subject", &s.subject)?;
        d.set_item("trial", &s.trial)?;
        d.set_item("coordinates", &s.coordinates)?;
        d.set_item("coordinate_units", &s.coordinate_units)?;
        d.set_item("bodies", &s.bodies)?;
        d.set_item("body_parents", &s.body_parents)?;
        d.set_item("markers", &s.markers)?;
        d.set_item("marker_bodies", &s.marker_bodies)?;
        d.set_item("proxies", &s.proxies)?;
        let scales =
            body_scales(s, None).map_err(|e| ArchiveError::new_err(format!("{}: {e}", self.path.display())))?;
        d.set_item("scales", scales)?;
        d.set_item("world_from_model", &s.world_from_model)?;
        Ok(d)
    }

    /// The label quality control, from `/smocap/label_qc` (None for files written before it):
    /// `mode`, `rigid_pairs`, `masked_frames`, `masked_share`, `suspect` (None when not), and
    /// `events`, a list of dicts (pandas-ready: `pd.DataFrame(trial.label_qc["events"])`) with
    /// `kind`, `markers`, `first_frame`, `last_frame`, `first_time`, `last_time` (s, the frames'
    /// times as in `q`'s index), `detected_frames`, `action`, `residual_before_mm`,
    /// `residual_after_mm` (None for masks).
    #[getter]
    fn label_qc<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(qc) = &self.rec.label_qc else { return Ok(None) };
        let d = PyDict::new(py);
        d.set_item("mode", &qc.mode)?;
        d.set_item("rigid_pairs", qc.rigid_pairs)?;
        d.set_item("masked_frames", qc.masked_frames)?;
        d.set_item("masked_share", qc.masked_share)?;
        d.set_item("suspect", (!qc.suspect.is_empty()).then_some(&qc.suspect))?;
        let secs = |frame: u32| self.time_of(frame);
        let events = qc
            .events
            .iter()
            .map(|e| {
                let ev = PyDict::new(py);
                ev.set_item("kind", &e.kind)?;
                ev.set_item("markers", &e.markers)?;
                ev.set_item("first_frame", e.first_frame)?;
                ev.set_item("last_frame", e.last_frame)?;
                ev.set_item("first_time", secs(e.first_frame))?;
                ev.set_item("last_time", secs(e.last_frame))?;
                ev.set_item("detected_frames", e.detected_frames)?;
                ev.set_item("action", &e.action)?;
                ev.set_item("residual_before_mm", e.residual_before_mm)?;
                ev.set_item("residual_after_mm", e.residual_after_mm.is_finite().then_some(e.residual_after_mm))?;
                Ok(ev)
            })
            .collect::<PyResult<Vec<_>>>()?;
        d.set_item("events", events)?;
        Ok(Some(d))
    }

    /// The runs of unfittable frames, from `/smocap/unfittable` (an empty list for a trial
    /// without one): dicts (pandas-ready) with `first_frame`, `last_frame`, `first_time`,
    /// `last_time` (s, as in `q`'s index), `frames`, `peak_rmse_mm`, `limit_mm`, `markers`,
    /// `marker_error_mm`, `rigid_move_mm`, `cause` ("data" or "model") and `why`.
    #[getter]
    fn unfittable<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let secs = |frame: u32| self.time_of(frame);
        let runs = self.rec.unfittable.iter().flat_map(|u| &u.runs);
        runs.map(|r| {
            let d = PyDict::new(py);
            d.set_item("first_frame", r.first_frame)?;
            d.set_item("last_frame", r.last_frame)?;
            d.set_item("first_time", secs(r.first_frame))?;
            d.set_item("last_time", secs(r.last_frame))?;
            d.set_item("frames", r.frames)?;
            d.set_item("peak_rmse_mm", r.peak_rmse_mm)?;
            d.set_item("limit_mm", r.limit_mm)?;
            d.set_item("markers", &r.markers)?;
            d.set_item("marker_error_mm", &r.marker_error_mm)?;
            d.set_item("rigid_move_mm", r.rigid_move_mm)?;
            d.set_item("cause", &r.cause)?;
            d.set_item("why", &r.why)?;
            Ok(d)
        })
        .collect()
    }

    /// Writes the coordinates as OpenSim's `.mot`, as `smocap export --mot` does (the
    /// conversion's model gives the order and which coordinates are in degrees).
    fn to_mot(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| -> Result<(), smocap::archive::export::ExportError> {
            let model = conversion_model(&self.rec, &self.path)?;
            write_mot(&self.rec, &model, &path)
        })
        .map_err(to_py::<ArchiveError>)
    }

    /// The subject's body mesh posed at every frame, as `smocap export --mesh` poses it (shaped
    /// to the subject's calibrated stature, sex and mass): `(vertices, faces)`, vertices float32
    /// of shape (frames, V, 3) in the Z-up world (m), faces uint32 of shape (F, 3), counter-
    /// clockwise seen from outside.
    fn body<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let (v, faces, frames, nv) = py
            .detach(|| -> Result<_, String> {
                let take = smocap::render::Take::from_record(&self.rec, &self.path).map_err(|e| e.to_string())?;
                let asset = smocap::body::BodyAsset::shipped().map_err(|e| e.to_string())?;
                let sub =
                    smocap::body::SubjectBody { stature_m: self.rec.subject_stature_m, info: self.rec.subject_info };
                let (body, _) = take
                    .dress(&asset, &sub, &smocap::body::FitSettings::default())
                    .map_err(|e| format!("binding the body mesh to the trial's model: {e}"))?;
                let mut ws = smocap::body::PoseWorkspace::new(&take.model, &body);
                let nq = take.model.nq();
                let mut y = vec![0.0; take.model.ny()];
                y[nq..].copy_from_slice(&take.scales);
                let nv = body.binding.influences.len();
                let mut v: Vec<f32> = Vec::with_capacity(take.q.len() * nv * 3);
                for q in &take.q {
                    y[..nq].copy_from_slice(&q[..nq]);
                    body.pose(&take.model, &y, &mut ws);
                    v.extend(ws.vertices.iter().flatten());
                }
                let faces: Vec<u32> = body.triangles.iter().flatten().copied().collect();
                Ok((v, faces, take.q.len(), nv))
            })
            .map_err(PyErr::new::<ArchiveError, _>)?;
        let nf = faces.len() / 3;
        let v = PyArray1::from_vec(py, v).reshape([frames, nv, 3])?.into_any();
        let f = PyArray1::from_vec(py, faces).reshape([nf, 3])?.into_any();
        Ok((v, f))
    }

    /// Retargets the trial onto a humanoid robot as `smocap retarget` does (nothing is
    /// written): `(q, report)`. `q`: MuJoCo's `qpos` per frame, indexed by frame time (s, as in
    /// `q`'s index), columns `root_x`, `root_y`, `root_z` (m, Z-up world), `root_qw`, `root_qx`,
    /// `root_qy`, `root_qz` (the root's orientation), then one per robot joint (rad, MJCF order).
    /// `report`: the quality report (`<trial>.json` of `smocap retarget`). `robot`: a shipped
    /// robot (`"g1"`) or a mapping file; `mjcf`: the robot's MJCF when the mapping does not name
    /// it; `settings`: a TOML file of retargeting settings.
    #[pyo3(signature = (robot = "g1", mjcf = None, settings = None))]
    fn retarget<'py>(
        &self,
        py: Python<'py>,
        robot: &str,
        mjcf: Option<PathBuf>,
        settings: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        use smocap::cli::robot::RobotSetup;
        let done = py.detach(|| {
            let setup = RobotSetup::load(robot, mjcf.as_deref(), settings.as_deref())
                .map_err(|e| PyErr::new::<ModelError, _>(format!("{e:#}")))?;
            let take = smocap::render::Take::from_record(&self.rec, &self.path)
                .map_err(|e| PyErr::new::<ArchiveError, _>(e.to_string()))?;
            setup.retarget(&take).map_err(|e| PyErr::new::<SmocapError, _>(format!("{}: {e}", self.path.display())))
        })?;
        let m = &done.motion;
        let root = ["root_x", "root_y", "root_z", "root_qw", "root_qx", "root_qy", "root_qz"];
        let names: Vec<String> = root.iter().map(|s| s.to_string()).chain(m.joint_names.iter().cloned()).collect();
        let rows: Vec<f64> = m.qpos.iter().flatten().copied().collect();
        let q = crate::table(py, rows, names, self.time())?;
        q.getattr("attrs")?.set_item("report", crate::to_python(py, &done.report)?)?;
        Ok(q)
    }

    fn __len__(&self) -> usize {
        self.rec.frames.len()
    }

    fn __repr__(&self) -> String {
        format!("Trial({:?}: {} frames)", self.path.display().to_string(), self.rec.frames.len())
    }
}
