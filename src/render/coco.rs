//! One camera's COCO keypoint file, streamed: images and annotations go to two part files as
//! frames are rendered, and are joined into `<camera>.coco.json` at the end (memory does not grow
//! with the trial's length). Written through a temporary name and a rename.

use super::RenderError;
use serde::Serialize;
use serde_json::Value;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// One COCO image: a camera's view of one frame (paths relative to the output folder).
#[derive(Debug, Serialize)]
pub struct Image<'a> {
    pub id: usize,
    pub file_name: &'a str,
    pub mask_file: &'a str,
    pub depth_file: &'a str,
    pub width: u32,
    pub height: u32,
    pub frame: usize,
    pub time_s: f64,
}

/// One subject in one image.
#[derive(Debug, Serialize)]
pub struct Annotation<'a> {
    pub id: usize,
    pub image_id: usize,
    pub category_id: usize,
    /// `[x, y, v]` per keypoint (px, pixel centres at integers; 0, 0 where v = 0).
    pub keypoints: &'a [f64],
    /// Each keypoint's depth along the camera axis (m; negative behind the camera).
    pub keypoint_depths_m: &'a [f64],
    pub num_keypoints: usize,
    /// The subject's pixels in the mask, widened to any visible keypoint outside them (px, pixel
    /// edges), `[x, y, w, h]`; zeros when neither.
    pub bbox: [f64; 4],
    /// The subject's pixels in the mask.
    pub area: f64,
    pub iscrowd: u8,
}

/// A COCO file being written.
pub struct CocoWriter {
    path: PathBuf,
    parts: [(PathBuf, Option<BufWriter<std::fs::File>>, bool); 2],
}

impl Drop for CocoWriter {
    /// The part files go, whether the file was finished or an error stopped the render.
    fn drop(&mut self) {
        for (p, w, _) in &mut self.parts {
            drop(w.take());
            let _ = std::fs::remove_file(p);
        }
    }
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> RenderError + '_ {
    move |source| RenderError::Io { file: path.display().to_string(), source }
}

impl CocoWriter {
    /// Starts `path` (its parts beside it).
    pub fn new(path: &Path) -> Result<CocoWriter, RenderError> {
        let part = |k: &str| -> Result<_, RenderError> {
            let mut p = path.as_os_str().to_owned();
            p.push(format!(".{k}.part{}", std::process::id()));
            let p = PathBuf::from(p);
            let f = std::fs::File::create(&p).map_err(io(&p))?;
            Ok((p, Some(BufWriter::new(f)), false))
        };
        Ok(CocoWriter { path: path.to_path_buf(), parts: [part("images")?, part("annotations")?] })
    }

    fn push(&mut self, k: usize, v: &impl Serialize) -> Result<(), RenderError> {
        let (p, w, started) = &mut self.parts[k];
        let w = w.as_mut().expect("open until dropped");
        if std::mem::replace(started, true) {
            w.write_all(b",\n").map_err(io(p))?;
        }
        serde_json::to_writer(&mut *w, v).map_err(|e| io(p)(e.into()))
    }

    pub fn image(&mut self, i: &Image<'_>) -> Result<(), RenderError> {
        self.push(0, i)
    }

    pub fn annotation(&mut self, a: &Annotation<'_>) -> Result<(), RenderError> {
        self.push(1, a)
    }

    /// Joins the parts under `head` (the file's other members: info, camera, categories).
    pub fn finish(mut self, head: &serde_json::Map<String, Value>) -> Result<(), RenderError> {
        let mut tmp = self.path.as_os_str().to_owned();
        tmp.push(format!(".tmp{}", std::process::id()));
        let tmp = PathBuf::from(tmp);
        let err = io(&self.path);
        let mut out = BufWriter::new(std::fs::File::create(&tmp).map_err(&err)?);
        let head = serde_json::to_string(head).expect("JSON values serialise");
        out.write_all(&head.as_bytes()[..head.len() - 1]).map_err(&err)?;
        out.write_all(if head.len() > 2 { b",\n" } else { b"\n" }).map_err(&err)?;
        for (k, (p, w, _)) in self.parts.iter_mut().enumerate() {
            drop(w.take().expect("open until dropped").into_inner().map_err(|e| io(p)(e.into_error()))?);
            out.write_all(if k == 0 { b"\"images\": [\n" } else { b"],\n\"annotations\": [\n" }).map_err(&err)?;
            std::io::copy(&mut std::fs::File::open(&p).map_err(io(p))?, &mut out).map_err(&err)?;
        }
        out.write_all(b"]}\n").map_err(&err)?;
        out.into_inner().map_err(|e| err(e.into_error()))?.sync_all().map_err(&err)?;
        std::fs::rename(&tmp, &self.path).map_err(&err) // the part files go on drop
    }
}
