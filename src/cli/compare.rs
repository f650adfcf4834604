//! `smocap compare OURS REFERENCE`: joint angles of a solved trial against a reference motion
//! ([`crate::eval::compare`]).

use crate::eval::compare::crosstalk::{corrected, CrossTalk, CrossTalkReport, Diagnosed};
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
    /// Leave the frames of OURS's unfittable windows (a converted trial's `/smocap/unfittable`:
    /// frames no pose fits) out of the statistics; they are included, and listed, by default.
    #[arg(long)]
    pub exclude_unfittable: bool,
    /// Exit 3 when any compared angle's RMSE exceeds this (degrees).
    #[arg(long)]
    pub max_rmse: Option<f64>,
    /// Also compare against the reference with its knee axes turned back by the axis errors its
    /// knee cross-talk gives (adduction following flexion), and report the knee offsets and RMSE
    /// after.
    #[arg(long)]
    pub correct_crosstalk: bool,
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
    let opt = CompareOptions {
        tolerance_s: a.tolerance,
        reference_shift_s: a.shift,
        coordinates,
        exclude_unfittable: a.exclude_unfittable,
    };
    let c = compare(&ours, &reference, &opt)?;
    print!("{}", table(&c));
    let pig;
    let map_used = match map.as_ref() {
        Some(m) => m,
        None => {
            pig = AngleMap::plug_in_gait();
            &pig
        }
    };
    let cross_talk = CrossTalkReport::of(&ours, &reference, map_used);
    print!("{}", cross_talk_table(&cross_talk));
    let after = match a.correct_crosstalk && !cross_talk.reference.is_empty() {
        true => Some(compare(&ours, &corrected(&reference, &cross_talk.reference), &opt)?),
        false => None,
    };
    if let Some(after) = &after {
        print!("{}", corrected_table(&c, after, &cross_talk.reference));
    } else if a.correct_crosstalk {
        println!("--correct-crosstalk: the reference has no knee with both flexion and adduction; nothing turned");
    }
    if let Some(p) = &a.json {
        let d = Diagnosed { comparison: c.clone(), cross_talk, corrected: after };
        std::fs::write(p, serde_json::to_string_pretty(&d)?).with_context(|| format!("writing {}", p.display()))?;
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
    for u in &c.unfittable {
        let w = &u.window;
        let _ = writeln!(
            s,
            "unfittable frames {}–{} ({:.3}–{:.3} s, {}: markers {}): {} matched frames {}",
            w.first,
            w.last,
            w.start_s,
            w.end_s,
            if w.cause == "data" { "the data is bad here" } else { "the model cannot reach them" },
            w.markers.join(", "),
            u.matched_frames,
            if u.excluded {
                "left out of the statistics"
            } else {
                "included in the statistics (--exclude-unfittable leaves them out)"
            }
        );
    }
    s
}

/// The knee cross-talk of both sides, when either has a knee's flexion and adduction.
pub fn cross_talk_table(x: &CrossTalkReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    if x.is_empty() {
        return s;
    }
    let _ = writeln!(s, "knee cross-talk (adduction following flexion: a flexion axis turned about the thigh)");
    let _ = writeln!(
        s,
        "{:<10} {:<5} {:>6} {:>7} {:>8} {:>11} {:>11}",
        "side", "knee", "frames", "r", "slope", "axis error", "r after"
    );
    for (who, found) in [("reference", &x.reference), ("ours", &x.ours)] {
        for k in found.iter() {
            let _ = writeln!(
                s,
                "{:<10} {:<5} {:>6} {:>7.3} {:>8.3} {:>10.1}° {:>11.3}",
                who, k.side, k.fit.frames, k.fit.r, k.fit.slope, k.fit.axis_error_deg, k.r_corrected
            );
        }
        if found.is_empty() {
            let _ = writeln!(
                s,
                "{who:<10} no knee with both angles ({}): a hinge knee has no adduction to follow its flexion",
                x.looked_for.join(", ")
            );
        }
    }
    s
}

/// The knee coordinates before and after turning the reference's knee axes back.
pub fn corrected_table(before: &Comparison, after: &Comparison, turned: &[CrossTalk]) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let axes: Vec<String> = turned.iter().map(|k| format!("{} {:+.1}°", k.side, k.fit.axis_error_deg)).collect();
    let _ = writeln!(s, "reference's knee axes turned back ({}):", axes.join(", "));
    let _ = writeln!(
        s,
        "{:<22} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "coordinate", "offset", "after", "RMSE", "after", "centred", "after"
    );
    for k in turned {
        for name in [&k.flexion, &k.adduction] {
            let (Some(b), Some(a)) = (before.get(name), after.get(name)) else { continue };
            let _ = writeln!(
                s,
                "{:<22} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
                name, b.offset, a.offset, b.rmse, a.rmse, b.rmse_centred, a.rmse_centred
            );
        }
    }
    s
}
