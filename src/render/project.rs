//! 2D ground truth: every model marker, joint centre and observed marker of a take projected
//! into each camera, per frame; the cameras' matrices (OpenCV convention); and the thesis'
//! metrics (mean 3D marker error, mean marker pixel error per camera).
//!
//! Written into one folder:
//! - `cameras.json`: per camera `K`, `R`, `t` (world → camera, m), `dist` (zeros), image size,
//!   centre (m), focal length and sensor width (mm);
//! - `<camera>.coco.json`: COCO keypoint layout, one image per frame (`frame`, `time_s`), two
//!   categories with their keypoint names listed once: `model` (model markers, then joint
//!   centres named by their body; `skeleton` joins each joint centre to its parent's) and
//!   `observed` (the observed markers, model marker order). `visibility` 2: in front of the
//!   camera and inside the image; 0 otherwise (then x = y = 0, as COCO has it; the CSV keeps the
//!   coordinates). No occlusion test: 1 is not used.
//! - `keypoints.csv`: one row per camera, frame and point (observed markers only where observed):
//!   `camera,frame,time_s,kind,name,x_m,y_m,z_m,u_px,v_px,depth_m,in_image` (world x y z);
//! - `metrics.json`: [`Metrics`].

use super::body_truth::BodyTruth;
use super::rig::{Camera, Pixel};
use super::take::Take;
use super::{write_file, RenderError};
use crate::body::keypoints::{NAMES as SURFACE_NAMES, SKELETON as SURFACE_SKELETON};
use crate::kinematics::Workspace;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use serde_json::{json, Value};
use std::path::Path;

/// A COCO keypoint file of one camera.
#[derive(Debug, Serialize)]
struct CocoFile {
    info: Value,
    camera: Value,
    categories: Value,
    images: Vec<CocoImage>,
    annotations: Vec<CocoAnnotation>,
}

/// One COCO image: a camera's view of one frame.
#[derive(Clone, Debug, Serialize)]
struct CocoImage {
    id: usize,
    file_name: String,
    width: u32,
    height: u32,
    frame: usize,
    time_s: f64,
}

/// One COCO keypoint annotation (a category's keypoints in one image).
#[derive(Clone, Debug, Serialize)]
struct CocoAnnotation {
    id: usize,
    image_id: usize,
    category_id: usize,
    keypoints: Vec<f64>,
    num_keypoints: usize,
    bbox: [f64; 4],
    area: f64,
    iscrowd: u8,
}

/// The thesis' metrics of one trial.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Metrics {
    pub trial: String,
    /// Frames projected.
    pub frames: usize,
    /// Mean distance (mm) between observed and model markers, over every observed marker of
    /// every projected frame; `None` when nothing was observed.
    pub marker_error_mm: Option<f64>,
    /// Observed markers counted.
    pub observed: usize,
    /// Mean distance (mm) between the body's virtual markers and the model's markers (the
    /// thesis' "marker spatial error"; [`crate::body::virtual_markers`]), over every skin marker
    /// and projected frame; `None` without a body.
    pub virtual_marker_error_mm: Option<f64>,
    /// The same over landmark markers only.
    pub virtual_landmark_error_mm: Option<f64>,
    pub cameras: Vec<CameraMetrics>,
}

/// One camera's pixel error.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct CameraMetrics {
    pub camera: String,
    /// Mean distance (px) between the projections of observed and model markers, over the pairs
    /// both inside the image; `None` when there are none.
    pub marker_error_px: Option<f64>,
    pub pairs: usize,
    /// Mean distance (px) between the projections of the virtual and the model's markers (the
    /// thesis' "marker pixel error"), over the pairs both inside the image; `None` without a body.
    pub virtual_marker_error_px: Option<f64>,
}

fn matrix(m: &Matrix3<f64>) -> Value {
    json!([[m[(0, 0)], m[(0, 1)], m[(0, 2)]], [m[(1, 0)], m[(1, 1)], m[(1, 2)]], [m[(2, 0)], m[(2, 1)], m[(2, 2)]]])
}

