//! A subject's body: the mesh shaped to the subject's stature, bound to its model, and posed by
//! linear-blend skinning with the model's body frames from forward kinematics.
//!
//! A vertex with influences `(b, w, u)` ([`super::Influence`]: `u` in body `b`'s frame at unit
//! scale) goes, in a state whose scales are `s` and body frames `(R_b, p_b)`, to
//! `Σ w (R_b (s_b ⊙ u) + p_b)`, turned into the Z-up world by `world_from_model`. The bind
//! state's own scales are divided out of `u`, so the subject's scale factors are applied in the
//! bind → pose transform: a femur scaled 1.1 makes the thigh's skin 1.1 times as long along the
//! femur's axis (skin blended across a joint follows both bodies' scales).
//!
//! Shaping: the mesh's `height` parameter is chosen so that its stature is the subject's
//! ([`BodyAsset::height_for_stature`]): the calibrated stature where it is known, else the
//! stature of the reference mesh dressed on the subject's scales; sex sets `gender`. The shaped
//! mesh is then bound to the model ([`super::bind()`]).

use super::asset::{BodyAsset, BodyShape, Phenotype};
use super::bind::{bind, bind_from, Binding};
use super::corrective::Corrective;
use super::helpers::JointInfluence;
use super::segments::BindError;
use crate::kinematics::cpu::{forward, Workspace};
use crate::model::anthropometry::Sex;
use crate::model::Model;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// The body of one subject on its model.
#[derive(Clone, Debug)]
pub struct Dressed {
    pub binding: Binding,
    /// The shape's parameters and its stature (m, highest minus lowest vertex of the shape).
    pub phenotype: Phenotype,
    pub shape_stature: f64,
    /// The stature the shape was chosen for (m).
    pub target_stature: f64,
    /// Counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// The right foot's skin (vertices mostly on `calcn_r` or `toes_r`), whose lowest vertex
    /// the body's height is read down to ([`Dressed::height`]).
    pub sole: Vec<u32>,
    /// The shaping to the subject's markers, where it was done ([`super::fit`]).
    pub fit: Option<ShapeFit>,
    /// Volume-preserving pose correctives ([`super::correctives`]; empty until
    /// [`super::dress_subject_with`] measures them at the subject's scales).
    pub correctives: Vec<Corrective>,
}

/// What the fit to the markers did ([`super::fit`]), per segment and overall.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ShapeFit {
    pub coefficients: Vec<f64>,
    /// Per asset segment: name, stretch along its body's x, y, z, shift (m, asset frame).
    pub segments: Vec<(String, [f64; 3], [f64; 3])>,
    /// Landmarks' median |d − ρ| (m) at the bind pose, before and after.
    pub landmark_median_before_m: f64,
    pub landmark_median_after_m: f64,
    /// Body height minus stature (m) before and after (`None`: stature unknown).
    pub stature_error_before_m: Option<f64>,
    pub stature_error_after_m: Option<f64>,
    /// Enclosed volume over the target, minus 1, before and after (`None`: mass unknown).
    pub volume_error_before: Option<f64>,
    pub volume_error_after: Option<f64>,
    pub markers_used: usize,
}

/// Scratch for posing: forward kinematics and the posed vertices (Z-up world, m).
#[derive(Clone, Debug)]
pub struct PoseWorkspace {
    pub kin: Workspace,
    pub vertices: Vec<[f32; 3]>,
    /// Per joint (bodies, then helpers): its map from unit-scale coordinates to the output frame.
    rot: Vec<Matrix3<f64>>,
    pos: Vec<Vector3<f64>>,
    /// Per joint: its rotation in the output frame (no scale); per body, at the bind state.
    turn: Vec<Matrix3<f64>>,
    bind_turn: Vec<Matrix3<f64>>,
    /// Per joint: its rotation since the bind pose (output frame); per corrective, its weight.
    since: Vec<Matrix3<f64>>,
    pub morph: Vec<f64>,
}

impl PoseWorkspace {
    /// Joint `j`'s (body `j < nb`, else helper `j − nb`) rotation and origin in the output
    /// frame after [`Dressed::pose_joints`] (a helper's origin is where it carries its parent's).
    pub fn joint(&self, j: usize) -> (Matrix3<f64>, Vector3<f64>) {
        (self.turn[j], self.pos[j])
    }

