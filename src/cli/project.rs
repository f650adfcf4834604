//! `smocap project`: 2D/3D ground truth of converted trials seen from a camera rig (COCO
//! keypoint JSON and CSV per camera and frame, the cameras' OpenCV matrices) and the thesis'
//! marker metrics; or, with `--points`, named world points projected (for checks against OpenCV).

use crate::render::{self, project};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ProjectArgs {
    /// MCAP files written by `smocap convert` (one output folder each: `--out` itself for one
    /// file, `--out/<file stem>` for several).
    #[arg(required_unless_present = "points")]
    pub files: Vec<PathBuf>,
    /// Camera rig (TOML: docs/guide/rendering-and-synthetic-video.md); default: the built-in
    /// two-camera rig (frontal and sagittal) around each trial.
    #[arg(long)]
    pub cameras: Option<PathBuf>,
    /// Seed of the default rig's perturbation of camera positions.
    #[arg(long, default_value_t = 0)]
    pub rig_seed: u64,
    /// Project every N-th frame (from the first).
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Instead of trials: project the points of this CSV (`name,x,y,z`, m, world; a header row)
    /// with `--cameras` (world coordinates); writes `cameras.json` and `points.csv`.
    #[arg(long, conflicts_with = "files", requires = "cameras")]
    pub points: Option<PathBuf>,
    /// Leave out the body mesh's ground truth (its surface keypoints, COCO-17 plus heel, big and
    /// small toe, as category `body`; the virtual markers and their spatial and pixel error).
    #[arg(long)]
    pub no_body: bool,
    /// Also write the metrics of every trial as one JSON array here.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
}

pub fn run(a: ProjectArgs) -> anyhow::Result<u8> {
    use anyhow::Context as _;
    anyhow::ensure!(a.stride >= 1, "--stride {}: expected at least 1", a.stride);
    if let Some(points) = &a.points {
        let cams = render::rig::read_rig(
            a.cameras.as_deref().expect("clap requires --cameras"),
            &render::SubjectFrame::world(),
        )?;
        let pts = project::read_points(points)?;
        project::write_points(&pts, &cams, &a.out)?;
        eprintln!("wrote {} ({} points × {} cameras)", a.out.join("points.csv").display(), pts.len(), cams.len());
        return Ok(0);
    }
    // One folder per file: `--out` itself for one file; for several, each file's path below the
    // folder they all lie in, without its extension (`--out/<dataset>/<subject>/<trial>`).
    let base = common_folder(&a.files);
    let mut dirs = std::collections::BTreeMap::new();
    for f in &a.files {
        let rel = f.strip_prefix(&base).unwrap_or(f).with_extension("");
        let dir = if a.files.len() == 1 { a.out.clone() } else { a.out.join(&rel) };
        if let Some((other, _)) = dirs.insert(dir.clone(), (f, rel.display().to_string())) {
            anyhow::bail!("{} and {} would both write into {}", other.display(), f.display(), dir.display());
        }
    }
    let mut rows = Vec::new();
    for (dir, (f, rel)) in &dirs {
        let rec = crate::archive::export::read_trial_record(f)?;
        let mut take = render::Take::from_record(&rec, f)?;
        if a.files.len() > 1 {
            take.name = rel.clone();
        }
        let cams = render::cameras(&take, a.cameras.as_deref(), a.rig_seed)?;
        let mut body = if a.no_body {
            None
        } else {
            let sub = crate::body::SubjectBody { stature_m: rec.subject_stature_m, info: rec.subject_info };
            render::body_truth::BodyTruth::new(&take, &sub)?
        };
        let m = project::write_ground_truth(&take, &cams, &take.strided(a.stride), dir, body.as_mut())?;
        eprintln!("wrote {} ({} frames × {} cameras)", dir.display(), m.frames, cams.len());
        rows.push(m);
    }
    rows.sort_by(|x, y| x.trial.cmp(&y.trial));
    print!("{}", project::metrics_table(&rows));
    if let Some(p) = &a.report_json {
        std::fs::write(p, serde_json::to_string_pretty(&rows)? + "\n")
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(0)
}

/// The deepest folder holding every file of `files` (their parents' common prefix).
pub(super) fn common_folder(files: &[PathBuf]) -> PathBuf {
    let parents: Vec<Vec<std::path::Component>> =
        files.iter().map(|f| f.parent().map(|p| p.components().collect()).unwrap_or_default()).collect();
    let Some(first) = parents.first() else { return PathBuf::new() };
    let n = (0..first.len()).take_while(|&i| parents.iter().all(|p| p.get(i) == Some(&first[i]))).count();
    first[..n].iter().collect()
}