/// A camera as JSON (OpenCV matrices).
pub fn camera_json(c: &Camera) -> Value {
    let centre = c.centre();
    json!({
        "name": c.name,
        "K": matrix(&c.k),
        "R": matrix(&c.r),
        "t": [c.t.x, c.t.y, c.t.z],
        "dist": [0.0, 0.0, 0.0, 0.0, 0.0],
        "width": c.width_px,
        "height": c.height_px,
        "centre_m": [centre.x, centre.y, centre.z],
        "focal_mm": c.focal_mm,
        "sensor_width_mm": c.sensor_width_mm,
    })
}

/// `number` as CSV text: shortest round-trip decimal.
fn num(v: f64) -> String {
    format!("{v}")
}

fn pretty(v: &Value) -> Vec<u8> {
    let mut s = serde_json::to_vec_pretty(v).expect("JSON values serialise");
    s.push(b'\n');
    s
}

/// The names of the `model` category's keypoints: markers, then joint centres (a body's name,
/// `joint:<body>` where a marker has that name).
pub fn keypoint_names(take: &Take) -> Vec<String> {
    let m = &take.model;
    let mut names: Vec<String> = m.markers.iter().map(|k| k.name.clone()).collect();
    for b in &m.bodies {
        let clash = m.markers.iter().any(|k| k.name == b.name);
        names.push(if clash { format!("joint:{}", b.name) } else { b.name.clone() });
    }
    names
}

/// COCO keypoints `[x, y, v, …]` and the count and bounding box of the visible ones.
fn coco_keypoints(pixels: &[Option<Pixel>]) -> (Vec<f64>, usize, [f64; 4]) {
    let mut kp = Vec::with_capacity(3 * pixels.len());
    let (mut lo, mut hi, mut n) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2], 0);
    for p in pixels {
        match p.filter(|p| p.in_image) {
            Some(p) => {
                kp.extend([p.u, p.v, 2.0]);
                lo = [lo[0].min(p.u), lo[1].min(p.v)];
                hi = [hi[0].max(p.u), hi[1].max(p.v)];
                n += 1;
            }
            None => kp.extend([0.0, 0.0, 0.0]),
        }
    }
    let bbox = if n > 0 { [lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]] } else { [0.0; 4] };
    (kp, n, bbox)
}

