//! What the robot should do in each frame: the robot's own skeleton posed like the human's
//! (the human's segment rotations applied to the robot's segments), the root moved like the
//! human's pelvis scaled by the leg-length ratio, orientations, and when each foot is planted.
//!
//! Positions: every task's robot body `b` has a parent task `p` (the nearest robot ancestor with
//! a position task). With `c` the human body that carries `b`'s joint centre (the parent of `b`'s
//! human body), `ΔR_c(t) = R_c(t) R_c(ref)ᵀ` its rotation since the reference posture, and `r` the
//! robot body origins at the robot's reference posture (world, m):
//! `target_b = target_p + ΔR_c(t) (r_b − r_p)`: the robot's segment, turned as the human's.
//! The root task's target is the human root scaled by `k_leg` (robot over human leg length,
//! hip to ankle, from the subject's solved segments): `(k_leg h_x, k_leg h_y, z_r + k_leg (h_z −
//! f_h − z_h))`, `f_h` the human heels' standing height (5th percentile over the trial), `z_h`
//! the human root above its heels and `z_r` the robot root above the ground, both standing at
//! the reference postures.
//! Orientations: `R_target_b = R_h_b(t) O_b`, `O_b = R_h_b(ref)ᵀ R_r_b(ref)` (both in world):
//! the offset that makes the two reference postures agree.
//! A foot is planted when its heel joint centre is within [`TargetSettings::contact_height`] of
//! its standing height and slower than [`TargetSettings::contact_speed`], and its toe joint centre
//! is down too (within the same height): the foot is flat, from foot flat to heel off, as the
//! robot's pinned foot is; for at least [`TargetSettings::contact_frames`] frames.

use super::mapping::Mapping;
use super::robot::Robot;
use super::RetargetError;
use crate::kinematics::cpu::{self, Workspace};
use crate::model::{CoordinateKind, Model};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// The solved human motion to retarget (borrowed from a trial).
#[derive(Clone, Copy, Debug)]
pub struct Human<'a> {
    pub model: &'a Model,
    /// Calibrated scale factors, `3·body + axis`.
    pub scales: &'a [f64],
    /// Coordinates per frame (model order).
    pub q: &'a [Vec<f64>],
    /// Frame times (s), increasing.
    pub times: &'a [f64],
    /// The rotation from the model's frame to the Z-up world.
    pub world_from_model: UnitQuaternion<f64>,
}

/// Contact detection settings (serialised into the report).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct TargetSettings {
    /// Heel and toe within this height (m) of their standing heights.
    pub contact_height: f64,
    /// The heel slower than this (m/s).
    pub contact_speed: f64,
    /// Shortest contact kept (frames).
    pub contact_frames: usize,
}

impl Default for TargetSettings {
    fn default() -> Self {
        TargetSettings { contact_height: 0.03, contact_speed: 0.35, contact_frames: 3 }
    }
}

/// One mapped robot body, resolved against both models.
#[derive(Clone, Debug)]
pub struct PlannedTask {
    pub robot_body: usize,
    pub human_body: usize,
    pub w_pos: f64,
    pub w_rot: f64,
    /// Parent task (index into the tasks), `None` for the root task.
    pub parent: Option<usize>,
    /// Robot over human segment length to the parent task (reported, not used).
    pub ratio: f64,
    /// The human body carrying the segment (`c`), its reference orientation (world), and the
    /// robot segment `r_b − r_p` at the reference (world, m).
    pub carrier: usize,
    pub carrier_ref: Matrix3<f64>,
    pub segment: Vector3<f64>,
    /// `O_b` (human body frame → robot body frame at the references).
    pub rot_offset: Matrix3<f64>,
}

/// One foot: robot body, human heel and toe bodies, and the sole's height.
#[derive(Clone, Debug)]
pub struct PlannedFoot {
    pub robot_body: usize,
    pub heel: usize,
    pub toe: usize,
    /// Height of the robot foot body's origin when the foot is flat on the ground (m).
    pub sole_height: f64,
    /// The task of the foot body or its nearest ancestor with a position task: where the foot
    /// lands is the robot's foot corrected by that task's error.
    pub guide: usize,
}

