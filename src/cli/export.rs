//! `smocap export`: a converted trial's state channel as an OpenSim motion and/or CSV.

use crate::archive::export::{conversion_model, read_trial_record, write_csv, write_mot};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
#[command(group(clap::ArgGroup::new("outputs").required(true).multiple(true).args(["mot", "csv"])))]
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
    /// The model (.osim or MJCF) that gives coordinate order and which are in degrees; by
    /// default the conversion's (the shipped model, the attached scaled `.osim`, or the MJCF file
    /// at its recorded path).
    #[arg(long)]
    pub model: Option<PathBuf>,
}

pub fn run(a: ExportArgs) -> anyhow::Result<u8> {
    use anyhow::Context as _;
    // The folders the outputs go to exist before the work starts.
    for out in [&a.mot, &a.csv].into_iter().flatten() {
        if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
        }
    }
    let rec = read_trial_record(&a.file)?;
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