/// Projects the frames `frames` of `take` into `cameras`, writes the files above into `dir` and
/// returns the metrics.
pub fn write_ground_truth(
    take: &Take,
    cameras: &[Camera],
    frames: &[usize],
    dir: &Path,
    mut body: Option<&mut BodyTruth>,
) -> Result<Metrics, RenderError> {
    let model = &take.model;
    let names = keypoint_names(take);
    let nm = model.markers.len();
    let marker_names: Vec<&str> = model.markers.iter().map(|m| m.name.as_str()).collect();
    let skeleton: Vec<[usize; 2]> =
        model.bodies.iter().enumerate().filter_map(|(b, body)| Some([nm + body.parent? + 1, nm + b + 1])).collect();
    let kinds: Vec<&str> = (0..names.len()).map(|i| if i < nm { "marker" } else { "joint" }).collect();
    let mut images = vec![Vec::new(); cameras.len()];
    let mut annotations = vec![Vec::new(); cameras.len()];
    let csv_path = dir.join("keypoints.csv");
    let csv_file = csv_path.display().to_string();
    let cv = |e: csv::Error| RenderError::Content { file: csv_file.clone(), what: e.to_string() };
    std::fs::create_dir_all(dir).map_err(|source| RenderError::Io { file: dir.display().to_string(), source })?;
    // Streamed to the file: a long trial's rows need not fit in memory.
    let mut csv = csv::Writer::from_path(&csv_path).map_err(cv)?;
    csv.write_record([
        "camera", "frame", "time_s", "kind", "name", "x_m", "y_m", "z_m", "u_px", "v_px", "depth_m", "in_image",
    ])
    .map_err(cv)?;
    let (mut err3, mut n3) = (0.0, 0usize);
    let mut errpx = vec![(0.0, 0usize); cameras.len()];
    let mut virt = VirtualErrors::new(cameras.len());
    let mut ws = Workspace::new(model);
    for (k, &i) in frames.iter().enumerate() {
        let pose = take.pose(i, &mut ws);
        for (m, o) in pose.observed.iter().enumerate() {
            if let Some(o) = o {
                err3 += (o - pose.markers[m]).norm();
                n3 += 1;
            }
        }
        let mut points: Vec<(&str, &str, Vector3<f64>)> =
            (pose.markers.iter().enumerate().map(|(m, p)| ("marker", marker_names[m], *p)))
                .chain(pose.joints.iter().enumerate().map(|(b, p)| ("joint", names[nm + b].as_str(), *p)))
                .chain(pose.observed.iter().enumerate().filter_map(|(m, p)| Some(("observed", marker_names[m], (*p)?))))
                .collect();
        if let Some(b) = body.as_deref_mut() {
            b.at(take, i);
            virt.add_spatial(b, &pose.markers);
            points.extend(b.surface.iter().zip(SURFACE_NAMES).map(|(p, n)| ("surface", n, Vector3::from(*p))));
            let vm = &b.virtual_markers.markers;
            points.extend(vm.iter().zip(&b.virtual_points).map(|(v, p)| ("virtual", marker_names[v.marker], *p)));
        }
        for (c, cam) in cameras.iter().enumerate() {
            let image_id = k + 1;
            images[c].push(CocoImage {
                id: image_id,
                file_name: format!("{}/{:06}.png", cam.name, take.frames[i]),
                width: cam.width_px,
                height: cam.height_px,
                frame: take.frames[i],
                time_s: take.times[i],
            });
            let model_px: Vec<Option<Pixel>> =
                pose.markers.iter().chain(&pose.joints).map(|p| Some(cam.project(p))).collect();
            let obs_px: Vec<Option<Pixel>> = pose.observed.iter().map(|o| o.map(|p| cam.project(&p))).collect();
            for (m, o) in obs_px.iter().enumerate() {
                if let (Some(o), Some(p)) = (o, model_px[m]) {
                    if o.in_image && p.in_image {
                        errpx[c].0 += ((o.u - p.u).powi(2) + (o.v - p.v).powi(2)).sqrt();
                        errpx[c].1 += 1;
                    }
                }
            }
            let body_px: Vec<Option<Pixel>> = match body.as_deref() {
                Some(b) => {
                    virt.add_pixels(c, cam, b, &pose.markers);
                    b.surface.iter().map(|p| Some(cam.project(&Vector3::from(*p)))).collect()
                }
                None => Vec::new(),
            };
            for (cat, px) in [(1, &model_px), (2, &obs_px), (3, &body_px)] {
                if cat == 3 && body.is_none() {
                    continue;
                }
                let (kp, n, bbox) = coco_keypoints(px);
                annotations[c].push(CocoAnnotation {
                    // the body's after every frame's model and observed annotations
                    id: if cat == 3 { 2 * frames.len() + k + 1 } else { 2 * k + cat },
                    image_id,
                    category_id: cat,
                    keypoints: kp,
                    num_keypoints: n,
                    bbox,
                    area: bbox[2] * bbox[3],
                    iscrowd: 0,
                });
            }
            for (kind, name, p) in &points {
                let px = cam.project(p);
                csv.write_record([
                    cam.name.clone(),
                    take.frames[i].to_string(),
                    num(take.times[i]),
                    kind.to_string(),
                    name.to_string(),
                    num(p.x),
                    num(p.y),
                    num(p.z),
                    num(px.u),
                    num(px.v),
                    num(px.depth),
                    (px.in_image as u8).to_string(),
                ])
                .map_err(cv)?;
            }
        }
    }
    csv.flush().map_err(|source| RenderError::Io { file: csv_path.display().to_string(), source })?;
    drop(csv);
    write_file(
        &dir.join("cameras.json"),
        &pretty(&json!({ "cameras": cameras.iter().map(camera_json).collect::<Vec<_>>() })),
    )?;
    for (c, cam) in cameras.iter().enumerate() {
        let coco = CocoFile {
            info: json!({
                "description": format!("smocap ground truth of {} from camera {}", take.name, cam.name),
                "version": env!("CARGO_PKG_VERSION"),
            }),
            camera: camera_json(cam),
            categories: {
                let mut cats = json!([
                    { "id": 1, "name": "model", "supercategory": "person", "keypoints": names, "keypoint_kinds": kinds, "skeleton": skeleton },
                    { "id": 2, "name": "observed", "supercategory": "person", "keypoints": marker_names, "skeleton": [] },
                ]);
                if body.is_some() {
                    cats.as_array_mut().expect("an array").push(json!(
                        { "id": 3, "name": "body", "supercategory": "person", "keypoints": SURFACE_NAMES, "skeleton": SURFACE_SKELETON }
                    ));
                }
                cats
            },
            images: std::mem::take(&mut images[c]),
            annotations: std::mem::take(&mut annotations[c]),
        };
        let path = dir.join(format!("{}.coco.json", cam.name));
        let io = |source| RenderError::Io { file: path.display().to_string(), source };
        let mut w = std::io::BufWriter::new(std::fs::File::create(&path).map_err(io)?);
        serde_json::to_writer(&mut w, &coco).map_err(|e| io(e.into()))?;
        std::io::Write::flush(&mut w).map_err(io)?;
    }
    let metrics = Metrics {
        trial: take.name.clone(),
        frames: frames.len(),
        marker_error_mm: (n3 > 0).then(|| err3 / n3 as f64 * 1e3),
        observed: n3,
        virtual_marker_error_mm: mean(virt.all).map(|e| e * 1e3),
        virtual_landmark_error_mm: mean(virt.landmarks).map(|e| e * 1e3),
        cameras: cameras
            .iter()
            .zip(&errpx)
            .zip(&virt.px)
            .map(|((c, &(s, n)), &v)| CameraMetrics {
                camera: c.name.clone(),
                marker_error_px: (n > 0).then(|| s / n as f64),
                pairs: n,
                virtual_marker_error_px: mean(v),
            })
            .collect(),
    };
    write_file(&dir.join("metrics.json"), &pretty(&serde_json::to_value(&metrics).expect("metrics serialise")))?;
    Ok(metrics)
}

