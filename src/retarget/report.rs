//! The quality report of one retargeted trial: tracking, limits, feet, self-collision, jerk,
//! and a verdict (`ok` only when every hard requirement holds).

use super::files::RobotMotion;
use super::robot::Robot;
use super::solve::Solver;
use super::targets::{Human, Plan, Targets};
use super::RetargetSettings;
use crate::archive::mcap_robot::BodyPoses;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Median and 95th percentile (mm) of one mapped body's distance to its scaled target.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Tracking {
    pub robot: String,
    pub human: String,
    pub median_mm: f64,
    pub p95_mm: f64,
}

/// One foot's ground contact.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FootReport {
    pub robot: String,
    /// Frames in which the foot is planted.
    pub contact_frames: usize,
    /// Mean horizontal speed of the foot body during contact (m/s).
    pub slide_mean_m_s: f64,
    pub slide_max_m_s: f64,
    /// Deepest point of the foot's capsules below the ground (m, ≥ 0) and frames with any.
    pub penetration_max_m: f64,
    pub penetration_frames: usize,
}

/// The report of one trial (`<trial>.json`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Report {
    pub trial: String,
    pub robot: String,
    pub frames: usize,
    pub fps: f64,
    /// `ok`, or `suspect` with `reasons`.
    pub status: String,
    pub reasons: Vec<String>,
    /// Robot over human segment lengths per mapped body, and the leg ratio of the root.
    pub scale: Vec<(String, f64)>,
    pub leg_ratio: f64,
    pub tracking: Vec<Tracking>,
    /// Hand, foot and pelvis tracking, median over them (mm).
    pub end_effector_median_mm: f64,
    /// Frames whose solution holds a non-finite number (never `ok`).
    #[serde(default)]
    pub non_finite_frames: usize,
    /// Joint-frames outside the joint's range (beyond 1e-9 rad).
    pub range_violations: usize,
    /// Joint-steps faster than the joint's velocity limit (beyond 1e-9 rad/s).
    pub velocity_violations: usize,
    pub feet: Vec<FootReport>,
    /// Frames with two capsules of the robot overlapping (distance < 0), and the deepest overlap (m).
    pub self_collision_frames: usize,
    pub self_collision_max_m: f64,
    /// Root mean square joint jerk (rad/s³).
    pub jerk_rms: f64,
    /// Mean Gauss–Newton iterations per frame (timings are printed, not stored: the report
    /// is a function of the input and settings alone).
    pub iterations_mean: f64,
    /// The settings used.
    pub settings: serde_json::Value,
    /// Colliding geoms of shapes not modelled (not checked for self-collision).
    pub ignored_geoms: Vec<String>,
}

/// Limits the verdict holds the trial to.
pub const MAX_PENETRATION_M: f64 = 0.01;
pub const MAX_SLIDE_M_S: f64 = 0.01;
pub const MAX_END_EFFECTOR_MM: f64 = 30.0;

impl Report {
    /// Sets `status` and `reasons` from the measurements.
    pub fn judge(&mut self) {
        let mut r = Vec::new();
        if self.non_finite_frames > 0 {
            r.push(format!("{} frames with non-finite coordinates", self.non_finite_frames));
        }
        if self.range_violations > 0 {
            r.push(format!("{} joint-frames outside their ranges", self.range_violations));
        }
        if self.velocity_violations > 0 {
            r.push(format!("{} joint-steps over their velocity limits", self.velocity_violations));
        }
        for f in &self.feet {
            if f.penetration_max_m > MAX_PENETRATION_M {
                r.push(format!("{} penetrates the ground by {:.1} mm", f.robot, f.penetration_max_m * 1e3));
            }
            if f.slide_mean_m_s > MAX_SLIDE_M_S {
                r.push(format!("{} slides {:.1} cm/s on average while planted", f.robot, f.slide_mean_m_s * 100.0));
            }
        }
        if self.self_collision_frames > 0 {
            r.push(format!(
                "{} frames with self-collision (deepest {:.1} mm)",
                self.self_collision_frames,
                self.self_collision_max_m * 1e3
            ));
        }
        if self.end_effector_median_mm > MAX_END_EFFECTOR_MM {
            r.push(format!("end effectors track their targets at {:.1} mm median", self.end_effector_median_mm));
        }
        self.status = if r.is_empty() { "ok" } else { "suspect" }.into();
        self.reasons = r;
    }
}

