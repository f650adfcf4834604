//! Humanoid robots from the solved human motion (`smocap retarget`, `docs/RETARGET.md`).
//!
//! A robot's MJCF is read with [`crate::io::mjcf`] ([`robot`]); a [`mapping`] says which human
//! body drives which robot body; [`targets`] scales the human's mapped joint centres onto the
//! robot's segment lengths (the subject's own, per chain) and detects planted feet; [`solve`]
//! runs one small QP per frame over the robot's coordinates with hard joint-range and velocity
//! limits, foot pins, a ground and self-collision rows, warm-started frame to frame; [`report`]
//! measures the result and [`files`] writes it (GMR pickle, mjlab CSV, NPZ).
//! [`track`] gives the robot's body poses for the trial's MCAP file ([`crate::archive::mcap_robot`]).
//! Imports `io`, `model`, `kinematics`, `solve` and `archive`; imported by `cli` only.

pub mod collide;
pub mod files;
pub mod mapping;
pub mod report;
pub mod robot;
pub mod solve;
pub mod targets;
pub mod track;

pub use files::RobotMotion;
pub use mapping::Mapping;
pub use report::Report;
pub use robot::Robot;
pub use solve::SolveSettings;
pub use targets::{Human, Plan, TargetSettings};

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};
use solve::{Pin, Solver};

/// Errors of retargeting.
#[derive(Debug, thiserror::Error)]
pub enum RetargetError {
    #[error("robot: {0}")]
    Robot(String),
    #[error("mapping: {0}")]
    Mapping(String),
    #[error(transparent)]
    MappingFile(#[from] mapping::MappingError),
}

/// All settings of a retargeting run (into the report).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct RetargetSettings {
    pub targets: TargetSettings,
    pub solve: SolveSettings,
}

/// A retargeted trial.
#[derive(Clone, Debug)]
pub struct Retargeted {
    pub motion: RobotMotion,
    pub report: Report,
    /// Robot coordinates per frame (root x y z, z-y-x angles, joints).
    pub q: Vec<Vec<f64>>,
    /// Per frame, per body: world orientation and origin (m), the forward kinematics of `q`.
    pub poses: crate::archive::mcap_robot::BodyPoses,
    /// The targets and contacts the robot was solved to.
    pub targets: files::TargetRecord,
}

/// The targets of `plan` as a [`files::TargetRecord`] (moved, not copied).
fn target_record(robot: &Robot, plan: &Plan, human: &Human, t: targets::Targets, fps: f64) -> files::TargetRecord {
    let body = |b: usize| robot.model.bodies[b].name.clone();
    files::TargetRecord {
        fps,
        robot_bodies: plan.tasks.iter().map(|k| body(k.robot_body)).collect(),
        human_bodies: plan.tasks.iter().map(|k| human.model.bodies[k.human_body].name.clone()).collect(),
        weights: plan.tasks.iter().map(|k| [k.w_pos, k.w_rot]).collect(),
        pos: t.pos,
        rot: t.rot,
        human: t.human,
        feet: plan.feet.iter().map(|f| body(f.robot_body)).collect(),
        contact: t.contact,
    }
}

/// Robots shipped inside the binary: name, MJCF, the mapping from the OpenSim full-body families.
const SHIPPED: [(&str, &str, &str); 1] =
    [("g1", include_str!("../../models/robots/g1/g1.xml"), include_str!("../../models/robots/g1/opensim.toml"))];

/// The names of the shipped robots.
pub fn shipped_names() -> Vec<&'static str> {
    SHIPPED.iter().map(|s| s.0).collect()
}

/// A shipped robot and its mapping by name (`g1`), or `None`.
pub fn shipped(name: &str) -> Option<Result<(Mapping, Robot), RetargetError>> {
    let (_, xml, toml_text) = SHIPPED.iter().find(|s| s.0 == name)?;
    let file = format!("models/robots/{name}/opensim.toml");
    Some((|| {
        let mut m: Mapping = toml::from_str(toml_text)
            .map_err(|e| mapping::MappingError::Parse { file: file.clone(), message: e.to_string() })?;
        m.robot = format!("models/robots/{name}/{name}.xml").into();
        let robot = Robot::from_text(xml, &m.robot.display().to_string(), &m)?;
        Ok((m, robot))
    })())
}