    /// Turns body `b`'s map by `g` about `centre` (output frame; helpers and correctives' joints
    /// stale until [`PoseWorkspace::refresh_helpers`]).
    pub(super) fn turn_body(&mut self, b: usize, g: &Matrix3<f64>, centre: &Vector3<f64>) {
        self.turn[b] = g * self.turn[b];
        self.rot[b] = g * self.rot[b];
        self.pos[b] = centre + g * (self.pos[b] - centre);
    }

    /// Recomputes the helpers' frames and every joint's rotation since the bind pose.
    pub(super) fn refresh_helpers(&mut self, body: &Dressed) {
        let hs = &body.binding.helpers.helpers;
        super::helpers::frames(hs, &self.bind_turn, &mut self.rot, &mut self.pos, &mut self.turn);
        let nb = self.bind_turn.len();
        for j in 0..self.turn.len() {
            let base = if j < nb { j } else { hs[j - nb].parent };
            self.since[j] = self.turn[j] * self.bind_turn[base].transpose();
        }
    }

    /// Adds corrective `k` at weight `w` to the posed vertices, turned by the joints (posed)
    /// that `joints` blends each vertex over.
    pub(super) fn add_corrective(&mut self, k: &Corrective, w: f64, joints: &[[JointInfluence; 4]]) {
        k.add_to(w, joints, &self.since, &mut self.vertices);
    }

    pub fn new(model: &Model, body: &Dressed) -> PoseWorkspace {
        PoseWorkspace {
            since: vec![Matrix3::identity(); model.nb() + body.binding.helpers.helpers.len()],
            morph: vec![0.0; body.correctives.len()],
            kin: Workspace::new(model),
            vertices: vec![[0.0; 3]; body.binding.influences.len()],
            rot: vec![Matrix3::identity(); model.nb() + body.binding.helpers.helpers.len()],
            pos: vec![Vector3::zeros(); model.nb() + body.binding.helpers.helpers.len()],
            turn: vec![Matrix3::identity(); model.nb() + body.binding.helpers.helpers.len()],
            bind_turn: {
                let r0 = body.binding.world_from_model.to_rotation_matrix().into_inner();
                body.binding.body_rot.iter().map(|r| r0 * r).collect()
            },
        }
    }
}

/// The reference phenotype with the subject's sex (`gender` 0 male, 1 female; 0.5 unknown).
pub fn phenotype_for(sex: Option<Sex>) -> Phenotype {
    let gender = match sex {
        Some(Sex::Male) => 0.0,
        Some(Sex::Female) => 1.0,
        None => 0.5,
    };
    Phenotype { gender, ..Phenotype::default() }
}

/// The vertices whose largest skinning weight is on the asset's right foot (`calcn_r`, `toes_r`).
fn right_foot(asset: &BodyAsset) -> Vec<u32> {
    let foot: Vec<u8> = ["calcn_r", "toes_r"].iter().filter_map(|s| asset.segment_index(s)).map(|i| i as u8).collect();
    let top =
        |k: &super::asset::Skin| (0..4).max_by(|&a, &b| k.weights[a].total_cmp(&k.weights[b])).map(|i| k.segments[i]);
    (0..asset.skin.len() as u32).filter(|&v| top(&asset.skin[v as usize]).is_some_and(|s| foot.contains(&s))).collect()
}

/// The lowest vertex along Z among `among` (among all where it is empty).
pub(super) fn lowest(vertices: &[[f32; 3]], among: &[u32]) -> usize {
    let z = |k: &usize| vertices[*k][2];
    match among.is_empty() {
        true => (0..vertices.len()).min_by(|a, b| z(a).total_cmp(&z(b))),
        false => among.iter().map(|&k| k as usize).min_by(|a, b| z(a).total_cmp(&z(b))),
    }
    .unwrap_or(0)
}

/// Highest minus lowest point along Z.
pub fn height_of(vertices: &[[f32; 3]]) -> f64 {
    let (lo, hi) = vertices.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| (lo.min(v[2]), hi.max(v[2])));
    (hi - lo) as f64
}

