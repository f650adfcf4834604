//! `smocap retarget`: converted trials onto a humanoid robot (GMR pickle, mjlab CSV, NPZ and a
//! quality report per trial, and the robot's channels in the trial's MCAP file).

use super::robot::{parse_offset, RobotSetup};
use crate::archive::mcap_out::WriterOptions;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct RetargetArgs {
    /// MCAP files written by `smocap convert` (or `solve --mcap`).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// A shipped robot (`g1`), or a mapping file: our TOML (docs/RETARGET.md) or GMR's
    /// `ik_match_table` JSON (with `--mjcf`).
    #[arg(long, default_value = "g1")]
    pub robot: String,
    /// The robot's MJCF, when the mapping file does not name it (GMR's JSON).
    #[arg(long)]
    pub mjcf: Option<PathBuf>,
    /// Output folder: `<trial>.pkl`, `<trial>.csv`, `<trial>.npz`, `<trial>.json` per trial.
    #[arg(long, required_unless_present = "into_mcap")]
    pub out: Option<PathBuf>,
    /// Add the robot to each input MCAP file (rewritten in place, atomically): `/robot/tf` (every
    /// robot body's pose per frame, frames `<robot>/<body>`), `/robot/scene` (its collision
    /// capsules) and a `smocap.robot` metadata record; a robot added before is replaced.
    #[arg(long)]
    pub into_mcap: bool,
    /// Where the robot stands in the MCAP's `world`: `X,Y` or `X,Y,Z` (m, Z up; default 0,0,0:
    /// where the human is), e.g. `0,1` beside a human walking along +x. The files are not moved.
    #[arg(long, value_parser = parse_offset, value_name = "X,Y[,Z]", requires = "into_mcap")]
    pub robot_offset: Option<[f64; 3]>,
    /// Settings (TOML: `[targets]` and `[solve]` tables of RetargetSettings); default: built in.
    #[arg(long)]
    pub settings: Option<PathBuf>,
    /// Also write `<trial>.targets.npz`: every task's target per frame and the planted feet
    /// (what the robot was asked to do; `scripts/compare_mink.py` drives mink with it).
    #[arg(long)]
    pub targets: bool,
    /// Print nothing but errors.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: RetargetArgs) -> anyhow::Result<u8> {
    let mut setup = RobotSetup::load(&a.robot, a.mjcf.as_deref(), a.settings.as_deref())?;
    setup.offset = a.robot_offset.unwrap_or_default().into();
    setup.write_targets = a.targets;
    if let Some(out) = &a.out {
        std::fs::create_dir_all(out).map_err(|e| anyhow::anyhow!("creating {}: {e}", out.display()))?;
    }
    if a.out.is_some() {
        // One folder takes one trial of each name: refuse rather than overwrite.
        let mut seen = std::collections::BTreeMap::new();
        for f in &a.inputs {
            if let Some(other) = seen.insert(f.file_stem(), f) {
                anyhow::bail!(
                    "{} and {} would both write {}.* into --out: retarget them into separate folders, or \
                     use `smocap convert --robot` (files beside each trial)",
                    other.display(),
                    f.display(),
                    f.file_stem().unwrap_or_default().to_string_lossy()
                );
            }
        }
    }
    let writer = WriterOptions::default();
    let mut suspect = false;
    for file in &a.inputs {
        let name = file.file_stem().map_or("trial".into(), |s| s.to_string_lossy().into_owned());
        let stem = a.out.as_ref().map(|o| o.join(&name));
        let (r, seconds) = setup.trial(file, stem.as_deref(), a.into_mcap.then_some(&writer))?;
        suspect |= r.status != "ok";
        if !a.quiet {
            eprintln!(
                "{name}: {} {} frames in {:.3} s ({:.0} frames/s), end effectors {:.1} mm median, {}{}",
                r.robot,
                r.frames,
                seconds,
                r.frames as f64 / seconds.max(1e-9),
                r.end_effector_median_mm,
                r.status,
                if r.reasons.is_empty() { String::new() } else { format!(": {}", r.reasons.join("; ")) }
            );
        }
    }
    Ok(if suspect { 2 } else { 0 })
}
