//! `smocap retarget`: converted trials onto a humanoid robot (GMR pickle, mjlab CSV, NPZ and a
//! quality report per trial).

use crate::retarget::{self, files, Human, Plan, RetargetSettings};
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;

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
    #[arg(long)]
    pub out: PathBuf,
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
    let (mapping, robot) = retarget::load(&a.robot, a.mjcf.as_deref())?;
    let settings: RetargetSettings = match &a.settings {
        Some(p) => toml::from_str(&std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?)
            .with_context(|| format!("parsing {}", p.display()))?,
        None => RetargetSettings::default(),
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut suspect = false;
    for file in &a.inputs {
        let rec = crate::archive::export::read_trial_record(file)?;
        let take = crate::render::Take::from_record(&rec, file)?;
        let human = Human {
            model: &take.model,
            scales: &take.scales,
            q: &take.q,
            times: &take.times,
            world_from_model: take.world_from_model,
        };
        let plan = Plan::new(&robot, &mapping, &human)?;
        let start = Instant::now();
        let done = retarget::retarget(&human, &robot, &plan, &settings, &take.name);
        let seconds = start.elapsed().as_secs_f64();
        let stem = a.out.join(&take.name);
        files::write_gmr_pickle(&stem.with_extension("pkl"), &done.motion)?;
        files::write_mjlab_csv(&stem.with_extension("csv"), &done.motion)?;
        files::write_npz(&stem.with_extension("npz"), &done.motion)?;
        if a.targets {
            files::write_targets_npz(&stem.with_extension("targets.npz"), &done.targets)?;
        }
        let json = serde_json::to_string_pretty(&done.report)? + "\n";
        crate::render::png_out::write_atomic(&stem.with_extension("json"), json.as_bytes())?;
        let r = &done.report;
        suspect |= r.status != "ok";
        if !a.quiet {
            eprintln!(
                "{}: {} {} frames in {:.3} s ({:.0} frames/s), end effectors {:.1} mm median, {}{}",
                take.name,
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
