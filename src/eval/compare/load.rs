//! Reading the two sides of a comparison into [`Motion`]s: OpenSim `.mot` / `.sto` tables
//! (smocap's, OpenSim's or AddBiomechanics' IK), converted trials (`.mcap`, the state channel),
//! and angle points of a C3D file (Plug-in Gait's `LKneeAngles`, …) through an [`AngleMap`].
//!
//! Rotational coordinates come out in degrees, translations in millimetres. In a table, a
//! column is a translation when its name ends in `_tx`, `_ty` or `_tz` (OpenSim's naming), and
//! rotations are converted from radians when the header says `inDegrees=no`.

use super::{Motion, Quantity, Series, Window};
use crate::io::markers::units_to_metres;
use serde::Deserialize;
use std::path::Path;

/// The shipped maps from angle outputs to coordinate names, by name: Plug-in Gait to the shipped
/// model's coordinates, and to OpenSim's Rajagopal family (whose pelvis tilt has the other sign).
pub const SHIPPED_MAPS: &[(&str, &str)] = &[
    ("plugingait", include_str!("../../../models/compare/plugingait.toml")),
    ("plugingait-opensim", include_str!("../../../models/compare/plugingait-opensim.toml")),
];

/// Errors reading a side of a comparison.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error(transparent)]
    Sto(#[from] crate::io::sto::StoError),
    #[error(transparent)]
    Markers(#[from] crate::io::MarkerFileError),
    #[error(transparent)]
    Mcap(#[from] crate::archive::export::ExportError),
    #[error("{file}: no time column (columns: {columns})")]
    NoTime { file: String, columns: String },
    #[error("angle map {file}: {message}")]
    Map { file: String, message: String },
    #[error("{file}: none of the angle map's points is in the file (the map looks for {wanted}; the file has {has})")]
    NoAngles { file: String, wanted: String, has: String },
    #[error("{file}: unknown kind of motion file (expected .mot, .sto, .mcap or .c3d)")]
    UnknownKind { file: String },
}

/// Whether a coordinate called `name` is a translation (OpenSim's `_tx`/`_ty`/`_tz` naming).
pub fn is_translation(name: &str) -> bool {
    name.ends_with("_tx") || name.ends_with("_ty") || name.ends_with("_tz")
}

/// One coordinate read from a component of a C3D angle point.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AngleEntry {
    /// The coordinate it gives (OpenSim-style name).
    pub coordinate: String,
    /// Point labels to look for, the first present wins (with or without a `Subject:` prefix).
    pub points: Vec<String>,
    /// Component of the point: 0 = x, 1 = y, 2 = z.
    pub component: usize,
    /// Multiplies the value (−1 where the two conventions' positive directions differ).
    #[serde(default = "one")]
    pub sign: f64,
}

fn one() -> f64 {
    1.0
}

/// Which C3D angle points give which coordinates.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AngleMap {
    pub angle: Vec<AngleEntry>,
}

impl AngleMap {
    /// Parses a map (TOML, the format of `models/compare/plugingait.toml`); `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<AngleMap, LoadError> {
        let map: AngleMap =
            toml::from_str(text).map_err(|e| LoadError::Map { file: file.into(), message: e.to_string() })?;
        if let Some(e) = map.angle.iter().find(|e| e.component > 2) {
            return Err(LoadError::Map {
                file: file.into(),
                message: format!("{}: component {} (expected 0, 1 or 2: x, y, z)", e.coordinate, e.component),
            });
        }
        Ok(map)
    }

    /// The shipped Plug-in Gait map for the shipped model.
    pub fn plug_in_gait() -> AngleMap {
        AngleMap::shipped("plugingait").expect("the shipped map exists")
    }

    /// The shipped map called `name` ([`SHIPPED_MAPS`]).
    pub fn shipped(name: &str) -> Option<AngleMap> {
        SHIPPED_MAPS
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(n, text)| AngleMap::parse(text, &format!("models/compare/{n}.toml")).expect("shipped maps parse"))
    }
}

/// Reads a motion file by its extension; C3D angle points go through `map` (the Plug-in Gait
/// map when `None`).
pub fn load_motion(path: &Path, map: Option<&AngleMap>) -> Result<Motion, LoadError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "mot" | "sto" => motion_from_table(&crate::io::sto::read_sto(path)?, &path.display().to_string()),
        "mcap" => motion_from_mcap(path),
        "c3d" => {
            let pig;
            let map = match map {
                Some(m) => m,
                None => {
                    pig = AngleMap::plug_in_gait();
                    &pig
                }
            };
            angles_from_markers(&crate::io::read_markers(path)?, map, &path.display().to_string())
        }
        _ => Err(LoadError::UnknownKind { file: path.display().to_string() }),
    }
}