/// `(sum, count)` to a mean; `None` when nothing was counted.
fn mean((s, n): (f64, usize)) -> Option<f64> {
    (n > 0).then(|| s / n as f64)
}

/// Sums of the virtual markers' distances to the model's markers: in space (m; all, and
/// landmarks) and per camera in pixels (both inside the image).
struct VirtualErrors {
    all: (f64, usize),
    landmarks: (f64, usize),
    px: Vec<(f64, usize)>,
}

impl VirtualErrors {
    fn new(cameras: usize) -> VirtualErrors {
        VirtualErrors { all: (0.0, 0), landmarks: (0.0, 0), px: vec![(0.0, 0); cameras] }
    }

    fn add_spatial(&mut self, b: &BodyTruth, markers: &[Vector3<f64>]) {
        for (v, p) in b.virtual_markers.markers.iter().zip(&b.virtual_points) {
            let d = (p - markers[v.marker]).norm();
            self.all = (self.all.0 + d, self.all.1 + 1);
            if v.landmark {
                self.landmarks = (self.landmarks.0 + d, self.landmarks.1 + 1);
            }
        }
    }

    fn add_pixels(&mut self, c: usize, cam: &Camera, b: &BodyTruth, markers: &[Vector3<f64>]) {
        for (v, p) in b.virtual_markers.markers.iter().zip(&b.virtual_points) {
            let (a, m) = (cam.project(p), cam.project(&markers[v.marker]));
            if a.in_image && m.in_image {
                let e = &mut self.px[c];
                *e = (e.0 + ((a.u - m.u).powi(2) + (a.v - m.v).powi(2)).sqrt(), e.1 + 1);
            }
        }
    }
}

