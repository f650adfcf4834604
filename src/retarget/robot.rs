//! A robot read from its MJCF: the kinematic [`Model`] (a free-joint root and hinge joints),
//! its collision spheres and capsules, the pairs of them that may collide, joint ranges and
//! velocity limits, and the conversion of its coordinates to MuJoCo's `qpos`.

use super::mapping::Mapping;
use super::RetargetError;
use crate::io::mjcf::{parse_mjcf_document, read_mjcf_document, GeomShape, MjcfDocument};
use crate::model::{CoordinateKind, Model};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// A collision capsule on a robot body, in the body's frame (m); a sphere has `a == b`.
#[derive(Clone, Debug)]
pub struct Capsule {
    pub name: String,
    pub body: usize,
    pub a: Vector3<f64>,
    pub b: Vector3<f64>,
    pub radius: f64,
}

/// The robot, immutable once read.
#[derive(Clone, Debug)]
pub struct Robot {
    /// Kinematics (scales all 1): coordinates 0..6 are the root's free joint (x, y, z, then
    /// z-y-x rotations), the rest one per hinge joint in MJCF order (= MuJoCo's `qpos[7..]`).
    pub model: Model,
    /// Hinge joint names, in `qpos[7..]` order.
    pub joint_names: Vec<String>,
    /// Coordinate index of each hinge joint.
    pub joints: Vec<usize>,
    /// Velocity limit of each coordinate (rad/s or m/s; ∞ for the root).
    pub velocity: Vec<f64>,
    pub capsules: Vec<Capsule>,
    /// Capsule index pairs that may collide (MuJoCo's rules: different bodies, not parent and
    /// child, not excluded, compatible `contype`/`conaffinity`).
    pub pairs: Vec<(usize, usize)>,
    /// Colliding geoms of other shapes, not modelled (named for the report).
    pub ignored_geoms: Vec<String>,
}

impl Robot {
    /// Reads the mapping's robot MJCF and checks that its root is a free joint and every other
    /// joint a hinge.
    pub fn load(mapping: &Mapping) -> Result<Robot, RetargetError> {
        let doc = read_mjcf_document(&mapping.robot).map_err(|e| RetargetError::Robot(e.to_string()))?;
        Robot::from_document(doc, &mapping.robot.display().to_string(), mapping)
    }

    /// [`Robot::load`] of MJCF text (`file` names it in messages).
    pub fn from_text(text: &str, file: &str, mapping: &Mapping) -> Result<Robot, RetargetError> {
        let doc = parse_mjcf_document(text, file).map_err(|e| RetargetError::Robot(e.to_string()))?;
        Robot::from_document(doc, file, mapping)
    }

    fn from_document(doc: MjcfDocument, file: &str, mapping: &Mapping) -> Result<Robot, RetargetError> {
        let model = doc.model;
        let bad = |what: String| RetargetError::Robot(format!("{file}: {what}"));
        let free = model.bodies.first().map(|b| b.joint.motions.len()) == Some(6) && model.nq() >= 6;
        if !free || model.coordinates[..3].iter().any(|c| c.kind != CoordinateKind::Translational) {
            return Err(bad("the first body needs a free joint (a floating base)".into()));
        }
        if let Some(b) = model.bodies.iter().skip(1).find(|b| b.parent.is_none()) {
            return Err(bad(format!("body '{}' hangs from the world: one floating tree expected", b.name)));
        }
        let mut joints = Vec::new();
        for (i, c) in model.coordinates.iter().enumerate().skip(6) {
            if c.kind != CoordinateKind::Rotational {
                return Err(bad(format!("joint '{}' is not a hinge (slide joints are not supported)", c.name)));
            }
            joints.push(i);
        }
        let joint_names: Vec<String> = joints.iter().map(|&i| model.coordinates[i].name.clone()).collect();
        let mut velocity = vec![f64::INFINITY; model.nq()];
        let limits = mapping.velocity_limits(joints.iter().map(|&i| model.coordinates[i].name.as_str()));
        for (&i, v) in joints.iter().zip(limits) {
            velocity[i] = v;
        }
        let (mut capsules, mut ignored_geoms, mut flags) = (Vec::new(), Vec::new(), Vec::new());
        for g in doc.geoms {
            let (a, b, radius) = match g.shape {
                GeomShape::Sphere { centre, radius } => (centre, centre, radius),
                GeomShape::Capsule { a, b, radius } => (a, b, radius),
                GeomShape::Other(kind) => {
                    ignored_geoms.push(format!("{} ({kind})", g.name));
                    continue;
                }
            };
            capsules.push(Capsule { name: g.name, body: g.body, a, b, radius });
            flags.push((g.contype, g.conaffinity));
        }
        let excluded: Vec<(usize, usize)> =
            doc.excludes.iter().filter_map(|(a, b)| Some((model.body_index(a)?, model.body_index(b)?))).collect();
        let pairs = collision_pairs(&model, &capsules, &flags, &excluded);
        Ok(Robot { model, joint_names, joints, velocity, capsules, pairs, ignored_geoms })
    }

    /// The state vector `[q; s]` (unit scales) with `q` copied in.
    pub fn state(&self, q: &[f64], y: &mut Vec<f64>) {
        y.clear();
        y.extend_from_slice(q);
        y.resize(self.model.ny(), 1.0);
    }

    /// Body index by name, or an error naming the robot's bodies.
    pub fn body(&self, name: &str) -> Result<usize, RetargetError> {
        self.model.body_index(name).ok_or_else(|| {
            let all: Vec<&str> = self.model.bodies.iter().map(|b| b.name.as_str()).collect();
            RetargetError::Mapping(format!("robot has no body '{name}'; its bodies: {}", all.join(", ")))
        })
    }

    /// MuJoCo `qpos` (root position, root quaternion w x y z, joints) from the root body's
    /// world pose and the coordinates.
    pub fn qpos(&self, root_rot: &Matrix3<f64>, root_pos: &Vector3<f64>, q: &[f64], out: &mut Vec<f64>) {
        // The root's orientation from forward kinematics is orthonormal to rounding.
        let quat = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*root_rot));
        let quat = if quat.w < 0.0 { -quat.into_inner() } else { quat.into_inner() };
        out.clear();
        out.extend_from_slice(root_pos.as_slice());
        out.extend_from_slice(&[quat.w, quat.i, quat.j, quat.k]);
        out.extend(self.joints.iter().map(|&i| q[i]));
    }
}

/// Capsule pairs that MuJoCo would test: on different bodies that are not parent and child,
/// not excluded, with `contype₁ & conaffinity₂ ≠ 0` or the converse.
fn collision_pairs(
    model: &Model,
    caps: &[Capsule],
    flags: &[(u32, u32)],
    excluded: &[(usize, usize)],
) -> Vec<(usize, usize)> {
    let mut pairs = Vec::new();
    for i in 0..caps.len() {
        for j in i + 1..caps.len() {
            let (a, b) = (caps[i].body, caps[j].body);
            let related = a == b || model.bodies[a].parent == Some(b) || model.bodies[b].parent == Some(a);
            let skip = excluded.contains(&(a, b)) || excluded.contains(&(b, a));
            let (f, g) = (flags[i], flags[j]);
            if !related && !skip && (f.0 & g.1 != 0 || g.0 & f.1 != 0) {
                pairs.push((i, j));
            }
        }
    }
    pairs
}
