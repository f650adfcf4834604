//! Setting up one subject from its files, shared by `smocap solve` and `smocap convert`: the model
//! (with marker set, profile, OpenSim Scale and IK setups), the static trial, reading trials into the
//! model's conventions, and calibrating once (with marker placement when asked).

use crate::io::{MarkerFileError, MarkerTrial};
use crate::pipeline::calibration::calibrate::calibrate_subject;
use crate::pipeline::context::Context;
use crate::pipeline::context::ContextError;
use crate::pipeline::input::convention::{conform_trial, InputConventions, InputOptions};
use crate::pipeline::input::trial::TrialError;
use crate::solve::{Calibration, QpBackend};
use std::path::{Path, PathBuf};

/// Errors setting up a subject.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    #[error(transparent)]
    Context(#[from] ContextError),
    #[error(transparent)]
    Osim(#[from] crate::io::osim::OsimError),
    #[error("the scale setup's static trial {path} does not exist; give the static trial with --static")]
    StaticMissing { path: String },
    #[error("a marker set ({path}) needs a model file")]
    MarkerSetWithoutModel { path: String },
    #[error(transparent)]
    Calibration(#[from] TrialError),
}

/// The files that describe a subject (all optional: the shipped model and its profile by default).
#[derive(Clone, Debug, Default)]
pub struct SubjectFiles {
    /// Model: OpenSim `.osim` or MJCF.
    pub model: Option<PathBuf>,
    /// OpenSim marker set file attached to the model.
    pub markerset: Option<PathBuf>,
    /// Solver profile (TOML).
    pub profile: Option<PathBuf>,
    /// OpenSim Scale tool setup (scale groups, marker placement, static weights, marker set and
    /// static trial when those are not given).
    pub scale_setup: Option<PathBuf>,
    /// OpenSim IK setup (marker and coordinate tasks).
    pub ik_setup: Option<PathBuf>,
    /// Static calibration trial; without one, frames of the motion trials are used.
    pub static_trial: Option<PathBuf>,
    /// Place the markers on the static trial after calibration.
    pub place_markers: bool,
    /// Keep the model's marker positions (no registration).
    pub no_register: bool,
    /// What is known of the subject (conditions the anthropometric prior; a Scale setup's
    /// height and mass fill what is not given).
    pub subject: crate::model::anthropometry::SubjectInfo,
    pub qp: Option<QpBackend>,
}

/// A subject ready to calibrate: its context, its static trial, and what was noticed on the way
/// (lines for stderr, e.g. `warning: ...`).
pub struct Subject {
    pub ctx: Context,
    pub static_path: Option<PathBuf>,
    pub notes: Vec<String>,
}

/// Loads the model named by `model` (the shipped model by default), attaching an OpenSim marker
/// set when given, with `profile` (the model's default profile when absent). Importer warnings
/// are in the context's `warnings`.
pub fn load_context(
    model: Option<&Path>,
    marker_set: Option<&Path>,
    profile: Option<&Path>,
) -> Result<Context, SetupError> {
    Ok(match (model, marker_set) {
        (None, Some(ms)) => return Err(SetupError::MarkerSetWithoutModel { path: ms.display().to_string() }),
        (None, None) if profile.is_none() => Context::shipped()?,
        (None, None) => {
            let m = crate::io::mjcf::parse_mjcf(crate::pipeline::context::SHIPPED_MODEL, "models/fullbody.xml")
                .map_err(ContextError::from)?;
            let path = profile.unwrap_or(Path::new(""));
            let prof = crate::model::profile::Profile::read(path).map_err(ContextError::from)?;
            Context::new(m, prof, &path.display().to_string(), "shipped:models/fullbody.xml".into())?
        }
        (Some(m), _) => Context::from_files_with_markers(m, marker_set, profile)?,
    })
}

/// Sets a subject up as `f` says, in the order `smocap solve` documents: model and marker set,
/// Scale setup, marker placement, QP backend, IK setup; without a static trial, calibration
/// weights are the motion weights.
pub fn prepare_subject(f: &SubjectFiles) -> Result<Subject, SetupError> {
    prepare_subject_with(f, false)
}

/// [`prepare_subject`], with `static_given` saying that the static trial is given otherwise than
/// as a file (e.g. in memory): the subject is then set up for a static calibration, and neither
/// `f.static_trial` nor the Scale setup's static file is looked at (`static_path` is `None`).
pub fn prepare_subject_with(f: &SubjectFiles, static_given: bool) -> Result<Subject, SetupError> {
    let mut notes = Vec::new();
    let setup = f.scale_setup.as_deref().map(crate::io::osim::read_scale_setup).transpose()?;
    let markerset = f.markerset.clone().or_else(|| setup.as_ref().and_then(|s| s.marker_set_file.clone()));
    let static_path = match (&f.static_trial, setup.as_ref().and_then(|s| s.static_file.clone())) {
        _ if static_given => None,
        (Some(p), _) => Some(p.clone()),
        (None, Some(p)) if p.exists() => Some(p),
        (None, Some(p)) => return Err(SetupError::StaticMissing { path: p.display().to_string() }),
        (None, None) => None,
    };
    let has_static = static_path.is_some() || static_given;
    f.subject.validate().map_err(TrialError::from)?;
    let mut ctx = load_context(f.model.as_deref(), markerset.as_deref(), f.profile.as_deref())?;
    ctx.subject = f.subject;
    ctx.static_calibration = has_static;
    if f.model.is_some() {
        notes.extend(ctx.warnings.iter().map(|w| format!("warning: {w}")));
    }
    if let (Some(s), Some(p)) = (&setup, &f.scale_setup) {
        let before = ctx.warnings.len();
        ctx = ctx.with_scale_setup(s, &p.display().to_string())?;
        notes.extend(ctx.warnings[before..].iter().map(|w| format!("warning: {w}")));
    }
    if f.place_markers {
        ctx.settings.marker_placement = true;
    }
    if f.no_register {
        ctx.settings.registration = false;
    }
    if let Some(qp) = f.qp {
        ctx.settings.qp = crate::solve::backend_for(qp, &ctx.proxy);
        if ctx.settings.qp != qp {
            notes.push(
                "note: the profile has general linear constraints, which only the clarabel QP backend solves".into(),
            );
        }
    }
    if let Some(p) = &f.ik_setup {
        let setup = crate::io::osim::read_ik_setup(p)?;
        let done = ctx.apply_ik_setup(&setup)?;
        notes.extend(setup.warnings.iter().chain(&done.warnings).map(|w| format!("warning: {w}")));
        notes.push(format!(
            "{}: {} markers weighted, {} without a task (unused, as in OpenSim), {} coordinate targets; its time range and files are not used",
            p.display(),
            done.markers_weighted,
            done.markers_without_task.len(),
            done.coordinate_targets
        ));
    }
    // Without a static trial, calibration runs on the motion frames with the motion weights.
    if !has_static {
        ctx.calibration_weights = ctx.marker_weights.clone();
    }
    Ok(Subject { ctx, static_path, notes })
}

/// Reads a marker file and brings it into the model's units and up axis.
pub fn read_trial(
    ctx: &Context,
    path: &Path,
    opt: &InputOptions,
) -> Result<(MarkerTrial, InputConventions), MarkerFileError> {
    let mut t = crate::io::read_markers(path)?;
    let conv = conform_trial(ctx, &mut t, opt);
    Ok((t, conv))
}

/// Calibrates the subject once from `inputs` (its static trial, or its motion trials); when marker
/// placement moved the markers, also returns the context with the markers placed, which the
/// trials are then solved with.
pub fn calibrate_placed(
    ctx: &Context,
    inputs: &[(&str, &MarkerTrial)],
) -> Result<(Calibration, Option<Context>), SetupError> {
    let c = calibrate_subject(ctx, inputs)?;
    let placed = placed_context(ctx, &c)?;
    Ok((c, placed))
}

/// The context with the markers where calibration `c` placed them (and its hips moved with them),
/// when marker placement moved any.
fn placed_context(ctx: &Context, c: &Calibration) -> Result<Option<Context>, SetupError> {
    Ok(c.marker_offsets
        .as_ref()
        .map(|o| ctx.with_marker_offsets(o))
        .transpose()?
        .map(|p| p.with_joint_moves(&c.joint_moves)))
}

/// [`calibrate_placed`] on the subject's static trials and motion trials together
/// ([`crate::pipeline::calibration::calibrate::calibrate_subject_with`]).
pub fn calibrate_placed_with<T: crate::pipeline::input::frames::TrialFrames + ?Sized>(
    ctx: &Context,
    statics: &[(&str, &T)],
    motions: &[(&str, &T)],
) -> Result<(Calibration, Option<Context>), SetupError> {
    let c = crate::pipeline::calibration::calibrate::calibrate_subject_with(ctx, statics, motions)?;
    let placed = placed_context(ctx, &c)?;
    Ok((c, placed))
}
