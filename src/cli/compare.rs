//! `smocap compare OURS REFERENCE`: joint angles of a solved trial against a reference motion
//! ([`crate::eval::compare`]).

use crate::eval::compare::figure::write_figure;
use crate::eval::compare::load::{load_motion, AngleMap, SHIPPED_MAPS};
use crate::eval::compare::{compare, CompareOptions, Comparison, Quantity};
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

/// The ten core lower-limb and pelvis coordinates (`--core`).
pub const CORE: [&str; 10] = [
    "hip_flexion_r",
    "hip_adduction_r",
    "knee_angle_r",
    "ankle_angle_r",
    "hip_flexion_l",
    "hip_adduction_l",
    "knee_angle_l",
    "ankle_angle_l",
    "pelvis_tilt",
    "pelvis_list",
];

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The solved trial: an OpenSim motion (`.mot`/`.sto`, e.g. from `smocap solve --mot-dir`) or a
    /// converted trial (`.mcap`).
    pub ours: PathBuf,
    /// The reference: an OpenSim/AddBiomechanics motion (`.mot`/`.sto`) or a C3D file with angle
    /// points (Plug-in Gait's `LKneeAngles`, …, read through `--map`).
    pub reference: PathBuf,
    /// Which C3D angle points give which coordinates: a shipped map (`plugingait`, the default, for
    /// the shipped model; `plugingait-opensim` for OpenSim's Rajagopal family, whose pelvis tilt has
    /// the other sign) or a TOML file (the format of `models/compare/plugingait.toml`).
    #[arg(long)]
    pub map: Option<String>,
    /// Compare only these coordinates (comma-separated).
    #[arg(long, value_delimiter = ',', conflicts_with = "core")]
    pub coordinates: Vec<String>,
    /// Compare the ten core coordinates: hip flexion and adduction, knee, ankle on both sides;
    /// pelvis tilt and list.
    #[arg(long)]
    pub core: bool,
    /// Largest time difference (s) between matched frames (default: half the finer frame period: frames sampled at the same instant).
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Seconds added to the reference's times before matching.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub shift: f64,
    /// Write the comparison as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write a figure (SVG) of the worst coordinates here.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Coordinates in the figure.
    #[arg(long, default_value_t = 6)]
    pub worst: usize,
    /// Exit 3 when any compared angle's RMSE exceeds this (degrees).
    #[arg(long)]
    pub max_rmse: Option<f64>,
}

pub fn run(a: CompareArgs) -> anyhow::Result<u8> {
    let map = match a.map.as_deref() {
        Some(name) => match AngleMap::shipped(name) {
            Some(m) => Some(m),
            None => {
                let text = std::fs::read_to_string(name).with_context(|| {
                    let shipped: Vec<&str> = SHIPPED_MAPS.iter().map(|(n, _)| *n).collect();
                    format!("reading the angle map {name} (not a file, nor a shipped map: {})", shipped.join(", "))
                })?;
                Some(AngleMap::parse(&text, name)?)
            }
        },
        None => None,
    };
    let ours = load_motion(&a.ours, map.as_ref())?;
    let reference = load_motion(&a.reference, map.as_ref())?;
    let coordinates = if a.core { CORE.iter().map(|s| s.to_string()).collect() } else { a.coordinates.clone() };
    let opt = CompareOptions { tolerance_s: a.tolerance, reference_shift_s: a.shift, coordinates };
    let c = compare(&ours, &reference, &opt)?;
    print!("{}", table(&c));
    if let Some(p) = &a.json {
        std::fs::write(p, serde_json::to_string_pretty(&c)?).with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &a.plot {
        write_figure(&c, &ours, &reference, a.worst, p)?;
        eprintln!("wrote {}", p.display());
    }
    let over: Vec<&str> = c
        .coordinates
        .iter()
        .filter(|s| s.quantity == Quantity::Angle && a.max_rmse.is_some_and(|m| s.rmse > m))
        .map(|s| s.name.as_str())
        .collect();
    if !over.is_empty() {
        eprintln!("RMSE above {:.2}°: {}", a.max_rmse.unwrap_or_default(), over.join(", "));
        return Ok(super::EXIT_SOME_FAILED);
    }
    Ok(0)
}

/// The comparison as a table, one line per coordinate, then a summary line.
pub fn table(c: &Comparison) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "{} against {}", c.ours, c.reference);
    let _ = writeln!(
        s,
        "{:<22} {:>6} {:>8} {:>8} {:>8} {:>7} {:>8}  unit",
        "coordinate", "frames", "RMSE", "offset", "centred", "corr", "max"
    );
    for k in &c.coordinates {
        let _ = writeln!(
            s,
            "{:<22} {:>6} {:>8.2} {:>8.2} {:>8.2} {:>7.3} {:>8.2}  {}",
            k.name,
            k.frames,
            k.rmse,
            k.offset,
            k.rmse_centred,
            k.correlation,
            k.max_abs,
            k.quantity.unit()
        );
    }
    let angles = c.coordinates.iter().filter(|k| k.quantity == Quantity::Angle).count();
    let _ = writeln!(
        s,
        "mean angle RMSE {:.2} deg over {angles} angles; {} of {} frames matched (tolerance {:.1} ms)",
        c.mean_angle_rmse,
        c.matched_frames,
        c.ours_frames,
        c.tolerance_s * 1e3
    );
    if !c.missing_in_reference.is_empty() {
        let _ = writeln!(s, "not in the reference: {}", c.missing_in_reference.join(", "));
    }
    if !c.missing_in_ours.is_empty() {
        let _ = writeln!(s, "not in ours: {}", c.missing_in_ours.join(", "));
    }
    s
}
