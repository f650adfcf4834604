//! `smocap render`: the solved people drawn through a camera rig (RGB, segment masks, depth,
//! COCO keypoints with visibility), for one trial, several in one scene (`--together`), or
//! whole `convert` output folders (sharded, resumable, with a dataset index).

use crate::archive::shard::Shard;
use crate::render::{self, raster, video, video_out};
use anyhow::Context as _;
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// MCAP files written by `smocap convert`, or folders holding them (a `convert --out`
    /// folder: every trial below it).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Output folder: for one trial the folder itself, else one folder per trial below it
    /// (its path below the inputs' common folder, without `.mcap`) and `index.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Camera rig (TOML: docs/guide/rendering-and-synthetic-video.md); default: the built-in
    /// two-camera rig around each trial (perturbed by `--seed`).
    #[arg(long)]
    pub cameras: Option<PathBuf>,
    /// Image size WxH (px) for every camera (intrinsics rescaled, horizontal fit); default: each
    /// camera's own.
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Render every N-th frame (from the first).
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// Seed of the looks (skin tone, clothing, light, background, floor) and the default rig.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A folder of PNG pictures: each scene gets one (chosen by the seed) behind the bodies,
    /// instead of the floor and a plain colour.
    #[arg(long, value_name = "DIR")]
    pub backgrounds: Option<PathBuf>,
    /// Draw all the given trials' subjects in one scene (cameras around the first), into `--out`.
    #[arg(long)]
    pub together: bool,
    /// Render only shard I of N of the trials (0-based, trial k of the sorted list goes to
    /// shard k mod N). When absent, read from the job array's environment as `convert` does.
    #[arg(long)]
    pub shard: Option<Shard>,
    /// Skip trials whose folder already holds `render.json` (written last, when a trial is done).
    #[arg(long)]
    pub resume: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("'{s}': expected WIDTHxHEIGHT in pixels, e.g. 1280x720");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.trim().parse().map_err(|_| bad())?, h.trim().parse().map_err(|_| bad())?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(bad());
    }
    Ok((w, h))
}

/// Every `.mcap` file of `inputs` (folders searched recursively), sorted.
fn trials(inputs: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for i in inputs {
        if i.is_dir() {
            for e in walkdir::WalkDir::new(i).sort_by_file_name() {
                let e = e.with_context(|| format!("listing {}", i.display()))?;
                if e.file_type().is_file() && e.path().extension().is_some_and(|x| x == "mcap") {
                    out.push(e.into_path());
                }
            }
        } else {
            out.push(i.clone());
        }
    }
    out.sort();
    out.dedup();
    Ok(out)
}

/// Renders `files` as one scene into `dir`; the summary is also written as `dir/render.json`.
fn render_scene(a: &RenderArgs, files: &[PathBuf], dir: &Path, name: &str) -> anyhow::Result<video_out::Rendered> {
    let mut r = video::scene_renderer(files, a.cameras.as_deref(), a.size, a.seed, name, a.backgrounds.as_deref())?;
    let frames: Vec<usize> = (0..r.len()).step_by(a.every).collect();
    let done = video_out::render_to_dir(&mut r, &frames, dir, !a.quiet)?;
    let summary = serde_json::json!({
        "trials": files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>(),
        "frames": done.frames, "cameras": done.cameras, "seconds": done.seconds,
        "frames_per_s": done.frames_per_s, "adapter": done.adapter, "seed": a.seed, "every": a.every,
        "phases_s": { "pose": done.phases.pose_s, "draw": done.phases.draw_s, "keypoints": done.keypoints_s,
                      "writers_wait": done.writers_wait_s },
    });
    render::png_out::write_atomic(
        &dir.join("render.json"),
        (serde_json::to_string_pretty(&summary)? + "\n").as_bytes(),
    )?;
    eprintln!(
        "wrote {} ({} frames × {} cameras, {:.1} frames/s on {})",
        dir.display(),
        done.frames,
        done.cameras,
        done.frames_per_s,
        done.adapter
    );
    if let Err(note) = &done.mp4 {
        eprintln!("note: {note}");
    }
    Ok(done)
}

pub fn run(a: RenderArgs) -> anyhow::Result<u8> {
    anyhow::ensure!(a.every >= 1, "--every {}: expected at least 1", a.every);
    let files = trials(&a.inputs)?;
    anyhow::ensure!(!files.is_empty(), "no .mcap file in {:?}", a.inputs);
    if a.together {
        render_scene(&a, &files, &a.out, "together")?;
        return Ok(0);
    }
    let single = files.len() == 1 && !a.inputs[0].is_dir();
    let base = super::project::common_folder(&files);
    let shard = match a.shard {
        Some(s) => Some(s),
        None => Shard::from_env(|k| std::env::var(k).ok())?,
    };
    let (mut ok, mut failed) = (0, 0);
    let (mut frames, mut seconds) = (0usize, 0f64);
    for (k, f) in files.iter().enumerate() {
        if shard.is_some_and(|s| k % s.count != s.index) {
            continue;
        }
        let rel = f.strip_prefix(&base).unwrap_or(f).with_extension("");
        let dir = if single { a.out.clone() } else { a.out.join(&rel) };
        if a.resume && dir.join("render.json").is_file() {
            eprintln!("{}: done before (render.json), skipped", dir.display());
            ok += 1;
            continue;
        }
        match render_scene(&a, std::slice::from_ref(f), &dir, &rel.display().to_string()) {
            Ok(d) => {
                ok += 1;
                frames += d.frames;
                seconds += d.seconds;
            }
            Err(e) if e.downcast_ref::<render::RenderError>().is_some_and(no_adapter) => return Err(e),
            Err(e) => {
                eprintln!("error: {}: {}", f.display(), super::one_line(&e));
                failed += 1;
            }
        }
    }
    if !single {
        write_index(&a.out)?;
        let rate =
            if frames > 0 { format!("; {:.1} frames/s", frames as f64 / seconds.max(1e-9)) } else { String::new() };
        eprintln!("{ok} trials rendered or done before, {failed} failed{rate}");
    }
    Ok(super::exit_code(ok, failed, false))
}

fn no_adapter(e: &render::RenderError) -> bool {
    matches!(e, render::RenderError::Raster(raster::RasterError::NoAdapter(_)))
}

/// `index.json`: every trial folder below `out` holding `render.json`, with its summary.
fn write_index(out: &Path) -> anyhow::Result<()> {
    let mut trials = Vec::new();
    for e in walkdir::WalkDir::new(out).sort_by_file_name() {
        let e = e.with_context(|| format!("listing {}", out.display()))?;
        if e.file_name() == "render.json" {
            let text = std::fs::read_to_string(e.path()).with_context(|| format!("reading {}", e.path().display()))?;
            let mut v: serde_json::Value =
                serde_json::from_str(&text).with_context(|| format!("{}", e.path().display()))?;
            let folder = e.path().parent().and_then(|p| p.strip_prefix(out).ok()).unwrap_or(Path::new(""));
            v["folder"] = serde_json::json!(folder.display().to_string());
            trials.push(v);
        }
    }
    let index = serde_json::json!({ "smocap_render_index": 1, "trials": trials });
    render::png_out::write_atomic(&out.join("index.json"), (serde_json::to_string_pretty(&index)? + "\n").as_bytes())?;
    Ok(())
}
