//! A retargeted trial as the MCAP file shows it ([`crate::archive::mcap_robot`]): every robot
//! body's world pose per frame ([`super::Retargeted::poses`]) and the robot's collision capsules.

use super::{Report, Robot};
use crate::archive::mcap_robot::{BodyPoses, RobotTrack, TrackCapsule};
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// The track of a retargeted motion with body `poses` ([`super::Retargeted::poses`]) and `report`
/// (retargeted from the human frames `frames`, one per robot frame) for a robot called `name`
/// (its frame prefix), its world `offset` (m) from the human's `world`.
pub fn track(
    robot: &Robot,
    name: &str,
    (poses, report): (BodyPoses, &Report),
    frames: &[usize],
    offset: Vector3<f64>,
) -> RobotTrack {
    let model = &robot.model;
    RobotTrack {
        name: name.to_string(),
        bodies: model.bodies.iter().map(|b| b.name.clone()).collect(),
        parents: model.bodies.iter().map(|b| b.parent).collect(),
        frames: frames.to_vec(),
        poses,
        capsules: robot
            .capsules
            .iter()
            .map(|c| TrackCapsule { body: c.body, a: c.a, b: c.b, radius: c.radius })
            .collect(),
        offset,
        metadata: summary(report),
    }
}

/// The report's headline figures, for the file's `smocap.robot` record.
pub fn summary(r: &Report) -> BTreeMap<String, String> {
    [
        ("model", r.robot.clone()),
        ("status", r.status.clone()),
        ("reasons", r.reasons.join("; ")),
        ("frames", r.frames.to_string()),
        ("fps", r.fps.to_string()),
        ("end_effector_median_mm", format!("{:.2}", r.end_effector_median_mm)),
        ("range_violations", r.range_violations.to_string()),
        ("velocity_violations", r.velocity_violations.to_string()),
        ("self_collision_frames", r.self_collision_frames.to_string()),
        ("settings", r.settings.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}
