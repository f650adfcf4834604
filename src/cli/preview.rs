//! `smocap preview`: a contact sheet (PNG) of a converted trial seen from each camera.

use crate::render;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct PreviewArgs {
    /// An MCAP file written by `smocap convert`.
    pub file: PathBuf,
    /// The PNG to write: one row (panel) per camera, one tile per shown frame.
    #[arg(long)]
    pub out: PathBuf,
    /// Camera rig (TOML); default: the built-in two-camera rig around the trial.
    #[arg(long)]
    pub cameras: Option<PathBuf>,
    /// Seed of the default rig's perturbation of camera positions.
    #[arg(long, default_value_t = 0)]
    pub rig_seed: u64,
    /// Frames shown per camera, evenly spaced over the trial (first and last included).
    #[arg(long, default_value_t = 6)]
    pub frames: usize,
    /// The trial's worst frames (highest marker RMSE, one per event) shown besides, with a red
    /// border.
    #[arg(long, default_value_t = 2)]
    pub worst: usize,
    /// Width of one tile (px); its height follows the camera's aspect ratio.
    #[arg(long, default_value_t = 240)]
    pub tile_width: u32,
}

pub fn run(a: PreviewArgs) -> anyhow::Result<u8> {
    anyhow::ensure!((1..=100).contains(&a.frames), "--frames {}: expected 1 to 100", a.frames);
    anyhow::ensure!((16..=4096).contains(&a.tile_width), "--tile-width {}: expected 16 to 4096", a.tile_width);
    let rec = crate::archive::export::read_trial_record(&a.file)?;
    let take = render::Take::from_record(&rec, &a.file)?;
    let cams = render::cameras(&take, a.cameras.as_deref(), a.rig_seed)?;
    anyhow::ensure!(a.worst <= 100, "--worst {}: expected 0 to 100", a.worst);
    let (layout, shown) = render::preview::write_contact_sheet(&take, &cams, a.frames, a.worst, a.tile_width, &a.out)?;
    let (w, h) = layout.size();
    eprintln!("wrote {} ({w} × {h} px: {} cameras × {} frames)", a.out.display(), layout.rows, layout.columns);
    for f in shown.iter().filter(|f| f.worst) {
        let rmse = f.rmse_mm.map_or("-".into(), |r| format!("{r:.1} mm"));
        eprintln!("  red border: frame {} (t = {:.2} s), marker RMSE {rmse}", f.index, f.time);
    }
    Ok(0)
}
