//! Everything that stays fixed while solving the trials of a subject.

use crate::io::mjcf::{self, MjcfError};
use crate::kinematics::assembly::Evaluator;
use crate::model::profile::{Profile, ProfileError};
use crate::model::proxy::{ProxyError, ProxyMap};
use crate::model::Model;
use crate::solve::SolverSettings;
use std::path::Path;

/// The shipped full-body model (MJCF) and its solver profile, embedded in the binary.
pub const SHIPPED_MODEL: &str = include_str!("../../models/fullbody.xml");
pub const SHIPPED_PROFILE: &str = include_str!("../../models/fullbody.toml");

/// Errors setting up a subject.
#[derive(Debug, thiserror::Error)]
pub enum ContextError {
    #[error(transparent)]
    Mjcf(#[from] MjcfError),
    #[error(transparent)]
    Osim(#[from] crate::io::osim::OsimError),
    #[error(transparent)]
    Profile(#[from] ProfileError),
    #[error("profile does not fit the model: {0}")]
    Proxy(#[from] ProxyError),
    #[error("profile {path}: {message}")]
    Settings { path: String, message: String },
    #[error("profile {path}: marker '{name}' is not in the model (it has: {valid})")]
    UnknownMarker { path: String, name: String, valid: String },
}

/// Model, proxy map, marker weights and settings of one subject.
#[derive(Clone, Debug)]
pub struct Context {
    pub model: Model,
    pub profile: Profile,
    pub proxy: ProxyMap,
    pub settings: SolverSettings,
    /// Weight of each model marker's squared error in motion frames (0 = excluded).
    pub marker_weights: Vec<f64>,
    /// Weight of each model marker in calibration on a static trial (by default the same as
    /// `marker_weights`; a Scale setup's marker placer tasks set their own).
    pub calibration_weights: Vec<f64>,
    /// Soft coordinate targets (OpenSim IK coordinate tasks): each frame's objective gains
    /// `½·w_j·(q_j − target_j)²` (rad or m) for every coordinate `j` with `w_j > 0`. Length nq.
    pub coordinate_weights: Vec<f64>,
    pub coordinate_targets: Vec<f64>,
    /// The posture of a static trial as a setup gives it: `(coordinate index, value rad or m,
    /// weight)` (an OpenSim Scale setup's `MarkerPlacer` coordinate tasks, `weight·(q − value)²`
    /// in the static frames, as OpenSim solves the static pose); other coordinates are held by
    /// the static posture prior.
    pub static_posture_values: Vec<(usize, f64, f64)>,
    /// The model's up direction in its world frame (opposite to its gravity); `None` when the
    /// model has no gravity.
    pub up: Option<nalgebra::Vector3<f64>>,
    /// What is known of the subject (sex, height, mass): conditions the anthropometric prior.
    pub subject: crate::model::anthropometry::SubjectInfo,
    /// The landmark definitions that measure the prior's dimensions on this model, with their
    /// source; `None` when no shipped file fits the model and none was given.
    pub landmarks: Option<(String, crate::model::anthropometry::Landmarks)>,
    /// Whether calibration runs on a static trial (else on frames of the motion trials).
    pub static_calibration: bool,
    /// Where the model and profile came from (for reports).
    pub model_source: String,
    /// What the model importer ignored or approximated.
    pub warnings: Vec<String>,
}

impl Context {
    /// Builds a context; `profile_name` is used in error messages. The model's up direction is
    /// taken as +Z (MJCF's default gravity); readers of model files set it from the file.
    pub fn new(
        model: Model,
        profile: Profile,
        profile_name: &str,
        model_source: String,
    ) -> Result<Context, ContextError> {
        let proxy = ProxyMap::new(&model, &profile)?;
        let mut settings = SolverSettings::from_table(&profile.solver)
            .map_err(|message| ContextError::Settings { path: profile_name.into(), message })?;
        settings.qp = crate::solve::backend_for(settings.qp, &proxy);
        let valid = || model.markers.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join(", ");
        for (name, &w) in &profile.markers.weights {
            if !w.is_finite() || w < 0.0 {
                return Err(ContextError::Settings {
                    path: profile_name.into(),
                    message: format!("marker weight {name} = {w}: weights must be finite and ≥ 0"),
                });
            }
        }
        if let Some(w) = profile.markers.default_weight.filter(|w| !w.is_finite() || *w < 0.0) {
            return Err(ContextError::Settings {
                path: profile_name.into(),
                message: format!("default_weight = {w}: weights must be finite and ≥ 0"),
            });
        }
        let m = &profile.markers;
        for name in m.weights.keys().chain(&m.exclude).chain(&m.tracking).chain(&m.anatomical) {
            if model.marker_index(name).is_none() {
                return Err(ContextError::UnknownMarker {
                    path: profile_name.into(),
                    name: name.clone(),
                    valid: valid(),
                });
            }
        }
        let marker_weights: Vec<f64> = model
            .markers
            .iter()
            .map(|m| {
                if profile.markers.exclude.contains(&m.name) {
                    0.0
                } else {
                    profile.markers.weights.get(&m.name).copied().or(profile.markers.default_weight).unwrap_or(m.weight)
                }
            })
            .collect();
        let nq = model.nq();
        let landmarks = crate::model::anthropometry::Landmarks::shipped_for(&model);
        Ok(Context {
            subject: Default::default(),
            landmarks,
            static_calibration: false,
            model,
            profile,
            proxy,
            settings,
            calibration_weights: marker_weights.clone(),
            marker_weights,
            coordinate_weights: vec![0.0; nq],
            coordinate_targets: vec![0.0; nq],
            static_posture_values: Vec::new(),
            up: Some(nalgebra::Vector3::z()),
            model_source,
            warnings: Vec::new(),
        })
    }

    /// The shipped full-body model with its profile.
    pub fn shipped() -> Result<Context, ContextError> {
        let model = mjcf::parse_mjcf(SHIPPED_MODEL, "models/fullbody.xml")?;
        let profile = Profile::parse(SHIPPED_PROFILE, Path::new("models/fullbody.toml"))?;
        let mut ctx = Context::new(model, profile, "models/fullbody.toml", "shipped:models/fullbody.xml".into())?;
        ctx.up = crate::io::gravity::model_up(SHIPPED_MODEL, false);
        Ok(ctx)
    }

    /// A model file (MJCF) with an optional profile file (default: every coordinate free,
    /// every body its own uniform scale).
    pub fn from_files(model_path: &Path, profile_path: Option<&Path>) -> Result<Context, ContextError> {
        Context::from_files_with_markers(model_path, None, profile_path)
    }

    /// A model file (`.osim` for OpenSim, anything else MJCF), optionally with an OpenSim marker
    /// set file attached, and an optional profile file.
    pub fn from_files_with_markers(
        model_path: &Path,
        marker_set: Option<&Path>,
        profile_path: Option<&Path>,
    ) -> Result<Context, ContextError> {
        let is_osim = model_path.extension().is_some_and(|e| e.eq_ignore_ascii_case("osim"));
        let (mut model, warnings) =
            if is_osim { crate::io::osim::read_osim(model_path)? } else { mjcf::read_mjcf(model_path)? };
        if let Some(ms) = marker_set {
            let markers = crate::io::osim::read_marker_set(ms, &model)?;
            model = model
                .with_markers(markers)
                .map_err(|e| ContextError::Settings { path: ms.display().to_string(), message: e.to_string() })?;
        }
        let (profile, name) = match profile_path {
            Some(p) => (Profile::read(p)?, p.display().to_string()),
            None => (Profile::default_for(&model), "<default profile>".to_string()),
        };
        let mut ctx = Context::new(model, profile, &name, model_path.display().to_string())?;
        ctx.warnings = warnings;
        // The file was read once already, so a failure here is as unlikely as harmless.
        ctx.up = std::fs::read_to_string(model_path).ok().and_then(|t| crate::io::gravity::model_up(&t, is_osim));
        Ok(ctx)
    }

    /// The same subject with its markers at `offsets` (unit-scale, body frame, m), e.g. after
    /// marker placement ([`crate::solve::Calibration::marker_offsets`]).
    pub fn with_marker_offsets(&self, offsets: &[nalgebra::Vector3<f64>]) -> Result<Context, ContextError> {
        let mut model = self.model.clone();
        for (m, o) in model.markers.iter_mut().zip(offsets) {
            m.offset = *o;
        }
        let proxy = ProxyMap::new(&model, &self.profile)?;
        Ok(Context { model, proxy, ..self.clone() })
    }

    /// The same subject with the joints of `moves` at their new locations (calibration's
    /// functional hips, [`crate::solve::Calibration::joint_moves`]; applying them again changes
    /// nothing).
    pub fn with_joint_moves(&self, moves: &[crate::solve::prior::JointMove]) -> Context {
        if moves.is_empty() {
            return self.clone();
        }
        Context { model: with_joint_moves(&self.model, moves), ..self.clone() }
    }

    /// The subject as its trials are solved: the calibration's morphology (scale proxies pinned
    /// to their calibrated values, so every frame of every trial has the one morphology, and
    /// the hip joints where calibration moved them) and its markers where calibration
    /// registered or placed them.
    pub fn pinned_to(&self, cal: &crate::solve::Calibration) -> Context {
        let mut ctx = self.with_joint_moves(&cal.joint_moves);
        if let Some(o) = &cal.marker_offsets {
            for (m, o) in ctx.model.markers.iter_mut().zip(o) {
                m.offset = *o;
            }
        }
        for (px, &v) in ctx.proxy.proxies.iter_mut().zip(&cal.proxies) {
            if px.kind == crate::model::proxy::ProxyKind::Scale {
                px.range = (v, v);
            }
        }
        ctx
    }

    /// The subject set up as an OpenSim Scale tool setup says: its scale groups replace the
    /// profile's, marker placement follows its `MarkerPlacer`, and the placer's task weights
    /// weight the static trial (markers without a task keep their weight). Bodies the model
    /// lacks are skipped with a warning (in `warnings`), as OpenSim's ScaleTool does.
    pub fn with_scale_setup(
        &self,
        setup: &crate::io::osim::ScaleSetup,
        setup_name: &str,
    ) -> Result<Context, ContextError> {
        let mut profile = self.profile.clone();
        let mut warnings = self.warnings.clone();
        if !setup.scale_groups.is_empty() {
            // Like OpenSim's ScaleTool, bodies the model lacks are skipped (with a warning).
            let mut groups = setup.scale_groups.clone();
            let mut missing = Vec::new();
            for g in &mut groups {
                g.bodies.retain(|b| {
                    let known = self.model.body_index(b).is_some();
                    if !known {
                        missing.push(b.clone());
                    }
                    known
                });
            }
            groups.retain(|g| !g.bodies.is_empty());
            if !missing.is_empty() {
                warnings.push(format!(
                    "{setup_name}: scale set names bodies the model lacks, skipped: {}",
                    missing.join(", ")
                ));
            }
            profile.scale_groups = groups;
        }
        let proxy = ProxyMap::new(&self.model, &profile)
            .map_err(|e| ContextError::Settings { path: setup_name.into(), message: e.to_string() })?;
        let mut settings = self.settings.clone();
        settings.marker_placement = setup.place_markers;
        // The setup's MarkerPlacer decides what happens to the markers, not registration.
        settings.registration = false;
        settings.qp = crate::solve::backend_for(settings.qp, &proxy);
        let calibration_weights = self
            .model
            .markers
            .iter()
            .zip(&self.calibration_weights)
            .map(|(m, &w)| setup.static_weights.get(&m.name).copied().unwrap_or(w))
            .collect();
        let mut static_posture_values = Vec::new();
        for t in &setup.static_coordinate_tasks {
            let Some(j) = self.model.coordinate_index(&t.name) else {
                warnings.push(format!(
                    "{setup_name}: line {}: coordinate task for '{}', which the model lacks; skipped",
                    t.line, t.name
                ));
                continue;
            };
            let value = match t.value {
                crate::io::osim::CoordinateValue::Default => self.model.coordinates[j].default,
                crate::io::osim::CoordinateValue::Manual(v) => v,
                crate::io::osim::CoordinateValue::FromFile => {
                    warnings.push(format!("{setup_name}: line {}: coordinate task '{}' takes its value from a file, which smocap does not read; the static posture prior holds it instead", t.line, t.name));
                    continue;
                }
            };
            static_posture_values.push((j, value, t.weight));
        }
        let mut subject = self.subject;
        subject.height_m = subject.height_m.or(setup.height_m);
        subject.mass_kg = subject.mass_kg.or(setup.mass_kg);
        Ok(Context {
            profile,
            proxy,
            settings,
            calibration_weights,
            warnings,
            subject,
            static_posture_values,
            ..self.clone()
        })
    }

    /// Tracking arrays (length ny) holding only the coordinate targets: `(reference, weights)`.
    pub fn coordinate_tracking(&self) -> (Vec<f64>, Vec<f64>) {
        let ny = self.model.ny();
        let (mut r, mut w) = (self.coordinate_targets.clone(), self.coordinate_weights.clone());
        r.resize(ny, 0.0);
        w.resize(ny, 0.0);
        (r, w)
    }

    /// Each marker's registration class ([`crate::model::marker_classes`]).
    pub fn marker_classes(&self) -> Vec<crate::model::MarkerClass> {
        crate::model::marker_classes(&self.model, &self.profile.markers.tracking, &self.profile.markers.anatomical)
    }

    /// Evaluator over this context's model and proxy map.
    pub fn evaluator(&self) -> Evaluator<'_> {
        Evaluator::new(&self.model, &self.proxy)
    }
}

/// `model` with the joints of `moves` at their new locations.
pub fn with_joint_moves(model: &Model, moves: &[crate::solve::prior::JointMove]) -> Model {
    let mut m = model.clone();
    for mv in moves {
        if let Some(b) = m.body_index(&mv.body) {
            m.bodies[b].joint.parent_offset.translation.vector = nalgebra::Vector3::from(mv.location_m);
        }
    }
    m
}