/// The mapping resolved for one robot and one subject.
#[derive(Clone, Debug)]
pub struct Plan {
    pub tasks: Vec<PlannedTask>,
    pub feet: Vec<PlannedFoot>,
    /// Robot coordinates of the reference posture (root at the origin).
    pub reference: Vec<f64>,
    /// `k_leg`: robot over human leg length, summed over the first foot's chain of position
    /// tasks below the root's child (hip to knee to ankle, the subject's solved segments).
    pub leg_ratio: f64,
    /// Root height above the ground when standing at the reference: robot `z_r`, and the human
    /// root above its heel joint centres `z_h` (m).
    pub robot_root_height: f64,
    pub human_root_height: f64,
}

/// Targets of every frame.
#[derive(Clone, Debug, Default)]
pub struct Targets {
    /// Per frame, per task: world position (m) and orientation.
    pub pos: Vec<Vec<Vector3<f64>>>,
    pub rot: Vec<Vec<Matrix3<f64>>>,
    /// Per frame, per task: the human joint centre (world, m, unscaled).
    pub human: Vec<Vec<Vector3<f64>>>,
    /// Per frame, per foot: planted.
    pub contact: Vec<Vec<bool>>,
}

/// Human joint centres and orientations (world) of state `q`, of `bodies` (ascending, each
/// one's parent listed before it); the other bodies' entries are zero.
fn human_frame(
    h: &Human,
    q: &[f64],
    ws: &mut Workspace,
    y: &mut Vec<f64>,
    bodies: &[usize],
) -> (Vec<Vector3<f64>>, Vec<Matrix3<f64>>) {
    y.clear();
    y.extend_from_slice(q);
    y.extend_from_slice(h.scales);
    // The bodies only: the markers are not needed.
    cpu::forward_part(h.model, y, ws, bodies, &[]);
    let w = *h.world_from_model.to_rotation_matrix().matrix();
    let (mut centres, mut rots) = (vec![Vector3::zeros(); h.model.nb()], vec![Matrix3::zeros(); h.model.nb()]);
    for &b in bodies {
        let s = Vector3::new(h.scales[3 * b], h.scales[3 * b + 1], h.scales[3 * b + 2]);
        let c = s.component_mul(&h.model.bodies[b].joint.child_offset.translation.vector);
        centres[b] = w * (ws.body_pos[b] + ws.body_rot[b] * c);
        rots[b] = w * ws.body_rot[b];
    }
    (centres, rots)
}

/// The human bodies the targets and contacts read (tasks' bodies, their carriers, the feet's heels
/// and toes) and their ancestors, ascending; all bodies unless every parent precedes its child.
fn needed_bodies(model: &Model, plan: &Plan) -> Vec<usize> {
    let mut need = vec![false; model.nb()];
    let read = plan.tasks.iter().flat_map(|t| [t.human_body, t.carrier]);
    for b in read.chain(plan.feet.iter().flat_map(|f| [f.heel, f.toe])) {
        for &a in model.chain(b) {
            need[a] = true;
        }
        need[b] = true;
    }
    if model.bodies.iter().enumerate().any(|(b, body)| body.parent.is_some_and(|p| p >= b)) {
        return (0..model.nb()).collect();
    }
    (0..model.nb()).filter(|&b| need[b]).collect()
}

/// The human's reference posture: every rotational coordinate 0, translations at default.
fn human_reference(model: &Model) -> Vec<f64> {
    model.coordinates.iter().map(|c| if c.kind == CoordinateKind::Rotational { 0.0 } else { c.default }).collect()
}

