//! Which human body drives which robot body: our TOML mapping, and GMR's `ik_match_table` JSON
//! read as it is.
//!
//! ```toml
//! robot = "g1.xml"                  # the robot's MJCF, relative to this file
//! [reference]                       # robot joint angles (rad) of the posture the human model
//! left_elbow_joint = 1.5708         #   has at all-zero coordinates; unnamed joints: 0
//! [velocity]                        # joint velocity limits (rad/s), glob patterns → value
//! "*_knee_joint" = 20.0
//! [[task]]                          # robot body ← human body
//! robot = "left_knee_link"
//! human = "tibia_l"
//! position = 1.0                    # weight on the position error (per m²); 0: none
//! orientation = 0.0                 # weight on the orientation error (per rad²); 0: none
//! [[foot]]                          # a foot that can be planted
//! robot = "left_ankle_roll_link"
//! heel = "calcn_l"                  # human bodies whose joint centres say "low and slow"
//! toe = "toes_l"
//! ```

use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Errors reading a mapping file.
#[derive(Debug, thiserror::Error)]
pub enum MappingError {
    #[error("{file}: cannot read: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}: {message}")]
    Parse { file: String, message: String },
}

/// One robot body driven by one human body.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Task {
    /// Robot body name (MJCF).
    pub robot: String,
    /// Human model body name; its joint centre is the tracked point.
    pub human: String,
    /// Weight on the squared position error (per m²).
    #[serde(default)]
    pub position: f64,
    /// Weight on the squared orientation error (per rad²).
    #[serde(default)]
    pub orientation: f64,
}

/// A robot foot and the human bodies that tell when it is planted.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Foot {
    /// Robot body carrying the sole's collision geoms.
    pub robot: String,
    /// Human heel body (e.g. `calcn_l`).
    pub heel: String,
    /// Human toe body (e.g. `toes_l`).
    pub toe: String,
}

/// A human → robot mapping.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Mapping {
    /// The robot's MJCF (resolved against the mapping file's folder).
    pub robot: PathBuf,
    /// Robot joint angles (rad) matching the human model at zero coordinates.
    #[serde(default)]
    pub reference: BTreeMap<String, f64>,
    /// Joint velocity limits (rad/s) by glob pattern over joint names; patterns should not
    /// overlap (where they do, the first in sorted order counts).
    #[serde(default)]
    pub velocity: BTreeMap<String, f64>,
    #[serde(rename = "task")]
    pub tasks: Vec<Task>,
    #[serde(rename = "foot", default)]
    pub feet: Vec<Foot>,
}