/// The coordinates of an OpenSim table (`time` first or anywhere).
pub fn motion_from_table(t: &crate::io::sto::Table, file: &str) -> Result<Motion, LoadError> {
    let time =
        t.column("time").ok_or_else(|| LoadError::NoTime { file: file.into(), columns: t.columns.join(", ") })?;
    // OpenSim writes `inDegrees=yes` for IK results; a table that does not say is taken as
    // degrees, as OpenSim's own readers do.
    let to_deg = if t.in_degrees() == Some(false) { 180.0 / std::f64::consts::PI } else { 1.0 };
    let series = t
        .columns
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != time)
        .map(|(i, name)| {
            let (quantity, k) =
                if is_translation(name) { (Quantity::Length, 1000.0) } else { (Quantity::Angle, to_deg) };
            Series { name: name.clone(), quantity, values: t.rows.iter().map(|r| r[i] * k).collect() }
        })
        .collect();
    Ok(Motion { source: file.into(), times: t.rows.iter().map(|r| r[time]).collect(), series, unfittable: Vec::new() })
}

/// The state channel of a converted trial (radians and metres by coordinate name).
fn motion_from_mcap(path: &Path) -> Result<Motion, LoadError> {
    let rec = crate::archive::export::read_trial_record(path)?;
    let names: Vec<String> = rec.frames.first().map(|f| f.state.q.keys().cloned().collect()).unwrap_or_default();
    let series = names
        .iter()
        .map(|name| {
            let (quantity, k) = if is_translation(name) {
                (Quantity::Length, 1000.0)
            } else {
                (Quantity::Angle, 180.0 / std::f64::consts::PI)
            };
            let values = rec.frames.iter().map(|f| f.state.q.get(name).map_or(f64::NAN, |v| v * k)).collect();
            Series { name: name.clone(), quantity, values }
        })
        .collect();
    let times: Vec<f64> = rec.frames.iter().map(|f| f.state.time + rec.time_offset).collect();
    // A window's span: the times of its first and last frames on this axis.
    let time_of =
        |frame: u32| rec.frames.iter().position(|f| f.state.frame == frame as usize).map_or(f64::NAN, |i| times[i]);
    let unfittable = rec
        .unfittable
        .iter()
        .flat_map(|u| &u.runs)
        .map(|r| Window {
            first: r.first_frame as usize,
            last: r.last_frame as usize,
            start_s: time_of(r.first_frame),
            end_s: time_of(r.last_frame),
            markers: r.markers.clone(),
            cause: r.cause.clone(),
        })
        .collect();
    Ok(Motion { source: path.display().to_string(), times, series, unfittable })
}

/// The coordinates `map` reads from the angle points of `t` (a C3D file read as points: the
/// values are degrees stored in the point's length units).
pub fn angles_from_markers(t: &crate::io::MarkerTrial, map: &AngleMap, file: &str) -> Result<Motion, LoadError> {
    // Points are stored in metres after reading; angle points were degrees in the file's units.
    let per_unit = 1.0 / units_to_metres(&t.source_units).unwrap_or(1.0);
    let find = |label: &str| {
        t.labels.iter().position(|l| l == label || l.rsplit_once(':').is_some_and(|(_, bare)| bare == label))
    };
    let mut series = Vec::new();
    for e in &map.angle {
        let Some(col) = e.points.iter().find_map(|p| find(p)) else { continue };
        let values = (0..t.n_frames())
            .map(|f| t.position(f, col).map_or(f64::NAN, |p| e.sign * p[e.component] * per_unit))
            .collect();
        series.push(Series { name: e.coordinate.clone(), quantity: Quantity::Angle, values });
    }
    if series.is_empty() {
        let mut wanted: Vec<&str> = map.angle.iter().flat_map(|e| e.points.iter().map(String::as_str)).collect();
        wanted.dedup();
        return Err(LoadError::NoAngles { file: file.into(), wanted: wanted.join(", "), has: t.labels.join(", ") });
    }
    Ok(Motion { source: file.into(), times: t.times.clone(), series, unfittable: Vec::new() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_maps_parse_and_name_both_sides() {
        for (name, _) in SHIPPED_MAPS {
            let m = AngleMap::shipped(name).unwrap();
            for c in ["knee_angle_r", "knee_angle_l", "hip_flexion_r", "ankle_angle_l", "pelvis_tilt"] {
                assert!(m.angle.iter().any(|e| e.coordinate == c), "{name}: {c}");
            }
        }
        let tilt = |n: &str| AngleMap::shipped(n).unwrap().angle.into_iter().find(|e| e.coordinate == "pelvis_tilt");
        assert_eq!(tilt("plugingait").unwrap().sign, -tilt("plugingait-opensim").unwrap().sign);
    }

    #[test]
    fn a_map_with_a_fourth_component_is_refused_with_its_coordinate() {
        let e =
            AngleMap::parse("[[angle]]\ncoordinate = \"k\"\npoints = [\"K\"]\ncomponent = 3\n", "m.toml").unwrap_err();
        assert!(e.to_string().contains("k: component 3"), "{e}");
    }

    #[test]
    fn tables_in_radians_come_out_in_degrees_and_translations_in_millimetres() {
        let t = crate::io::sto::parse_sto(
            "Coordinates\ninDegrees=no\nendheader\ntime\tknee\tpelvis_tx\n0\t1\t0.5\n",
            "x.mot",
        )
        .unwrap();
        let m = motion_from_table(&t, "x.mot").unwrap();
        assert!((m.get("knee").unwrap().values[0] - 57.29577951308232).abs() < 1e-12);
        assert_eq!(m.get("pelvis_tx").unwrap().values[0], 500.0);
        assert_eq!(m.get("pelvis_tx").unwrap().quantity, Quantity::Length);
    }
}
