//! A solved trial as the renderers see it: the subject's model at its calibrated scales, its
//! coordinates per frame and the observed markers, from a converted MCAP file or from `solve`.
//!
//! Frames: the model's own frame (`model`, as the solver works in it) and the Z-up `world` of
//! the MCAP `/tf` tree, `world_from_model` apart. Everything the renderers use is in `world`
//! (metres); times are seconds since the trial's first sample.

use super::RenderError;
use crate::archive::export::{conversion_model, TrialRecord};
use crate::kinematics::cpu::{self, Workspace};
use crate::model::Model;
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use std::path::Path;

/// A solved trial ready to render.
#[derive(Clone, Debug)]
pub struct Take {
    /// The trial's name (the MCAP file's stem, or the trial's).
    pub name: String,
    /// The model whose forward kinematics place bodies and markers.
    pub model: Model,
    /// Scale factors, `3·body + axis`, the same in every frame (the calibrated morphology).
    pub scales: Vec<f64>,
    /// Frame times (s since the trial's first sample), strictly increasing.
    pub times: Vec<f64>,
    /// Frame index in the trial of each frame.
    pub frames: Vec<usize>,
    /// Coordinates per frame, in model order (rad or m).
    pub q: Vec<Vec<f64>>,
    /// Observed markers per frame, per model marker (`model` frame, m); `None` where not observed.
    pub observed: Vec<Vec<Option<Vector3<f64>>>>,
    /// The rotation from `model` to the Z-up `world`.
    pub world_from_model: UnitQuaternion<f64>,
}

/// Bodies, markers and joint centres of one frame in `world` (m).
#[derive(Clone, Debug)]
pub struct Pose {
    /// Orientation and origin of each body.
    pub body_rot: Vec<Matrix3<f64>>,
    pub body_pos: Vec<Vector3<f64>>,
    /// Each model marker.
    pub markers: Vec<Vector3<f64>>,
    /// Each body's joint centre: the origin of its joint frame (the joint's child frame, where
    /// its parent's motions act), fixed on the body.
    pub joints: Vec<Vector3<f64>>,
    /// Observed markers (model marker order), `None` where not observed.
    pub observed: Vec<Option<Vector3<f64>>>,
}

/// Frames of a trial the body's skin is fitted at (beside the bind pose; [`Take::dress`]).
pub const FIT_POSES: usize = 8;

impl Take {
    /// The subject's body on this take: shaped from `sub`, bound to the model, and fitted to the
    /// model's markers at the bind pose and [`FIT_POSES`] of the take's frames
    /// ([`crate::body::dress_subject_with`]); with a one-line summary.
    pub fn dress(
        &self,
        asset: &crate::body::BodyAsset,
        sub: &crate::body::SubjectBody,
        fit: &crate::body::FitSettings,
    ) -> Result<(crate::body::Dressed, String), crate::body::BindError> {
        let poses = crate::body::fit_poses(&self.q, FIT_POSES);
        crate::body::dress_subject_with(&self.model, &self.world_from_model, asset, &self.scales, sub, &poses, fit)
    }

