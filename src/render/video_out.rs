//! A [`Renderer`]'s frames written to a folder: `cameras.json` (as `smocap project` writes it),
//! per camera `<camera>/rgb|mask|depth/<frame:06>.png` and `<camera>.coco.json`, and
//! `<camera>.mp4` where `ffmpeg` is on `PATH`. PNG encoding runs on writer threads while the next
//! frame is drawn; a bounded queue keeps memory flat in the trial's length.

use super::coco::{Annotation, CocoWriter, Image};
use super::png_out::{write_atomic, Encoder};
use super::raster::Images;
use super::video::{Keypoints, Renderer};
use super::RenderError;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::sync::Mutex;

/// What was rendered.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Rendered {
    pub frames: usize,
    pub cameras: usize,
    pub seconds: f64,
    pub frames_per_s: f64,
    pub adapter: String,
    /// Wall time (s) drawing ([`super::video::Phases`]), testing keypoints and writing COCO
    /// records, and waiting for the PNG writers (their queue full).
    pub phases: super::video::Phases,
    pub keypoints_s: f64,
    pub writers_wait_s: f64,
    /// Written videos, or why none.
    pub mp4: Result<Vec<String>, String>,
}

struct Job {
    camera: usize,
    frame: usize,
    images: Images,
}

/// The files of camera `cam`'s frame `frame` (relative to the output folder).
pub fn frame_files(cam: &str, frame: usize) -> [String; 3] {
    ["rgb", "mask", "depth"].map(|k| format!("{cam}/{k}/{frame:06}.png"))
}

fn writer(
    dir: &Path,
    names: &[String],
    max_label: u16,
    jobs: &Mutex<mpsc::Receiver<Job>>,
    back: mpsc::Sender<Images>,
) -> Result<(), RenderError> {
    let mut enc = Encoder::default();
    loop {
        let job = match jobs.lock().unwrap_or_else(|p| p.into_inner()).recv() {
            Ok(j) => j,
            Err(_) => return Ok(()),
        };
        let [rgb, mask, depth] = frame_files(&names[job.camera], job.frame).map(|f| dir.join(f));
        write_atomic(&rgb, enc.rgb(&job.images))?;
        write_atomic(&mask, enc.mask(&job.images, max_label))?;
        write_atomic(&depth, enc.depth(&job.images))?;
        let _ = back.send(job.images);
    }
}

/// The COCO file's members other than images and annotations.
fn coco_head(r: &Renderer, c: usize) -> serde_json::Map<String, serde_json::Value> {
    let categories: Vec<_> = r
        .actors
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let (names, kinds) = r.keypoint_names(k);
            let ns = crate::body::keypoints::NAMES.len();
            let mut skeleton: Vec<[usize; 2]> = crate::body::keypoints::SKELETON.to_vec();
            skeleton.extend(
                (a.take.model.bodies.iter().enumerate())
                    .filter_map(|(b, body)| Some([ns + body.parent? + 1, ns + b + 1])),
            );
            let bodies: Vec<&str> = a.take.model.bodies.iter().map(|b| b.name.as_str()).collect();
            json!({ "id": k + 1, "name": a.take.name, "supercategory": "person", "keypoints": names,
                    "keypoint_kinds": kinds, "skeleton": skeleton,
                    "mask_labels": { "first": r.labels[k].first, "bodies": bodies } })
        })
        .collect();
    let mut m = serde_json::Map::new();
    m.insert("info".into(), json!({
        "description": format!("smocap render of {} from camera {}", r.actors[0].take.name, r.cameras[c].name),
        "version": env!("CARGO_PKG_VERSION"),
        "visibility": "v=2 visible, v=1 occluded (by the body itself or another subject; docs/guide/rendering-and-synthetic-video.md), v=0 outside the image",
        "depth_png": "16-bit, millimetres along the camera axis, 0 where no body",
        "mask_png": "0 background; subject k's body b: mask_labels.first + b",
    }));
    m.insert("camera".into(), super::project::camera_json(&r.cameras[c]));
    m.insert("categories".into(), json!(categories));
    m
}

