//! The body of a known subject: the shape chosen from the subject's stature, sex and mass, and
//! its height against the stature.
//!
//! `gender` comes from sex (0.5 unknown); where the stature is known the mesh's `height` gives
//! that stature (else [`Dressed::new`] sizes it from the scales); where the mass is known too,
//! `weight` is chosen so that the shaped mesh's enclosed volume times [`BODY_DENSITY`] is the
//! mass (about BMI: the volume at a given stature grows with `weight`). The shape is chosen
//! before binding; the subject's scales then stretch it per segment, which is why the stature
//! is asked of the bound body at those scales (two rounds in [`Dressed::new`]).

use super::asset::{BodyAsset, Phenotype};
use super::fit::{fit_to_markers, FitSettings};
use super::metrics::volume;
use super::pose::{phenotype_for, Dressed, PoseWorkspace};
use super::segments::BindError;
use crate::model::anthropometry::SubjectInfo;
use crate::model::Model;
use nalgebra::UnitQuaternion;

/// Whole-body density (kg/m³) turning the mesh's volume into mass: 1010, between the
/// densities measured by underwater weighing with the lungs' residual air (about 1000–1070).
pub const BODY_DENSITY: f64 = 1010.0;

/// What is known of the subject for its body.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SubjectBody {
    /// The calibrated stature (m; `Calibration.prior.stature_m`), else the given height.
    pub stature_m: Option<f64>,
    pub info: SubjectInfo,
}

impl SubjectBody {
    /// The stature the body is shaped to: the calibrated one, else the subject's given height.
    pub fn stature(&self) -> Option<f64> {
        self.stature_m.or(self.info.height_m)
    }
}

/// Mass (kg) of the dressed body at its bind pose and `scales`, at [`BODY_DENSITY`].
pub fn posed_mass(model: &Model, body: &Dressed, scales: &[f64]) -> f64 {
    let mut ws = PoseWorkspace::new(model, body);
    body.pose(model, &body.bind_state(model, scales), &mut ws);
    volume(&ws.vertices, &body.triangles) * BODY_DENSITY
}

/// Mass (kg) of a shape at [`BODY_DENSITY`].
pub fn shape_mass(asset: &BodyAsset, p: &Phenotype) -> f64 {
    let s = asset.shape_from(p);
    let v: Vec<[f32; 3]> = s.vertices.iter().map(|v| [v.x as f32, v.y as f32, v.z as f32]).collect();
    volume(&v, &asset.triangles) * BODY_DENSITY
}

/// The phenotype of a subject: `gender` from sex; with stature and mass, the `weight` whose shape
/// at that stature has that mass (clamped to [0, 1]); `height` is left for [`Dressed::new`].
pub fn phenotype_for_subject(asset: &BodyAsset, sub: &SubjectBody) -> Phenotype {
    let base = phenotype_for(sub.info.sex);
    let (Some(h), Some(m)) = (sub.stature(), sub.info.mass_kg) else { return base };
    let mass_at = |w: f64| {
        let p = Phenotype { weight: w, ..base };
        asset.height_for_stature(&p, h).ok().map(|p| shape_mass(asset, &p))
    };
    let (Some(lo_m), Some(hi_m)) = (mass_at(0.0), mass_at(1.0)) else { return base };
    let weight = if m <= lo_m {
        0.0
    } else if m >= hi_m {
        1.0
    } else {
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..14 {
            let mid = 0.5 * (lo + hi);
            match mass_at(mid) {
                Some(x) if x < m => lo = mid,
                _ => hi = mid,
            }
        }
        0.5 * (lo + hi)
    };
    Phenotype { weight, ..base }
}

/// The subject's body on `model` at `scales`, and a one-line summary of its height against
/// the stature it was shaped to ([`dress_subject_with`] the default [`FitSettings`]).
pub fn dress_subject(
    model: &Model,
    world_from_model: &UnitQuaternion<f64>,
    asset: &BodyAsset,
    scales: &[f64],
    sub: &SubjectBody,
) -> Result<(Dressed, String), BindError> {
    dress_subject_with(model, world_from_model, asset, scales, sub, &[], &FitSettings::default())
}

/// The subject's body: the phenotype from stature, sex and mass, bound to `model`, then shaped
/// to the model's markers and the stature ([`fit_to_markers`], at the bind pose and `poses`:
/// coordinates `q` of some of the trial's frames, see [`fit_poses`]) with `fit`.
pub fn dress_subject_with(
    model: &Model,
    world_from_model: &UnitQuaternion<f64>,
    asset: &BodyAsset,
    scales: &[f64],
    sub: &SubjectBody,
    poses: &[&[f64]],
    fit: &FitSettings,
) -> Result<(Dressed, String), BindError> {
    let p = phenotype_for_subject(asset, sub);
    let mut body = Dressed::new(model, world_from_model, asset, scales, sub.stature(), p)?;
    let mut mass = posed_mass(model, &body, scales);
    // the subject's scales stretch the shape, so its mass is off the phenotype's; the fit below
    // matches the volume to the mass itself
    if scales.len() == 3 * model.nb() {
        let stature = sub.stature().unwrap_or(body.target_stature);
        let volume = sub.info.mass_kg.map(|m| m / BODY_DENSITY);
        body.fit = Some(fit_to_markers(model, &mut body, asset, scales, Some(stature), volume, poses, fit));
        mass = posed_mass(model, &body, scales);
        body.correctives = super::correctives::build(model, &body, asset, scales);
    }
    let height = body.bind_pose_height(model, scales);
    let what = match (sub.stature_m, sub.info.height_m) {
        (Some(_), _) => "calibrated stature",
        (None, Some(_)) => "given height",
        (None, None) => "stature of the mesh at the scales",
    };
    let mut line = format!(
        "body: height {height:.4} m at the subject's scales, {what} {:.4} m ({:+.1} mm); gender {:.2}, weight {:.3}, height {:.3}",
        body.target_stature,
        1e3 * (height - body.target_stature),
        p.gender,
        body.phenotype.weight,
        body.phenotype.height
    );
    line += &format!("; mass of the body {mass:.1} kg at {BODY_DENSITY} kg/m³");
    if let Some(m) = sub.info.mass_kg {
        line += &format!(" (subject {m:.1} kg)");
    }
    if let (Some(c), Some(g)) = (sub.stature_m, sub.info.height_m) {
        line += &format!("; given height {g:.3} m ({:+.1} mm from the calibrated)", 1e3 * (g - c));
    }
    if let Some(f) = &body.fit {
        line += &format!(
            "; shaped to {} markers: landmarks' median |d − {:.0} mm| {:.1} → {:.1} mm at the bind pose",
            f.markers_used,
            fit.marker_radius_m * 1e3,
            f.landmark_median_before_m * 1e3,
            f.landmark_median_after_m * 1e3
        );
    }
    Ok((body, line))
}

/// Up to `n` of `frames` (each the model's coordinates `q`), evenly spaced, first and last
/// included: the poses the skin is fitted at.
pub fn fit_poses(frames: &[Vec<f64>], n: usize) -> Vec<&[f64]> {
    match frames.len() {
        0 => Vec::new(),
        len if len <= n => frames.iter().map(|q| q.as_slice()).collect(),
        len => (0..n).map(|i| frames[i * (len - 1) / (n - 1).max(1)].as_slice()).collect(),
    }
}
