//! `smocap export`: a converted trial's state channel as an OpenSim motion and/or CSV, or its
//! subject and motion as an animated glTF scene.

use crate::archive::export::{conversion_model, read_trial_record, write_csv, write_mot};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
#[command(group(clap::ArgGroup::new("outputs").required(true).multiple(true).args(["mot", "csv", "gltf", "mesh", "skin_report"])))]
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
    /// Write the subject's body mesh posed at `--frames` as OBJ files `<trial>_<frame>.obj`
    /// into this folder (metres, the Z-up world of `project`).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Write the model markers' signed distances to the subject's posed skin over every frame
    /// (JSON): per marker the median and 90th percentile of |distance − 7 mm| (a marker's radius),
    /// and pooled over landmark (anatomical) markers and the others.
    #[arg(long, value_name = "FILE.json")]
    pub skin_report: Option<PathBuf>,
    /// Trial frame numbers for `--mesh`, comma-separated (default: the first frame).
    #[arg(long, value_delimiter = ',', requires = "mesh")]
    pub frames: Vec<usize>,
    /// What `--gltf` shows of the subject: `mesh` (the body mesh skinned to the body nodes;
    /// capsules, with a note, where the body does not bind to the model) or `capsules` (bones).
    #[arg(long, value_enum, default_value_t = BodyKind::Mesh)]
    pub body: BodyKind,
    #[command(flatten)]
    pub scene: GltfArgs,
    /// The model (.osim or MJCF) that gives coordinate order and which are in degrees; by
    /// default the conversion's (the shipped model, the attached scaled `.osim`, or the MJCF file
    /// at its recorded path).
    #[arg(long)]
    pub model: Option<PathBuf>,
}

/// The subject in a glTF export.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BodyKind {
    Mesh,
    Capsules,
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
    if let Some(dir) = &a.mesh {
        write_meshes(&rec, &a.file, dir, &a.frames)?;
    }
    if let Some(out) = &a.skin_report {
        super::skin_report::write(&rec, &a.file, out, subject_body(&rec))?;
    }
    if a.mot.is_none() && a.csv.is_none() && a.gltf.is_none() {
        return Ok(0);
    }
    if let Some(out) = &a.gltf {
        let take = crate::render::Take::from_record(&rec, &a.file)?;
        let cams = crate::render::cameras(&take, a.scene.cameras.as_deref(), a.scene.rig_seed)?;
        let body = match a.body {
            BodyKind::Capsules => None,
            BodyKind::Mesh => dress_or_note(&take, &subject_body(&rec))?,
        };
        std::fs::write(out, crate::render::scene::glb_with_body(&take, &cams, a.scene.up, body.as_ref())?)
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

/// The subject's body on the take's model, its height against the stature on stderr; `None`,
/// with a note, where the body does not bind to the model.
pub(super) fn dress_or_note(
    take: &crate::render::Take,
    sub: &crate::body::SubjectBody,
) -> anyhow::Result<Option<crate::body::Dressed>> {
    let asset = crate::body::BodyAsset::shipped()?;
    Ok(match take.dress(&asset, sub, &crate::body::FitSettings::default()) {
        Ok((d, line)) => {
            eprintln!("{}: {line}", take.name);
            Some(d)
        }
        Err(e) => {
            eprintln!("note: the body mesh does not bind to this model ({e}); bones as capsules");
            None
        }
    })
}

/// What the trial's file says of its subject for the body mesh.
pub(super) fn subject_body(rec: &crate::archive::export::TrialRecord) -> crate::body::SubjectBody {
    crate::body::SubjectBody { stature_m: rec.subject_stature_m, info: rec.subject_info }
}

/// The body posed at `frames` (trial frame numbers; the first frame if none) as OBJ files.
fn write_meshes(
    rec: &crate::archive::export::TrialRecord,
    file: &std::path::Path,
    dir: &std::path::Path,
    frames: &[usize],
) -> anyhow::Result<()> {
    use crate::body::{BodyAsset, PoseWorkspace};
    use anyhow::Context as _;
    let take = crate::render::Take::from_record(rec, file)?;
    let asset = BodyAsset::shipped()?;
    let (body, line) = take
        .dress(&asset, &subject_body(rec), &crate::body::FitSettings::default())
        .context("binding the body mesh to the trial's model")?;
    eprintln!("{}: {line}", take.name);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let wanted = if frames.is_empty() { vec![*take.frames.first().unwrap_or(&0)] } else { frames.to_vec() };
    let mut ws = PoseWorkspace::new(&take.model, &body);
    let mut y = vec![0.0; take.model.ny()];
    for f in wanted {
        let i = take.frames.iter().position(|&g| g == f).with_context(|| {
            format!(
                "frame {f} is not in {} (frames {}..={})",
                file.display(),
                take.frames[0],
                take.frames[take.len() - 1]
            )
        })?;
        let nq = take.model.nq();
        y[..nq].copy_from_slice(&take.q[i]);
        y[nq..].copy_from_slice(&take.scales);
        body.pose(&take.model, &y, &mut ws);
        let name = format!("{}_{f}", take.name);
        let out = dir.join(format!("{name}.obj"));
        std::fs::write(&out, crate::body::obj::obj(&name, &ws.vertices, &body.triangles))
            .with_context(|| format!("writing {}", out.display()))?;
        eprintln!("wrote {}", out.display());
    }
    Ok(())
}