impl Dressed {
    /// The body of a subject whose model is `model` (frame `world_from_model` from the Z-up
    /// world) at scales `scales` (`3·body + axis`), of stature `stature` (m) where known, from
    /// phenotype `base` (its `height` is replaced).
    pub fn new(
        model: &Model,
        world_from_model: &UnitQuaternion<f64>,
        asset: &BodyAsset,
        scales: &[f64],
        stature: Option<f64>,
        base: Phenotype,
    ) -> Result<Dressed, BindError> {
        let first = |target: f64| match asset.height_for_stature(&base, target) {
            Ok(p) => p,
            // beyond the shape space: the nearest end (the skeleton's scales still size it)
            Err(_) => Phenotype { height: if target > asset.rest.stature() { 1.0 } else { 0.0 }, ..base },
        };
        let (target, mut start) = match stature {
            Some(h) => (h, None),
            None => {
                let reference = asset.shape_from(&base);
                let b = bind(model, world_from_model, asset, &reference)?;
                let y = b.y.clone();
                (Dressed::from_binding(b, base, &reference, 0.0, asset).bind_pose_height(model, scales), Some(y))
            }
        };
        // Rounds: the height a shape gives at the subject's scales corrects the stature asked of
        // the next (binding a taller mesh also raises the bind scales, which the subject's scales
        // are divided by, so the posed height moves less than the mesh's: a secant step, its
        // slope kept in [0.1, 1.5]); the best of at most four rounds, stopping within 2 mm.
        let sized = scales.len() == 3 * model.nb();
        let mut ask = target;
        let mut best: Option<(f64, Dressed)> = None;
        let mut last: Option<(f64, f64)> = None; // (ask, height)
        for _ in 0..if sized { 4 } else { 1 } {
            let phenotype = first(ask);
            let shape = asset.shape_from(&phenotype);
            let b = bind_from(model, world_from_model, asset, &shape, start.as_deref())?;
            start = Some(b.y.clone());
            let d = Dressed::from_binding(b, phenotype, &shape, target, asset);
            if !sized {
                return Ok(d);
            }
            let h = d.bind_pose_height(model, scales);
            let slope = last.map_or(1.0, |(a0, h0)| if (ask - a0).abs() > 1e-9 { (h - h0) / (ask - a0) } else { 1.0 });
            last = Some((ask, h));
            let err = (h - target).abs();
            if best.as_ref().is_none_or(|(e, _)| err < *e) {
                best = Some((err, d));
            }
            if err < 0.002 {
                break;
            }
            ask = (ask + (target - h) / slope.clamp(0.1, 1.5)).clamp(0.5, 2.6);
        }
        Ok(best.expect("one round at least").1)
    }

    fn from_binding(
        binding: Binding,
        phenotype: Phenotype,
        shape: &BodyShape,
        target: f64,
        asset: &BodyAsset,
    ) -> Dressed {
        Dressed {
            binding,
            phenotype,
            shape_stature: shape.stature(),
            target_stature: target,
            triangles: asset.triangles.clone(),
            sole: right_foot(asset),
            fit: None,
            correctives: Vec::new(),
        }
    }

    /// The bind state's coordinates with `scales`.
    pub fn bind_state(&self, model: &Model, scales: &[f64]) -> Vec<f64> {
        let mut y = self.binding.y[..model.nq()].to_vec();
        y.extend_from_slice(scales);
        y
    }

    /// Height (m) of the body at the bind pose and `scales` ([`Dressed::height`]).
    pub fn bind_pose_height(&self, model: &Model, scales: &[f64]) -> f64 {
        let mut ws = PoseWorkspace::new(model, self);
        self.pose(model, &self.bind_state(model, scales), &mut ws);
        self.height(&ws.vertices)
    }

    /// Height (m) of posed `vertices` as a stature is read: the highest vertex above the right
    /// foot's sole, as the stature dimensions of `models/landmarks/` read it (down to the right
    /// heel). Both soles are level on most subjects; where the legs differ (`smocap synth` draws
    /// each side's scales on their own: its second subject's left leg is 9 cm longer) the
    /// highest-minus-lowest vertex would read the longer leg, and the shaping would shrink the
    /// whole shape to make up for it.
    pub fn height(&self, vertices: &[[f32; 3]]) -> f64 {
        let hi = vertices.iter().fold(f32::NEG_INFINITY, |hi, v| hi.max(v[2]));
        (hi - vertices[lowest(vertices, &self.sole)][2]) as f64
    }

    /// Poses the body at state `y = [q; s]`: [`Dressed::pose_joints`], then [`Dressed::skin`]
    /// into `ws.vertices` and the correctives at their weights. Allocates nothing.
    pub fn pose(&self, model: &Model, y: &[f64], ws: &mut PoseWorkspace) {
        self.pose_joints(model, y, ws);
        self.skin_only(ws);
        for (k, c) in self.correctives.iter().enumerate() {
            ws.add_corrective(c, ws.morph[k], &self.binding.helpers.joints);
        }
    }