/// Collects what the report needs, frame by frame.
pub(super) struct Recorder {
    qpos: Vec<Vec<f64>>,
    body_pos: Vec<Vec<[f64; 3]>>,
    /// Per frame, per body: world orientation and origin (m), for the MCAP file's `/robot/tf`.
    poses: BodyPoses,
    /// Per task, per frame: distance to the target (m).
    errors: Vec<Vec<f64>>,
    /// Per foot, per frame: body origin (world) and lowest capsule point above ground (m).
    feet: Vec<Vec<(Vector3<f64>, f64)>>,
    /// Per frame: the smallest capsule-pair distance (m; `+∞` when no bounding spheres touch).
    closest: Vec<f64>,
    iterations: usize,
}

impl Recorder {
    pub fn new(plan: &Plan, n: usize) -> Recorder {
        Recorder {
            qpos: Vec::with_capacity(n),
            body_pos: Vec::with_capacity(n),
            poses: Vec::with_capacity(n),
            errors: vec![Vec::with_capacity(n); plan.tasks.len()],
            feet: vec![Vec::with_capacity(n); plan.feet.len()],
            closest: Vec::with_capacity(n),
            iterations: 0,
        }
    }

    /// Frame `i`, solved to `q`, with `s.ws` at `q`.
    pub fn record(&mut self, s: &Solver, t: &Targets, i: usize, q: &[f64], used: usize) {
        let (robot, plan, ws) = (s.robot(), s.plan(), &s.ws);
        let mut qpos = Vec::new();
        robot.qpos(&ws.body_rot[0], &ws.body_pos[0], q, &mut qpos);
        self.qpos.push(qpos);
        self.body_pos.push(ws.body_pos.iter().map(|p| [p.x, p.y, p.z]).collect());
        let pose = |(r, p): (&nalgebra::Matrix3<f64>, &Vector3<f64>)| {
            (UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r)), *p)
        };
        self.poses.push(ws.body_rot.iter().zip(&ws.body_pos).map(pose).collect());
        for (k, task) in plan.tasks.iter().enumerate() {
            self.errors[k].push((ws.body_pos[task.robot_body] - t.pos[i][k]).norm());
        }
        for (k, f) in plan.feet.iter().enumerate() {
            let low = s.lowest_of(f.robot_body);
            self.feet[k].push((ws.body_pos[f.robot_body], low));
        }
        let closest = s.frame_closest();
        self.closest.push(closest);
        self.iterations += used;
    }

    /// The motion, the judged report and the body poses.
    #[allow(clippy::too_many_arguments)]
    pub fn finish(
        self,
        robot: &Robot,
        plan: &Plan,
        human: &Human,
        t: &Targets,
        q: &[Vec<f64>],
        fps: f64,
        settings: &RetargetSettings,
        name: &str,
    ) -> (RobotMotion, Report, BodyPoses) {
        let n = q.len();
        let rm = &robot.model;
        let hname = |b: usize| human.model.bodies[b].name.clone();
        let tracking: Vec<Tracking> = plan
            .tasks
            .iter()
            .zip(&self.errors)
            .filter(|(task, _)| task.w_pos > 0.0)
            .map(|(task, e)| {
                let [median, p95] = quantiles(e, [0.5, 0.95]);
                Tracking {
                    robot: rm.bodies[task.robot_body].name.clone(),
                    human: hname(task.human_body),
                    median_mm: median * 1e3,
                    p95_mm: p95 * 1e3,
                }
            })
            .collect();
        // End effectors: the root and every position task no other task hangs from.
        let leaves: Vec<f64> = (0..plan.tasks.len())
            .filter(|&k| plan.tasks[k].w_pos > 0.0)
            .filter(|&k| k == 0 || !plan.tasks.iter().any(|c| c.parent == Some(k) && c.w_pos > 0.0))
            .flat_map(|k| self.errors[k].iter().copied())
            .collect();
        let (mut range_violations, mut velocity_violations) = (0, 0);
        for i in 0..n {
            for &j in &robot.joints {
                let (lo, hi) = rm.coordinates[j].range;
                range_violations += usize::from(q[i][j] < lo - 1e-9 || q[i][j] > hi + 1e-9);
                if i > 0 {
                    let dt = human.times[i] - human.times[i - 1];
                    velocity_violations += usize::from((q[i][j] - q[i - 1][j]).abs() > robot.velocity[j] * dt + 1e-9);
                }
            }
        }
        let feet = plan
            .feet
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let track = &self.feet[k];
                let slides: Vec<f64> = (1..n)
                    .filter(|&i| t.contact[i][k] && t.contact[i - 1][k])
                    .map(|i| {
                        let d = track[i].0 - track[i - 1].0;
                        d.xy().norm() / (human.times[i] - human.times[i - 1]).max(1e-9)
                    })
                    .collect();
                let depth: Vec<f64> = track.iter().map(|(_, low)| (-low).max(0.0)).collect();
                FootReport {
                    robot: rm.bodies[f.robot_body].name.clone(),
                    contact_frames: t.contact.iter().filter(|c| c[k]).count(),
                    slide_mean_m_s: if slides.is_empty() {
                        0.0
                    } else {
                        slides.iter().sum::<f64>() / slides.len() as f64
                    },
                    slide_max_m_s: slides.iter().copied().fold(0.0, f64::max),
                    penetration_max_m: depth.iter().copied().fold(0.0, f64::max),
                    penetration_frames: depth.iter().filter(|&&d| d > 0.0).count(),
                }
            })
            .collect();
        let dt = if fps > 0.0 { 1.0 / fps } else { 1.0 };
        let mut jerk = (0.0, 0usize);
        for i in 3..n {
            for &j in &robot.joints {
                let d3 = q[i][j] - 3.0 * q[i - 1][j] + 3.0 * q[i - 2][j] - q[i - 3][j];
                jerk = (jerk.0 + (d3 / dt.powi(3)).powi(2), jerk.1 + 1);
            }
        }
        let mut report = Report {
            trial: name.to_string(),
            robot: rm.name.clone(),
            frames: n,
            fps,
            status: String::new(),
            reasons: Vec::new(),
            scale: plan.tasks.iter().skip(1).map(|t| (rm.bodies[t.robot_body].name.clone(), t.ratio)).collect(),
            leg_ratio: plan.leg_ratio,
            tracking,
            end_effector_median_mm: quantiles(&leaves, [0.5])[0] * 1e3,
            non_finite_frames: q.iter().filter(|f| f.iter().any(|v| !v.is_finite())).count(),
            range_violations,
            velocity_violations,
            feet,
            self_collision_frames: self.closest.iter().filter(|&&d| d < 0.0).count(),
            self_collision_max_m: self.closest.iter().map(|d| (-d).max(0.0)).fold(0.0, f64::max),
            jerk_rms: if jerk.1 > 0 { (jerk.0 / jerk.1 as f64).sqrt() } else { 0.0 },
            iterations_mean: self.iterations as f64 / n.max(1) as f64,
            settings: serde_json::to_value(settings).unwrap_or_default(),
            ignored_geoms: robot.ignored_geoms.clone(),
        };
        report.judge();
        let motion = RobotMotion {
            fps,
            joint_names: robot.joint_names.clone(),
            qpos: self.qpos,
            body_names: rm.bodies.iter().map(|b| b.name.clone()).collect(),
            body_pos_w: self.body_pos,
        };
        (motion, report, self.poses)
    }
}

/// The `p`-quantiles (nearest rank) of `v`, sorted once; 0 when empty.
fn quantiles<const N: usize>(v: &[f64], p: [f64; N]) -> [f64; N] {
    if v.is_empty() {
        return [0.0; N];
    }
    let mut s = v.to_vec();
    s.sort_unstable_by(f64::total_cmp);
    p.map(|p| s[((s.len() - 1) as f64 * p).round() as usize])
}