/// Projects named `world` points (m) into `cameras`: `cameras.json` and `points.csv`
/// (`camera,name,x_m,y_m,z_m,u_px,v_px,depth_m,in_image`) into `dir`.
pub fn write_points(points: &[(String, Vector3<f64>)], cameras: &[Camera], dir: &Path) -> Result<(), RenderError> {
    let path = dir.join("points.csv");
    let cv = |e: csv::Error| RenderError::Content { file: path.display().to_string(), what: e.to_string() };
    let mut csv = csv::Writer::from_writer(Vec::new());
    csv.write_record(["camera", "name", "x_m", "y_m", "z_m", "u_px", "v_px", "depth_m", "in_image"]).map_err(cv)?;
    for cam in cameras {
        for (name, p) in points {
            let px = cam.project(p);
            let row = [num(p.x), num(p.y), num(p.z), num(px.u), num(px.v), num(px.depth)];
            let mut rec = vec![cam.name.clone(), name.clone()];
            rec.extend(row);
            rec.push((px.in_image as u8).to_string());
            csv.write_record(&rec).map_err(cv)?;
        }
    }
    let bytes =
        csv.into_inner().map_err(|e| RenderError::Content { file: path.display().to_string(), what: e.to_string() })?;
    write_file(&path, &bytes)?;
    write_file(
        &dir.join("cameras.json"),
        &pretty(&json!({ "cameras": cameras.iter().map(camera_json).collect::<Vec<_>>() })),
    )
}

/// Reads named points from a CSV with columns `name,x,y,z` (m, `world`; a header row).
pub fn read_points(path: &Path) -> Result<Vec<(String, Vector3<f64>)>, RenderError> {
    let file = path.display().to_string();
    let bad = |what: String| RenderError::Content { file: file.clone(), what };
    let mut r = csv::Reader::from_path(path).map_err(|e| bad(e.to_string()))?;
    let mut out = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| bad(e.to_string()))?;
        let line = i + 2;
        if rec.len() != 4 {
            return Err(bad(format!("line {line}: expected name,x,y,z, found {} fields", rec.len())));
        }
        let v = |k: usize| {
            rec[k].trim().parse::<f64>().map_err(|_| bad(format!("line {line}: '{}' is not a number", &rec[k])))
        };
        out.push((rec[0].to_string(), Vector3::new(v(1)?, v(2)?, v(3)?)));
    }
    Ok(out)
}

/// A Markdown table of metrics: trial, frames, 3D marker error (mm), then per camera the pixel error.
pub fn metrics_table(rows: &[Metrics]) -> String {
    let cams: Vec<String> =
        rows.first().map(|m| m.cameras.iter().map(|c| c.camera.clone()).collect()).unwrap_or_default();
    let body = rows.iter().any(|m| m.virtual_marker_error_mm.is_some());
    let mut s = String::from("| trial | frames | 3D marker error (mm) |");
    for c in &cams {
        s += &format!(" {c} (px) |");
    }
    if body {
        s += " virtual markers (mm) |";
        for c in &cams {
            s += &format!(" virtual {c} (px) |");
        }
    }
    s += "\n|---|---:|---:|";
    s += &"---:|".repeat(cams.len() + if body { 1 + cams.len() } else { 0 });
    s.push('\n');
    let f = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
    for m in rows {
        s += &format!("| {} | {} | {} |", m.trial, m.frames, f(m.marker_error_mm, 2));
        for c in &m.cameras {
            s += &format!(" {} |", f(c.marker_error_px, 2));
        }
        if body {
            s += &format!(" {} |", f(m.virtual_marker_error_mm, 2));
            for c in &m.cameras {
                s += &format!(" {} |", f(c.virtual_marker_error_px, 2));
            }
        }
        s.push('\n');
    }
    s
}