/// A robot by shipped name or mapping file (our TOML, or GMR's JSON with `mjcf` naming the
/// robot's MJCF when the JSON does not).
pub fn load(robot: &str, mjcf: Option<&std::path::Path>) -> Result<(Mapping, Robot), RetargetError> {
    if let Some(r) = shipped(robot) {
        return r;
    }
    let path = std::path::Path::new(robot);
    if !path.exists() {
        return Err(RetargetError::Robot(format!(
            "'{robot}' is neither a shipped robot ({}) nor a mapping file",
            shipped_names().join(", ")
        )));
    }
    let mut m = Mapping::read(path)?;
    if let Some(x) = mjcf {
        m.robot = x.to_path_buf();
    }
    if m.robot.as_os_str().is_empty() {
        return Err(RetargetError::Mapping(format!("{robot}: names no robot MJCF; give one with --mjcf")));
    }
    let r = Robot::load(&m)?;
    Ok((m, r))
}

/// The flat orientation with the yaw of `r` (rotation about world z only).
fn flat(r: &Matrix3<f64>) -> Matrix3<f64> {
    let yaw = r[(1, 0)].atan2(r[(0, 0)]);
    *Rotation3::from_axis_angle(&Vector3::z_axis(), yaw).matrix()
}

/// Retargets `human` (trial `name`) onto `robot` with `plan`.
pub fn retarget(human: &Human, robot: &Robot, plan: &Plan, settings: &RetargetSettings, name: &str) -> Retargeted {
    let targets = plan.targets(human, &settings.targets);
    let n = human.q.len();
    let mut solver = Solver::new(robot, plan, settings.solve.clone());
    let mut q = plan.reference.clone();
    if let (Some(p), Some(r)) = (targets.pos.first(), targets.rot.first()) {
        q[..3].copy_from_slice(p[0].as_slice());
        let (roll, pitch, yaw) = Rotation3::from_matrix_unchecked(r[0]).euler_angles();
        q[3..6].copy_from_slice(&[yaw, pitch, roll]);
    }
    let (mut prev, mut prev2) = (q.clone(), q.clone());
    let mut pins: Vec<Option<Pin>> = vec![None; plan.feet.len()];
    let mut out = report::Recorder::new(plan, n);
    let mut all_q = Vec::with_capacity(n);
    for i in 0..n {
        let dt = if i > 0 { human.times[i] - human.times[i - 1] } else { 0.0 };
        for (k, f) in plan.feet.iter().enumerate() {
            pins[k] = match (targets.contact[i][k], pins[k], i > 0) {
                (true, Some(p), _) => Some(p),
                (true, None, true) => {
                    // Lands where the target puts it: the robot's foot moved by its guide's error.
                    let guide = plan.tasks[f.guide].robot_body;
                    let error = targets.pos[i][f.guide] - solver.ws.body_pos[guide];
                    let (pos, rot) = (solver.ws.body_pos[f.robot_body] + error, solver.ws.body_rot[f.robot_body]);
                    let z = f.sole_height + settings.solve.ground_margin;
                    Some(Pin { pos: Vector3::new(pos.x, pos.y, z), rot: flat(&rot) })
                }
                _ => None,
            };
        }
        if i >= 2 {
            // Warm start: the last two frames' velocity continued (the solve starts closer).
            for ((qj, p), p2) in q.iter_mut().zip(&prev).zip(&prev2) {
                *qj = p + (p - p2);
            }
        }
        let used = solver.frame(&targets, i, &mut q, (i > 0).then_some((prev.as_slice(), dt)), &pins);
        out.record(&solver, &targets, i, &q, used);
        prev2.copy_from_slice(&prev);
        prev.copy_from_slice(&q);
        all_q.push(q.clone());
    }
    let fps = if n > 1 { (n - 1) as f64 / (human.times[n - 1] - human.times[0]).max(1e-9) } else { 0.0 };
    let (motion, report, poses) = out.finish(robot, plan, human, &targets, &all_q, fps, settings, name);
    let targets = target_record(robot, plan, human, targets, fps);
    Retargeted { motion, report, q: all_q, poses, targets }
}