/// Renders the positions `frames` of `r`'s takes into `dir`; `progress` shows a bar on stderr.
pub fn render_to_dir(r: &mut Renderer, frames: &[usize], dir: &Path, progress: bool) -> Result<Rendered, RenderError> {
    let start = std::time::Instant::now();
    let names: Vec<String> = r.cameras.iter().map(|c| c.name.clone()).collect();
    let cams = json!({ "cameras": r.cameras.iter().map(super::project::camera_json).collect::<Vec<_>>() });
    write_atomic(&dir.join("cameras.json"), (serde_json::to_string_pretty(&cams).expect("JSON") + "\n").as_bytes())?;
    let mut cocos =
        names.iter().map(|n| CocoWriter::new(&dir.join(format!("{n}.coco.json")))).collect::<Result<Vec<_>, _>>()?;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).clamp(1, 8);
    let (job_tx, job_rx) = mpsc::sync_channel::<Job>(names.len() * 2);
    let (back_tx, back_rx) = mpsc::channel::<Images>();
    let jobs = Mutex::new(job_rx);
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(frames.len() as u64),
        if progress { indicatif::ProgressDrawTarget::stderr() } else { indicatif::ProgressDrawTarget::hidden() },
    );
    let max_label = r.max_label();
    let mut waits = [0.0f64; 2];
    let drawn = std::thread::scope(|s| -> Result<(), RenderError> {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                let back = back_tx.clone();
                let (jobs, names) = (&jobs, &names);
                s.spawn(move || writer(dir, names, max_label, jobs, back))
            })
            .collect();
        let result = draw_all(r, frames, &names, &mut cocos, (&job_tx, &back_rx), &bar, &mut waits);
        drop(job_tx);
        for w in workers {
            w.join().expect("a writer thread panicked")?;
        }
        result
    });
    bar.finish_and_clear();
    drawn?;
    for (c, coco) in cocos.into_iter().enumerate() {
        coco.finish(&coco_head(r, c))?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let mp4 = write_mp4s(r, frames, dir, &names);
    Ok(Rendered {
        frames: frames.len(),
        cameras: names.len(),
        seconds,
        frames_per_s: frames.len() as f64 / seconds.max(1e-9),
        adapter: r.adapter().to_string(),
        phases: r.phases,
        keypoints_s: waits[0],
        writers_wait_s: waits[1],
        mp4,
    })
}

fn draw_all(
    r: &mut Renderer,
    frames: &[usize],
    names: &[String],
    cocos: &mut [CocoWriter],
    (jobs, back): (&mpsc::SyncSender<Job>, &mpsc::Receiver<Images>),
    bar: &indicatif::ProgressBar,
    waits: &mut [f64; 2],
) -> Result<(), RenderError> {
    let mut images: Vec<Images> = vec![Images::default(); names.len()];
    let mut kp = Keypoints::default();
    let mut next_id = 1;
    for (n, &i) in frames.iter().enumerate() {
        r.draw(i, &mut images)?;
        let frame = r.actors[0].take.frames[i];
        for (c, coco) in cocos.iter_mut().enumerate() {
            let t = std::time::Instant::now();
            let [rgb, mask, depth] = frame_files(&names[c], frame);
            let (width, height) = images[c].size;
            let time_s = r.actors[0].take.times[i];
            coco.image(&Image {
                id: n + 1,
                file_name: &rgb,
                mask_file: &mask,
                depth_file: &depth,
                width,
                height,
                frame,
                time_s,
            })?;
            for k in 0..r.actors.len() {
                r.keypoints(k, i, c, &images[c], &mut kp);
                coco.annotation(&Annotation {
                    id: next_id,
                    image_id: n + 1,
                    category_id: k + 1,
                    keypoints: &kp.xyv,
                    keypoint_depths_m: &kp.depths_m,
                    num_keypoints: kp.labelled,
                    bbox: kp.bbox,
                    area: kp.area as f64,
                    iscrowd: 0,
                })?;
                next_id += 1;
            }
            let spare = back.try_recv().unwrap_or_default();
            let images = std::mem::replace(&mut images[c], spare);
            let sent = std::time::Instant::now();
            waits[0] += (sent - t).as_secs_f64();
            let full = jobs.send(Job { camera: c, frame, images }).is_err();
            waits[1] += sent.elapsed().as_secs_f64();
            if full {
                // A writer stopped on an error; it is reported when the writers are joined.
                return Ok(());
            }
        }
        bar.inc(1);
    }
    Ok(())
}

fn which(program: &str) -> Option<PathBuf> {
    std::env::split_paths(&std::env::var_os("PATH")?).map(|d| d.join(program)).find(|p| p.is_file())
}

/// One MP4 per camera from its RGB frames (H.264, the takes' frame rate over the stride), or
/// why none was written.
fn write_mp4s(r: &Renderer, frames: &[usize], dir: &Path, names: &[String]) -> Result<Vec<String>, String> {
    let ffmpeg = which("ffmpeg").ok_or("ffmpeg is not on PATH: no MP4 written (the PNG frames are)")?;
    let t = &r.actors[0].take.times;
    let span = match (frames.first(), frames.last()) {
        (Some(&a), Some(&b)) if b > a => t[b] - t[a],
        _ => 0.0,
    };
    let fps = if span > 0.0 { (frames.len() - 1) as f64 / span } else { 25.0 };
    let mut out = Vec::new();
    for n in names {
        let file = dir.join(format!("{n}.mp4"));
        let tmp = dir.join(format!("{n}.tmp{}.mp4", std::process::id()));
        let status = std::process::Command::new(&ffmpeg)
            .args(["-y", "-loglevel", "error", "-framerate", &format!("{fps:.6}"), "-pattern_type", "glob", "-i"])
            .arg(dir.join(n).join("rgb").join("*.png"))
            .args(["-c:v", "libx264", "-pix_fmt", "yuv420p", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"])
            .arg(&tmp)
            .status()
            .map_err(|e| format!("running {}: {e}", ffmpeg.display()))?;
        if !status.success() {
            let _ = std::fs::remove_file(&tmp);
            return Err(format!("ffmpeg failed ({status}) on {}", dir.join(n).display()));
        }
        std::fs::rename(&tmp, &file).map_err(|e| format!("{}: {e}", file.display()))?;
        out.push(file.display().to_string());
    }
    Ok(out)
}
