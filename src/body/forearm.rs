//! The forearm's roll in the bind pose ([`ForearmRoll`]): the joint centres leave pronation
//! free, so a residual turns each radius until the model's hand lies as the mesh's does.

use super::asset::{BodyAsset, BodyShape};
use super::segments::SegmentMap;
use crate::kinematics::cpu::{forward, Workspace};
use crate::model::{Model, MotionKind};
use nalgebra::{Matrix3, Vector3};

/// Weight of a forearm's roll residual (m per unit of direction error: 0.1 makes 10° cost
/// about as much as 17 mm of joint-centre error).
const ROLL_WEIGHT: f64 = 0.1;

/// The roll of a forearm in the bind pose. The joint centres leave pronation free, so the
/// mesh's hand (palm toward the thigh in the A-pose) would otherwise hang on a model hand at its
/// default pronation (supinated in OpenSim's arm models, 90° away). The residual is
/// `ROLL_WEIGHT · (R_radius u − r)`: `r` is the mesh's radial direction (little-finger knuckle
/// to index knuckle) and `u` the model's, in the radius frame, both made perpendicular to the
/// pronation axis. The model's radial direction is its wrist flexion axis (a coordinate of the
/// hand's joint named `*flex*`; flexion turns the right hand about its radial direction, the
/// left about its ulnar one); where the hand is welded, the wrist centre's offset from the
/// pronation axis, which lies toward the radius (on Rajagopal's and the shipped arm it is 18°
/// and 32° from the flexion axis).
pub(super) struct ForearmRoll {
    radius: usize,
    /// The model's radial direction and the pronation axis (radius frame, unit, perpendicular).
    radial_local: Vector3<f64>,
    axis: Vector3<f64>,
    /// The mesh's radial direction (model frame, unit).
    radial: Vector3<f64>,
}

impl ForearmRoll {
    pub(super) fn residual(&self, ws: &Workspace) -> Vector3<f64> {
        let rot = ws.body_rot[self.radius];
        let a = rot * self.axis;
        let target = (self.radial - a * a.dot(&self.radial)).try_normalize(1e-9).unwrap_or(self.radial);
        (rot * self.radial_local - target) * ROLL_WEIGHT
    }
}

/// The forearms whose radius turns on one unlocked coordinate and carries a hand body: their
/// [`ForearmRoll`]s, each axis found by turning its coordinate a little at `y0`.
pub(super) fn forearm_rolls(
    model: &Model,
    map: &SegmentMap,
    asset: &BodyAsset,
    shape: &BodyShape,
    model_from_world: &Matrix3<f64>,
    y0: &[f64],
) -> Vec<ForearmRoll> {
    let mut ws0 = Workspace::new(model);
    let mut ws1 = Workspace::new(model);
    forward(model, y0, &mut ws0);
    // the world axis `body` turns about, and the velocity of `point`'s origin, as `coord` turns
    let mut turn = |coord: usize, body: usize, point: usize| -> Option<(Vector3<f64>, Vector3<f64>)> {
        let h = 1e-6;
        let mut y1 = y0.to_vec();
        y1[coord] += h;
        forward(model, &y1, &mut ws1);
        let d = (ws1.body_rot[body] * ws0.body_rot[body].transpose() - Matrix3::identity()) / h;
        let axis = Vector3::new(d[(2, 1)] - d[(1, 2)], d[(0, 2)] - d[(2, 0)], d[(1, 0)] - d[(0, 1)]);
        Some((axis.try_normalize(1e-6)?, (ws1.body_pos[point] - ws0.body_pos[point]) / h))
    };
    let rotations = |body: usize, unlocked: bool| -> Vec<usize> {
        model.motions[model.bodies[body].joint.motions.clone()]
            .iter()
            .filter(|m| m.kind == MotionKind::Rotation)
            .filter_map(|m| m.coordinate)
            .filter(|&c| !(unlocked && model.coordinates[c].locked))
            .collect()
    };
    let owned = |s: &str| asset.segment_index(s).filter(|&i| map.own[i]).map(|i| map.host[i]);
    let mut out = Vec::new();
    for (side, sign) in [('r', 1.0), ('l', -1.0)] {
        let (Some(radius), Some(hand)) = (owned(&format!("radius_{side}")), owned(&format!("hand_{side}"))) else {
            continue;
        };
        let cube =
            |n: &str| asset.joint_index(&format!("joint-{side}-{n}")).map(|j| model_from_world * shape.joints[j]);
        let (Some(index), Some(little)) = (cube("finger-2-1"), cube("finger-5-1")) else { continue };
        let [pronation] = rotations(radius, true)[..] else { continue };
        let Some((axis, wrist_velocity)) = turn(pronation, radius, hand) else { continue };
        let flexion = rotations(hand, false).into_iter().find(|&c| model.coordinates[c].name.contains("flex"));
        let radial_world = match flexion.and_then(|c| turn(c, hand, hand)) {
            Some((flex_axis, _)) => flex_axis * sign,
            None => wrist_velocity.cross(&axis),
        };
        let Some(radial_world) = (radial_world - axis * axis.dot(&radial_world)).try_normalize(1e-6) else { continue };
        let Some(radial) = (index - little).try_normalize(1e-9) else { continue };
        let back = ws0.body_rot[radius].transpose();
        out.push(ForearmRoll { radius, radial_local: back * radial_world, axis: back * axis, radial });
    }
    out
}