impl Plan {
    /// Resolves `mapping` against `robot` and the human model; an error names what is missing.
    pub fn new(robot: &Robot, mapping: &Mapping, human: &Human) -> Result<Plan, RetargetError> {
        let hb = |name: &str| {
            human.model.body_index(name).ok_or_else(|| {
                RetargetError::Mapping(format!("the human model '{}' has no body '{name}'", human.model.name))
            })
        };
        let rm = &robot.model;
        let mut reference: Vec<f64> = rm.coordinates.iter().map(|c| c.default.clamp(c.range.0, c.range.1)).collect();
        for (name, v) in &mapping.reference {
            let i = rm
                .coordinate_index(name)
                .ok_or_else(|| RetargetError::Mapping(format!("robot has no joint '{name}'")))?;
            reference[i] = *v;
        }
        reference[..6].fill(0.0);
        let mut rws = Workspace::new(rm);
        let mut y = Vec::new();
        robot.state(&reference, &mut y);
        cpu::forward(rm, &y, &mut rws);
        let mut hws = Workspace::new(human.model);
        let all: Vec<usize> = (0..human.model.nb()).collect();
        let (hc, hr) = human_frame(human, &human_reference(human.model), &mut hws, &mut y, &all);

        let mut tasks = Vec::<PlannedTask>::new();
        // Tasks whose human body is missing (a model without arms) are left out.
        for t in &mapping.tasks {
            let Ok(human_body) = hb(&t.human) else { continue };
            let robot_body = robot.body(&t.robot)?;
            let rot_offset = hr[human_body].transpose() * rws.body_rot[robot_body];
            let carrier = human.model.bodies[human_body].parent.unwrap_or(human_body);
            tasks.push(PlannedTask {
                robot_body,
                human_body,
                w_pos: t.position,
                w_rot: t.orientation,
                parent: None,
                ratio: 1.0,
                rot_offset,
                carrier,
                carrier_ref: hr[carrier],
                segment: Vector3::zeros(),
            });
        }
        if tasks.is_empty() {
            return Err(RetargetError::Mapping(format!(
                "no task of the mapping names a body of '{}'",
                human.model.name
            )));
        }
        tasks.sort_by_key(|t| t.robot_body);
        if tasks[0].robot_body != 0 {
            return Err(RetargetError::Mapping(format!(
                "no task drives the robot's root body '{}'",
                rm.bodies[0].name
            )));
        }
        for i in 1..tasks.len() {
            let chain = rm.chain(tasks[i].robot_body);
            let parent = (0..i).rev().find(|&j| tasks[j].w_pos > 0.0 && chain.contains(&tasks[j].robot_body));
            let p = parent.unwrap_or(0);
            let lr = (rws.body_pos[tasks[i].robot_body] - rws.body_pos[tasks[p].robot_body]).norm();
            let lh = (hc[tasks[i].human_body] - hc[tasks[p].human_body]).norm();
            tasks[i].parent = Some(p);
            tasks[i].ratio = if lh > 1e-3 { lr / lh } else { 1.0 };
            tasks[i].segment = rws.body_pos[tasks[i].robot_body] - rws.body_pos[tasks[p].robot_body];
        }
        let feet = mapping
            .feet
            .iter()
            .map(|f| {
                let robot_body = robot.body(&f.robot)?;
                let lowest = robot
                    .capsules
                    .iter()
                    .filter(|c| c.body == robot_body)
                    .map(|c| (rws.body_rot[robot_body] * c.a).z.min((rws.body_rot[robot_body] * c.b).z) - c.radius)
                    .fold(f64::INFINITY, f64::min);
                if !lowest.is_finite() {
                    return Err(RetargetError::Mapping(format!("foot '{}' has no collision geoms", f.robot)));
                }
                let chain = rm.chain(robot_body);
                let guide = (0..tasks.len())
                    .rev()
                    .find(|&k| tasks[k].w_pos > 0.0 && chain.contains(&tasks[k].robot_body))
                    .unwrap_or(0);
                Ok(PlannedFoot { robot_body, heel: hb(&f.heel)?, toe: hb(&f.toe)?, sole_height: -lowest, guide })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let (mut lr, mut lh) = (0.0, 0.0);
        if let Some(f) = feet.first() {
            let mut k = f.guide;
            while let Some(p) = tasks[k].parent.filter(|&p| p != 0) {
                lr += tasks[k].segment.norm();
                lh += (hc[tasks[k].human_body] - hc[tasks[p].human_body]).norm();
                k = p;
            }
        }
        let leg_ratio = if lh > 1e-3 && lr > 0.0 { lr / lh } else { 1.0 };
        let (robot_root_height, human_root_height) = match feet.first() {
            Some(f) => (
                rws.body_pos[0].z - rws.body_pos[f.robot_body].z + f.sole_height,
                hc[tasks[0].human_body].z - hc[f.heel].z,
            ),
            None => (rws.body_pos[0].z, hc[tasks[0].human_body].z),
        };
        Ok(Plan { tasks, feet, reference, leg_ratio, robot_root_height, human_root_height })
    }

    /// The targets and contacts of every frame of `human`.
    pub fn targets(&self, human: &Human, settings: &TargetSettings) -> Targets {
        let n = human.q.len();
        let mut ws = Workspace::new(human.model);
        let mut y = Vec::new();
        let bodies = needed_bodies(human.model, self);
        let frames: Vec<_> = human.q.iter().map(|q| human_frame(human, q, &mut ws, &mut y, &bodies)).collect();
        let standing = |body: usize| percentile(frames.iter().map(|(c, _)| c[body].z).collect(), 0.05);
        let heel_floor = self.feet.iter().map(|f| standing(f.heel)).fold(f64::INFINITY, f64::min);
        let heel_floor = if heel_floor.is_finite() { heel_floor } else { 0.0 };
        let mut t = Targets::default();
        for (c, r) in &frames {
            let mut pos: Vec<Vector3<f64>> = Vec::with_capacity(self.tasks.len());
            for task in &self.tasks {
                let h = c[task.human_body];
                let p = match task.parent {
                    None => {
                        let k = self.leg_ratio;
                        let z = self.robot_root_height + k * (h.z - heel_floor - self.human_root_height);
                        Vector3::new(k * h.x, k * h.y, z)
                    }
                    Some(p) => pos[p] + r[task.carrier] * task.carrier_ref.transpose() * task.segment,
                };
                pos.push(p);
            }
            t.pos.push(pos);
            t.human.push(self.tasks.iter().map(|task| c[task.human_body]).collect());
            t.rot.push(self.tasks.iter().map(|task| r[task.human_body] * task.rot_offset).collect());
        }
        let mut contact = vec![vec![false; self.feet.len()]; n];
        for (k, f) in self.feet.iter().enumerate() {
            let (heel0, toe0) = (standing(f.heel), standing(f.toe));
            let speed = |i: usize, b: usize| {
                let (a, z) = (i.saturating_sub(1), (i + 1).min(n - 1));
                let dt = human.times[z] - human.times[a];
                if dt > 0.0 {
                    (frames[z].0[b] - frames[a].0[b]).norm() / dt
                } else {
                    0.0
                }
            };
            let raw: Vec<bool> = (0..n)
                .map(|i| {
                    let c = &frames[i].0;
                    let heel =
                        c[f.heel].z - heel0 < settings.contact_height && speed(i, f.heel) < settings.contact_speed;
                    // The toe down too: the foot is flat (from foot flat to heel off), as the
                    // robot's pinned foot is.
                    heel && c[f.toe].z - toe0 < settings.contact_height
                })
                .collect();
            for (i, v) in keep_runs(&raw, settings.contact_frames).into_iter().enumerate() {
                contact[i][k] = v;
            }
        }
        t.contact = contact;
        t
    }
}

/// The `p`-quantile (nearest rank) of `v`; 0 for an empty `v`.
fn percentile(mut v: Vec<f64>, p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// `raw` with runs of `true` shorter than `min` set to `false`.
fn keep_runs(raw: &[bool], min: usize) -> Vec<bool> {
    let mut out = vec![false; raw.len()];
    let mut i = 0;
    while i < raw.len() {
        if !raw[i] {
            i += 1;
            continue;
        }
        let end = (i..raw.len()).find(|&j| !raw[j]).unwrap_or(raw.len());
        if end - i >= min {
            out[i..end].fill(true);
        }
        i = end;
    }
    out
}