    /// Linear-blend skinning of the joints posed in `ws` into `ws.vertices`, no correctives.
    pub(super) fn skin_only(&self, ws: &mut PoseWorkspace) {
        self.skin(&ws.rot, &ws.pos, &mut ws.vertices);
    }

    /// Forward kinematics and every joint's map (bodies, then helpers) at state `y`, read with
    /// [`PoseWorkspace::joint`], and the correctives' weights (`ws.morph`). Allocates nothing.
    pub fn pose_joints(&self, model: &Model, y: &[f64], ws: &mut PoseWorkspace) {
        forward(model, y, &mut ws.kin);
        let PoseWorkspace { kin, rot, pos, turn, .. } = ws;
        let r0 = self.binding.world_from_model.to_rotation_matrix().into_inner();
        for b in 0..model.nb() {
            let i = model.scale_index(b, 0);
            // world from unit-scale body coordinates: R0 R_b diag(s_b)
            turn[b] = r0 * kin.body_rot[b];
            rot[b] = turn[b] * Matrix3::from_diagonal(&Vector3::new(y[i], y[i + 1], y[i + 2]));
            pos[b] = r0 * kin.body_pos[b];
        }
        ws.refresh_helpers(self);
        for (k, c) in self.correctives.iter().enumerate() {
            ws.morph[k] = c.weight(&ws.since[c.parent], &ws.since[c.child]);
        }
    }

    /// Linear-blend skinning with `rot[j]`, `pos[j]`: each joint's (bodies, then helpers) map
    /// from unit-scale coordinates to the output frame (`R diag(s)`, origin), into `out` (one
    /// per vertex).
    pub fn skin(&self, rot: &[Matrix3<f64>], pos: &[Vector3<f64>], out: &mut [[f32; 3]]) {
        let b = &self.binding;
        for ((o, joints), inf) in out.iter_mut().zip(&b.helpers.joints).zip(&b.influences) {
            let mut v = Vector3::zeros();
            for x in joints {
                if x.weight == 0.0 {
                    break;
                }
                let j = x.joint as usize;
                let l = inf[x.from as usize].local;
                let u = Vector3::new(l[0] as f64, l[1] as f64, l[2] as f64);
                v += (rot[j] * u + pos[j]) * x.weight as f64;
            }
            *o = [v.x as f32, v.y as f32, v.z as f32];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::context::Context;

    #[test]
    fn the_bind_pose_gives_back_the_shaped_mesh() {
        let asset = BodyAsset::shipped().unwrap();
        let model = Context::shipped().unwrap().model;
        let ones = vec![1.0; 3 * model.nb()];
        let body =
            Dressed::new(&model, &UnitQuaternion::identity(), &asset, &ones, None, Phenotype::default()).unwrap();
        let h = body.bind_pose_height(&model, &ones);
        assert!((h - body.target_stature).abs() < 0.01, "{h} {}", body.target_stature);
        // at the bind state itself (its own scales) skinning reproduces the shape exactly
        let mut ws = PoseWorkspace::new(&model, &body);
        body.pose(&model, &body.binding.y, &mut ws);
        let shape = asset.shape_from(&body.phenotype);
        let worst = ws
            .vertices
            .iter()
            .zip(&shape.vertices)
            .map(|(a, b)| (Vector3::new(a[0] as f64, a[1] as f64, a[2] as f64) - b).norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn a_longer_femur_lengthens_the_thigh() {
        let asset = BodyAsset::shipped().unwrap();
        let model = Context::shipped().unwrap().model;
        let body =
            Dressed::new(&model, &UnitQuaternion::identity(), &asset, &[], Some(1.75), Phenotype::default()).unwrap();
        let mut y = body.binding.y.clone();
        let mut ws = PoseWorkspace::new(&model, &body);
        body.pose(&model, &y, &mut ws);
        let before = height_of(&ws.vertices);
        let femur = model.body_index("femur_r").unwrap();
        let fl = model.body_index("femur_l").unwrap();
        for b in [femur, fl] {
            for k in 0..3 {
                y[model.scale_index(b, k)] *= 1.1;
            }
        }
        body.pose(&model, &y, &mut ws);
        let after = height_of(&ws.vertices);
        // a thigh is about 0.4 m: 10 % longer raises the body by about 4 cm
        assert!(after - before > 0.025 && after - before < 0.06, "{before} {after}");
    }
}
