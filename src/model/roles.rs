//! What a marker is on the body, from its name: a bony landmark, a wand, a cluster marker or a
//! computed joint centre ([`MarkerRole`]), read from the shipped table
//! `models/markers/roles.toml` (which documents the matching). Calibration registers landmarks
//! within millimetres and the rest freely ([`super::marker_classes`]).

use super::MarkerClass;
use serde::{Deserialize, Serialize};

/// The shipped role table.
pub const SHIPPED_ROLES: &str = include_str!("../../models/markers/roles.toml");

/// What a marker is on the body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MarkerRole {
    /// On a bony landmark.
    Landmark,
    /// On a wand or a segment's shaft, placed by eye.
    Wand,
    /// One of a segment's cluster.
    Cluster,
    /// A point computed by other software (a regression joint centre, a ground projection).
    JointCentre,
}

impl MarkerRole {
    /// How registration treats a marker of this role.
    pub fn class(self) -> MarkerClass {
        match self {
            MarkerRole::Landmark => MarkerClass::Anatomical,
            _ => MarkerClass::Tracking,
        }
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    role: MarkerRole,
    what: String,
    names: Vec<String>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    role: Vec<Entry>,
}

/// A role table: name patterns to roles, first match wins.
#[derive(Clone, Debug)]
pub struct RoleTable {
    entries: Vec<Entry>,
}

/// A name upper-cased with everything but letters and digits removed.
fn normalise(name: &str) -> String {
    name.chars().filter(|c| c.is_ascii_alphanumeric()).map(|c| c.to_ascii_uppercase()).collect()
}

/// The name without its side: a leading `L`/`R`/`LEFT`/`RIGHT`, or a trailing `L`/`R`/`LEFT`/
/// `RIGHT` after a separator (`ASIS_r`); candidates, longest side word first.
fn without_side(name: &str) -> Vec<String> {
    let mut out = Vec::new();
    let n = normalise(name);
    for side in ["LEFT", "RIGHT", "L", "R"] {
        if let Some(rest) = n.strip_prefix(side).filter(|r| !r.is_empty()) {
            out.push(rest.to_string());
        }
    }
    if let Some((head, tail)) = name.rsplit_once(|c: char| !c.is_ascii_alphanumeric()) {
        if ["L", "R", "LEFT", "RIGHT"].contains(&tail.to_ascii_uppercase().as_str()) && !head.is_empty() {
            out.push(normalise(head));
        }
    }
    out
}

/// Whether `name` (normalised) matches `pattern` (a stem, `*` at either end for any text, `#` at
/// the end for one or more digits).
fn matches(pattern: &str, name: &str) -> bool {
    if let Some(stem) = pattern.strip_suffix('#') {
        return name.strip_prefix(stem).is_some_and(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()));
    }
    match (pattern.strip_prefix('*'), pattern.strip_suffix('*')) {
        (Some(tail), _) => name.ends_with(tail),
        (_, Some(head)) => name.starts_with(head),
        _ => pattern == name,
    }
}

impl RoleTable {
    /// Parses a table (the format of `models/markers/roles.toml`); `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<RoleTable, String> {
        let f: File = toml::from_str(text).map_err(|e| format!("{file}: {e}"))?;
        Ok(RoleTable { entries: f.role })
    }

    /// The shipped table.
    pub fn shipped() -> RoleTable {
        RoleTable::parse(SHIPPED_ROLES, "models/markers/roles.toml").expect("the shipped role table parses")
    }

    /// The role of a marker called `name`, and what the table says it is on; `None` when no
    /// entry matches (as written first, then without its side).
    pub fn role_of(&self, name: &str) -> Option<(MarkerRole, &str)> {
        let find = |n: &str| {
            self.entries.iter().find(|e| e.names.iter().any(|p| matches(p, n))).map(|e| (e.role, e.what.as_str()))
        };
        find(&normalise(name)).or_else(|| without_side(name).iter().find_map(|n| find(n)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn common_spellings_of_one_landmark_have_one_role() {
        let t = RoleTable::shipped();
        for n in ["RASI", "r.ASIS", "L.ASIS", "R_ASIS", "LFWT", "ASIS_r"] {
            assert_eq!(t.role_of(n).map(|r| r.1), Some("anterior superior iliac spine"), "{n}");
        }
        for n in ["LKNE", "r_knee", "R.Knee.Lat", "L_mknee", "RLFC", "R.MKnee"] {
            assert_eq!(t.role_of(n).map(|r| r.1), Some("femoral epicondyle"), "{n}");
        }
        for n in ["RHEE", "L_calc", "R.Heel", "RCAL", "LTOE", "r_5meta", "R.MT5"] {
            assert_eq!(t.role_of(n).map(|r| r.0), Some(MarkerRole::Landmark), "{n}");
        }
    }

    #[test]
    fn wands_clusters_and_computed_centres_are_not_landmarks() {
        let t = RoleTable::shipped();
        for (n, role) in [
            ("LTHI", MarkerRole::Wand),
            ("RTIB", MarkerRole::Wand),
            ("LSHN", MarkerRole::Wand),
            ("r_thigh3", MarkerRole::Cluster),
            ("R.TH1", MarkerRole::Cluster),
            ("r_sh2", MarkerRole::Cluster),
            ("r_shank_antsup", MarkerRole::Cluster),
            ("R.Thigh.Upper", MarkerRole::Cluster),
            ("R_HJC", MarkerRole::JointCentre),
            ("L.HeelGround", MarkerRole::JointCentre),
            ("RKJC", MarkerRole::JointCentre),
        ] {
            assert_eq!(t.role_of(n).map(|r| r.0), Some(role), "{n}");
        }
    }

    #[test]
    fn trunk_markers_without_a_side_match_as_written() {
        let t = RoleTable::shipped();
        for n in ["C7", "T10", "STRN", "CLAV", "SACR", "S2", "V.Sacral"] {
            assert_eq!(t.role_of(n).map(|r| r.0), Some(MarkerRole::Landmark), "{n}");
        }
        assert_eq!(t.role_of("RSHO").map(|r| r.1), Some("acromion"));
        assert_eq!(t.role_of("XYZ_unknown"), None);
    }
}
