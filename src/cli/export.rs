//! `smocap export`: a converted trial's state channel as an OpenSim motion and/or CSV, or its
//! subject and motion as an animated glTF scene.

use crate::archive::export::{conversion_model, read_trial_record, write_csv, write_mot};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
#[command(group(clap::ArgGroup::new("outputs").required(true).multiple(true).args(["mot", "csv", "gltf"])))]
pub struct ExportArgs {
    /// An MCAP file written by `smocap convert`.
    pub file: PathBuf,
    /// Write an OpenSim motion (`.mot`: every coordinate, rotations in degrees, as
    /// `smocap solve --mot-dir` writes).
    #[arg(long)]
    pub mot: Option<PathBuf>,
    /// Write a CSV table: time (s), frame, coordinates (rad, m), scales per body, RMSE (m), status.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Write a glTF 2.0 binary (`.glb`): one node per body (named as the model's), the motion as
    /// one animation at the trial's frame times, bones and model markers, observed markers, the
    /// cameras (metres).
    #[arg(long)]
    pub gltf: Option<PathBuf>,
    #[command(flatten)]
    pub scene: GltfArgs,
    /// The model (.osim or MJCF) that gives coordinate order and which are in degrees; by
    /// default the conversion's (the shipped model, the attached scaled `.osim`, or the MJCF file
    /// at its recorded path).
    #[arg(long)]
    pub model: Option<PathBuf>,
}

/// Options of a glTF export (`export --gltf`, `solve --gltf-dir`).
#[derive(Args, Debug, Clone)]
pub struct GltfArgs {
    /// Up axis of the glTF scene: `y` (glTF's convention, what Blender and three.js import
    /// upright) or `z` (the Z-up world of the MCAP `/tf`, unconverted).
    #[arg(long = "up", value_enum, default_value_t = crate::render::scene::Up::Y)]
    pub up: crate::render::scene::Up,
    /// Camera rig (TOML) to include; default: the built-in two-camera rig around the trial.
    #[arg(long)]
    pub cameras: Option<PathBuf>,
    /// Seed of the default rig's perturbation of camera positions.
    #[arg(long, default_value_t = 0)]
    pub rig_seed: u64,
}

pub fn run(a: ExportArgs) -> anyhow::Result<u8> {
    use anyhow::Context as _;
    // The folders the outputs go to exist before the work starts.
    for out in [&a.mot, &a.csv, &a.gltf].into_iter().flatten() {
        if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
        }
    }
    let rec = read_trial_record(&a.file)?;
    if let Some(out) = &a.gltf {
        let take = crate::render::Take::from_record(&rec, &a.file)?;
        let cams = crate::render::cameras(&take, a.scene.cameras.as_deref(), a.scene.rig_seed)?;
        std::fs::write(out, crate::render::scene::glb(&take, &cams, a.scene.up)?)
            .with_context(|| format!("writing {}", out.display()))?;
        eprintln!(
            "wrote {} ({} frames, {} bodies, {} cameras)",
            out.display(),
            take.len(),
            take.model.nb(),
            cams.len()
        );
        if a.mot.is_none() && a.csv.is_none() {
            return Ok(0);
        }
    }
    let model = match &a.model {
        Some(p) => Some(super::load_context(Some(p.as_path()), None)?.model),
        None => match conversion_model(&rec, &a.file) {
            Ok(m) => Some(m),
            Err(e) if a.mot.is_some() => {
                return Err(anyhow::Error::new(e).context("--mot needs the model (try --model)"))
            }
            Err(e) => {
                eprintln!("note: {e}; CSV columns in name order");
                None
            }
        },
    };
    if let (Some(out), Some(m)) = (&a.mot, &model) {
        write_mot(&rec, m, out)?;
        eprintln!("wrote {} ({} frames)", out.display(), rec.frames.len());
    }
    if let Some(out) = &a.csv {
        write_csv(&rec, model.as_ref(), out)?;
        eprintln!("wrote {} ({} frames)", out.display(), rec.frames.len());
    }
    Ok(0)
}
