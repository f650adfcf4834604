//! Results out to OpenSim, so its users continue where smocap stops: a solved trial's coordinates
//! as a `.mot` motion, and the calibrated subject as a scaled `.osim` model (plus its scale set).

use crate::pipeline::context::Context;

use crate::io::osim::{self, MassScaling, OsimError, OsimWriteError};
use crate::io::sto::{self, StoError, Table};
use crate::io::MarkerTrial;
use crate::model::{Function, Model, MotionKind};
use crate::pipeline::running::trial::TrialResult;
use crate::solve::Calibration;
use nalgebra::Vector3;
use std::path::Path;

/// Errors writing results.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Sto(#[from] StoError),
    #[error(transparent)]
    Osim(#[from] OsimError),
    #[error(transparent)]
    OsimWrite(#[from] OsimWriteError),
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{frames} frames of proxies but {times} frame times")]
    Frames { frames: usize, times: usize },
    #[error("{proxies} proxies per frame for a proxy map of {expected}")]
    Proxies { proxies: usize, expected: usize },
}

/// For each coordinate, whether OpenSim gives it in degrees in a `.mot` with `inDegrees=yes`:
/// its motion type is rotational, i.e. it drives a rotation through a `LinearFunction` of slope
/// ±1 and no translation so (OpenSim `CustomJoint::constructCoordinates`; other joint types and
/// MJCF hinges are pure). Coupled coordinates (driven only through other functions, e.g. the
/// Rajagopal knee's `knee_angle_r_beta`) stay in radians, as OpenSim's IK writes them.
pub fn opensim_degrees(model: &Model) -> Vec<bool> {
    let mut pure_rot = vec![false; model.nq()];
    let mut pure_trans = vec![false; model.nq()];
    for m in &model.motions {
        if let (Some(c), Function::Linear { slope, .. }) = (m.coordinate, &m.func) {
            if slope.abs() == 1.0 {
                match m.kind {
                    MotionKind::Rotation => pure_rot[c] = true,
                    MotionKind::Translation => pure_trans[c] = true,
                }
            }
        }
    }
    pure_rot.iter().zip(&pure_trans).map(|(r, t)| *r && !t).collect()
}

/// Frames of a trial as an OpenSim motion: `time` (s, one per frame), then every model
/// coordinate in model order (locked and coupled ones too, through the proxy map) from each
/// frame's proxies, rotations in degrees ([`opensim_degrees`]), translations in metres;
/// `inDegrees=yes`.
pub fn motion_table(ctx: &Context, proxies: &[Vec<f64>], times: &[f64]) -> Result<Table, ExportError> {
    if proxies.len() != times.len() {
        return Err(ExportError::Frames { frames: proxies.len(), times: times.len() });
    }
    let q = coordinates(ctx, proxies)?;
    Ok(coordinate_table(&ctx.model, times.iter().copied().zip(q)))
}

/// Every model coordinate (model order, locked and coupled ones too, rad or m) of each frame's
/// proxies, through the proxy map: the numbers a motion ([`motion_table`]) holds, before degrees.
pub fn coordinates(ctx: &Context, proxies: &[Vec<f64>]) -> Result<Vec<Vec<f64>>, ExportError> {
    let np = ctx.proxy.np();
    if let Some(p) = proxies.iter().find(|p| p.len() != np) {
        return Err(ExportError::Proxies { proxies: p.len(), expected: np });
    }
    let model = &ctx.model;
    let (mut y, mut dphi) = (vec![0.0; model.ny()], vec![0.0; ctx.proxy.terms.len()]);
    Ok(proxies
        .iter()
        .map(|p| {
            ctx.proxy.apply(p, &mut y, &mut dphi);
            y[..model.nq()].to_vec()
        })
        .collect())
}

/// An OpenSim motion from `(time s, coordinates in model order, rad or m)` per frame: `time`,
/// then every coordinate, rotations in degrees ([`opensim_degrees`]); `inDegrees=yes`.
pub fn coordinate_table(model: &Model, frames: impl IntoIterator<Item = (f64, Vec<f64>)>) -> Table {
    let deg = opensim_degrees(model);
    let mut columns = vec!["time".to_string()];
    columns.extend(model.coordinates.iter().map(|c| c.name.clone()));
    let mut rows = Vec::new();
    for (t, q) in frames {
        let mut row = Vec::with_capacity(columns.len());
        row.push(t);
        row.extend(q.iter().zip(&deg).map(|(&v, &d)| if d { v.to_degrees() } else { v }));
        rows.push(row);
    }
    Table { header: vec![("inDegrees".into(), "yes".into())], columns, rows }
}

/// Writes every frame of a solved trial (bridged frames included) at the trial's frame times
/// to `path` as an OpenSim motion ([`motion_table`]; OpenSim 4 storage format, named
/// `Coordinates` as OpenSim's inverse kinematics names it).
pub fn write_mot(ctx: &Context, result: &TrialResult, trial: &MarkerTrial, path: &Path) -> Result<(), ExportError> {
    Ok(sto::write_sto(path, "Coordinates", &motion_table(ctx, &result.proxies, &trial.times)?)?)
}

/// The calibrated scale factors `(x, y, z)` of every body.
pub fn body_scales(ctx: &Context, calibration: &Calibration) -> Result<Vec<Vector3<f64>>, ExportError> {
    if calibration.proxies.len() != ctx.proxy.np() {
        return Err(ExportError::Proxies { proxies: calibration.proxies.len(), expected: ctx.proxy.np() });
    }
    let y = ctx.proxy.state(&calibration.proxies);
    let m = &ctx.model;
    Ok((0..m.nb()).map(|b| Vector3::from_fn(|k, _| y[m.scale_index(b, k)])).collect())
}

/// The calibrated subject as OpenSim 4 `.osim` text, with warnings. `source` is the `.osim`
/// text the model was read from and its file name: it is rewritten with the scale factors as
/// OpenSim's ScaleTool would ([`osim::scale_osim`], keeping muscles and geometry; markers are the
/// context's, e.g. from a marker-set file). Without it (a model from MJCF) the model is
/// generated ([`osim::format_osim`]).
pub fn scaled_osim(
    ctx: &Context,
    calibration: &Calibration,
    source: Option<(&str, &str)>,
    mass: MassScaling,
) -> Result<(String, Vec<String>), ExportError> {
    let scales = body_scales(ctx, calibration)?;
    Ok(match source {
        Some((text, file)) => osim::scale_osim(text, file, &ctx.model, &scales, mass)?,
        None => osim::format_osim(&ctx.model, &scales)?,
    })
}

/// Writes the calibrated subject to `out` ([`scaled_osim`]; `model_file` is the file the model
/// came from: an `.osim` one is rewritten, otherwise the model is generated), and its scale set
/// (OpenSim `ScaleSet`, for OpenSim's ScaleTool) beside it as `<out stem>.scaleset.xml`. Returns
/// the warnings and the scale set's path.
pub fn write_scaled_model(
    ctx: &Context,
    calibration: &Calibration,
    model_file: Option<&Path>,
    out: &Path,
) -> Result<(Vec<String>, std::path::PathBuf), ExportError> {
    let io = |p: &Path| {
        let file = p.display().to_string();
        move |source| ExportError::Io { file, source }
    };
    let osim_file = model_file.filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("osim")));
    let text = osim_file.map(|p| std::fs::read_to_string(p).map_err(io(p))).transpose()?;
    let name = osim_file.map(|p| p.display().to_string()).unwrap_or_default();
    let source = text.as_deref().map(|t| (t, name.as_str()));
    let mass = MassScaling { subject_mass: ctx.subject.mass_kg, ..MassScaling::default() };
    let (osim_text, warnings) = scaled_osim(ctx, calibration, source, mass)?;
    std::fs::write(out, osim_text).map_err(io(out))?;
    let set_path = out.with_extension("scaleset.xml");
    let set = osim::format_scale_set(&ctx.model, &body_scales(ctx, calibration)?);
    std::fs::write(&set_path, set).map_err(io(&set_path))?;
    Ok((warnings, set_path))
}