    /// The trial of a converted MCAP file: the attached scaled model (its coordinates by name,
    /// unit scales: the calibrated morphology is in the model) where the file has one that names
    /// every coordinate, else the conversion model ([`conversion_model`]) at the first frame's
    /// scales; observed markers from `/markers`, matched by name.
    pub fn from_record(rec: &TrialRecord, file: &Path) -> Result<Take, RenderError> {
        let name = file.file_stem().map_or("trial".into(), |s| s.to_string_lossy().into_owned());
        let bad = |what: String| RenderError::Content { file: file.display().to_string(), what };
        let first = &rec.frames.first().ok_or_else(|| bad("no frames".into()))?.state;
        let scaled = rec.scaled_model.as_deref().and_then(|text| {
            let (m, _) = crate::io::osim::parse_osim(text, "scaled_model.osim").ok()?;
            m.coordinates.iter().all(|c| first.q.contains_key(&c.name)).then_some(m)
        });
        let (model, scales) = match scaled {
            Some(m) => {
                let nb = m.nb();
                (m, vec![1.0; 3 * nb])
            }
            None => {
                let m = conversion_model(rec, file)?;
                let s = m.bodies.iter().flat_map(|b| first.s.get(&b.name).copied().unwrap_or([1.0; 3])).collect();
                (m, s)
            }
        };
        let index: Vec<Option<usize>> =
            model.markers.iter().map(|m| rec.marker_names.iter().position(|n| *n == m.name)).collect();
        let (mut times, mut frames, mut q, mut observed) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for f in &rec.frames {
            let s = &f.state;
            let row = model
                .coordinates
                .iter()
                .map(|c| {
                    s.q.get(&c.name)
                        .copied()
                        .ok_or_else(|| bad(format!("frame {} has no coordinate '{}'", s.frame, c.name)))
                })
                .collect::<Result<Vec<f64>, _>>()?;
            let cloud = rec.observed.get(&s.frame);
            let obs = index
                .iter()
                .map(|i| {
                    let p = &cloud?[3 * (*i)?..3 * (*i)? + 3];
                    p.iter().all(|v| v.is_finite()).then(|| Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64))
                })
                .collect();
            times.push(s.time);
            frames.push(s.frame);
            q.push(row);
            observed.push(obs);
        }
        let world_from_model = rec.world_from_model.map_or(UnitQuaternion::identity(), |[x, y, z, w]| {
            UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
        });
        Ok(Take { name, model, scales, times, frames, q, observed, world_from_model })
    }

    /// A trial `solve` just solved: the subject's context (its calibrated markers), the result
    /// (each frame's proxies) and the trial (observed markers, times).
    pub fn from_solve(
        ctx: &crate::pipeline::Context,
        result: &crate::pipeline::TrialResult,
        trial: &crate::io::MarkerTrial,
    ) -> Result<Take, RenderError> {
        let model = &ctx.model;
        let (nq, nb) = (model.nq(), model.nb());
        let mut y = vec![0.0; model.ny()];
        let mut dphi = vec![0.0; ctx.proxy.terms.len()];
        ctx.proxy.apply(&result.calibration.proxies, &mut y, &mut dphi);
        let scales = y[nq..nq + 3 * nb].to_vec();
        let cols = crate::pipeline::input::trial::match_markers(ctx, &result.name, trial)
            .map_err(|e| RenderError::Content { file: result.name.clone(), what: e.to_string() })?
            .columns;
        let t0 = trial.times.first().copied().unwrap_or(0.0);
        let (mut times, mut frames, mut q, mut observed) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (f, p) in result.proxies.iter().enumerate() {
            ctx.proxy.apply(p, &mut y, &mut dphi);
            q.push(y[..nq].to_vec());
            times.push(trial.times.get(f).map_or(f as f64 / trial.rate_hz.max(1e-9), |t| t - t0));
            frames.push(f);
            observed.push(
                cols.iter()
                    .map(|c| c.and_then(|c| trial.position(f, c)).map(|p| Vector3::new(p[0], p[1], p[2])))
                    .collect(),
            );
        }
        let name = Path::new(&result.name).file_stem().map_or("trial".into(), |s| s.to_string_lossy().into_owned());
        let world_from_model = crate::archive::mcap_out::world_from_model(ctx.up);
        Ok(Take { name, model: model.clone(), scales, times, frames, q, observed, world_from_model })
    }

    /// Frames in the take.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// Forward kinematics of frame `i` (`model` frame) into `ws`.
    pub fn forward(&self, i: usize, ws: &mut Workspace) {
        let mut y = self.q[i].clone();
        y.extend_from_slice(&self.scales);
        cpu::forward(&self.model, &y, ws);
    }

    /// Body `b`'s joint centre in its own frame (m): the joint's child offset, scaled.
    pub fn joint_centre_local(&self, b: usize) -> Vector3<f64> {
        let s = Vector3::new(self.scales[3 * b], self.scales[3 * b + 1], self.scales[3 * b + 2]);
        s.component_mul(&self.model.bodies[b].joint.child_offset.translation.vector)
    }

    /// Frame `i` in `world`.
    pub fn pose(&self, i: usize, ws: &mut Workspace) -> Pose {
        self.forward(i, ws);
        let r0 = *self.world_from_model.to_rotation_matrix().matrix();
        let body_rot: Vec<Matrix3<f64>> = ws.body_rot.iter().map(|r| r0 * r).collect();
        let body_pos: Vec<Vector3<f64>> = ws.body_pos.iter().map(|p| r0 * p).collect();
        let joints = (0..self.model.nb()).map(|b| body_pos[b] + body_rot[b] * self.joint_centre_local(b)).collect();
        let markers = (0..self.model.markers.len()).map(|m| r0 * ws.marker(m)).collect();
        let observed = self.observed[i].iter().map(|o| o.map(|p| r0 * p)).collect();
        Pose { body_rot, body_pos, markers, joints, observed }
    }

    /// Every `stride`-th frame index (from 0), the frames projection and previews work on.
    pub fn strided(&self, stride: usize) -> Vec<usize> {
        (0..self.len()).step_by(stride.max(1)).collect()
    }
}

/// Which side of the body a name is on: `_r`/`_l` suffixes, `r_`/`l_`, `r.`/`l.`,
/// `right`/`left` prefixes (any case), or an upper-case `R`/`L` before another capital
/// (`RASI`, `LKNE`).
pub fn side_of(name: &str) -> Side {
    let lower = name.to_ascii_lowercase();
    let bytes = name.as_bytes();
    let caps = |c: u8| bytes.len() > 1 && bytes[0] == c && bytes[1].is_ascii_uppercase();
    let is = |s: char| {
        let (p1, p2, p3, suf) =
            (format!("{s}_"), format!("{s}."), if s == 'r' { "right" } else { "left" }, format!("_{s}"));
        lower.starts_with(&p1) || lower.starts_with(&p2) || lower.starts_with(p3) || lower.ends_with(&suf)
    };
    if is('r') || caps(b'R') {
        Side::Right
    } else if is('l') || caps(b'L') {
        Side::Left
    } else {
        Side::Centre
    }
}

/// Left, right or on the midline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Left,
    Right,
    Centre,
}

impl Side {
    /// The colour of a side (sRGB 0–255): left blue, right red, centre light grey.
    pub fn rgb(self) -> [u8; 3] {
        match self {
            Side::Left => [60, 120, 230],
            Side::Right => [230, 70, 60],
            Side::Centre => [200, 200, 200],
        }
    }
}