impl Mapping {
    /// Reads a mapping: our TOML, or (`.json`) GMR's `ik_match_table` ([`Mapping::from_gmr`]).
    pub fn read(path: &Path) -> Result<Mapping, MappingError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| MappingError::Io { file: file.clone(), source })?;
        let parse = |message: String| MappingError::Parse { file: file.clone(), message };
        let mut m = if path.extension().is_some_and(|e| e == "json") {
            Mapping::from_gmr(&text).map_err(parse)?
        } else {
            toml::from_str::<Mapping>(&text).map_err(|e| parse(e.to_string()))?
        };
        if m.robot.is_relative() {
            m.robot = path.parent().unwrap_or(Path::new(".")).join(&m.robot);
        }
        Ok(m)
    }

    /// A GMR `ik_match_table` config (`{"robot_root_name", "ik_match_table1": {robot body: [human
    /// body, position weight, rotation weight, offset, quaternion]}, "ik_match_table2": …}`):
    /// the robot bodies and weights of its final stage (table 2 when `use_ik_match_table2`, else
    /// table 1), the SMPL-X joint names translated to OpenSim bodies ([`SMPLX_TO_OPENSIM`]), and
    /// a foot wherever a robot body follows SMPL-X's `left_foot`/`right_foot`. GMR's position and
    /// rotation offsets are for SMPL-X frames and are not used: the orientation offsets come
    /// from the reference postures (all-zero here: add a `[reference]` with our TOML if the
    /// robot's zero posture is not standing with arms down). GMR's file names no robot MJCF:
    /// `robot` is left empty for the caller (`--mjcf`).
    pub fn from_gmr(text: &str) -> Result<Mapping, String> {
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| e.to_string())?;
        let second = v.get("use_ik_match_table2").and_then(|b| b.as_bool()).unwrap_or(false);
        let table = [second.then_some("ik_match_table2"), Some("ik_match_table1")]
            .into_iter()
            .flatten()
            .find_map(|k| v.get(k).and_then(|t| t.as_object()))
            .ok_or("no `ik_match_table1` object: not a GMR ik config")?;
        let (mut tasks, mut feet) = (Vec::new(), Vec::new());
        for (robot, entry) in table {
            let e = entry.as_array().ok_or_else(|| format!("`{robot}`: expected [human, pos_w, rot_w, ...]"))?;
            let smplx = e.first().and_then(|h| h.as_str()).ok_or_else(|| format!("`{robot}`: no human name"))?;
            let human = SMPLX_TO_OPENSIM
                .iter()
                .find(|(s, _)| *s == smplx)
                .map(|(_, o)| o.to_string())
                .ok_or_else(|| format!("`{robot}`: SMPL-X joint `{smplx}` has no OpenSim body here"))?;
            let w = |i: usize| e.get(i).and_then(|x| x.as_f64()).unwrap_or(0.0);
            if let Some(side) = smplx.strip_suffix("_foot") {
                let s = if side == "left" { "l" } else { "r" };
                feet.push(Foot { robot: robot.clone(), heel: format!("calcn_{s}"), toe: format!("toes_{s}") });
            }
            tasks.push(Task { robot: robot.clone(), human, position: w(1), orientation: w(2) });
        }
        // GMR's weights are 0–100 on errors in m and rad: ours are relative, the largest 1.
        let top = tasks.iter().map(|t| t.position.max(t.orientation)).fold(0.0, f64::max).max(1e-12);
        for t in &mut tasks {
            t.position /= top;
            t.orientation /= top;
        }
        Ok(Mapping { robot: PathBuf::new(), reference: BTreeMap::new(), velocity: BTreeMap::new(), tasks, feet })
    }

    /// Velocity limits (rad/s) of the joints `names`: each the first matching pattern's (in the
    /// patterns' order), else unlimited. Each pattern is compiled once; an invalid one matches
    /// nothing.
    pub fn velocity_limits<'n>(&self, names: impl IntoIterator<Item = &'n str>) -> Vec<f64> {
        let matchers: Vec<(globset::GlobMatcher, f64)> = self
            .velocity
            .iter()
            .filter_map(|(pat, &v)| globset::Glob::new(pat).ok().map(|g| (g.compile_matcher(), v)))
            .collect();
        let limit = |name: &str| matchers.iter().find(|(m, _)| m.is_match(name)).map_or(f64::INFINITY, |(_, v)| *v);
        names.into_iter().map(limit).collect()
    }
}

/// SMPL-X joint names (GMR's human bodies) → OpenSim full-body bodies.
pub const SMPLX_TO_OPENSIM: [(&str, &str); 19] = [
    ("pelvis", "pelvis"),
    ("left_hip", "femur_l"),
    ("right_hip", "femur_r"),
    ("left_knee", "tibia_l"),
    ("right_knee", "tibia_r"),
    ("left_ankle", "talus_l"),
    ("right_ankle", "talus_r"),
    ("left_foot", "calcn_l"),
    ("right_foot", "calcn_r"),
    ("spine3", "torso"),
    ("spine2", "torso"),
    ("left_shoulder", "humerus_l"),
    ("right_shoulder", "humerus_r"),
    ("left_elbow", "ulna_l"),
    ("right_elbow", "ulna_r"),
    ("left_wrist", "hand_l"),
    ("right_wrist", "hand_r"),
    ("head", "head"),
    ("neck", "torso"),
];
