//! `render`: a converted trial drawn through a camera rig into NumPy arrays, without files
//! (`smocap::render::video`, as `smocap render` draws it).

use crate::errors::{to_py, SmocapError};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use smocap::render::raster::Images;
use smocap::render::video::{scene_renderer, Keypoints};
use std::path::PathBuf;

/// One camera's frames, stacked.
#[derive(Default)]
struct Stack {
    rgb: Vec<u8>,
    mask: Vec<u16>,
    depth: Vec<f32>,
    keypoints: Vec<f64>,
    depths: Vec<f64>,
}

/// Renders `trial` (a `.mcap` from `smocap convert`) at `frames` (trial frame numbers; all by
/// default) through `cameras` (a rig file; the default rig by default) at `size` (w, h).
#[pyfunction]
#[pyo3(signature = (trial, cameras=None, size=None, frames=None, seed=0))]
pub fn render<'py>(
    py: Python<'py>,
    trial: PathBuf,
    cameras: Option<PathBuf>,
    size: Option<(u32, u32)>,
    frames: Option<Vec<usize>>,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let name = trial.file_stem().map_or("trial".into(), |s| s.to_string_lossy().into_owned());
    let run = || -> Result<_, smocap::render::RenderError> {
        let mut r = scene_renderer(std::slice::from_ref(&trial), cameras.as_deref(), size, seed, &name, None)?;
        let take_frames = &r.actors[0].take.frames;
        let at: Vec<usize> = match &frames {
            None => (0..r.len()).collect(),
            Some(f) => f
                .iter()
                .map(|n| {
                    take_frames.iter().position(|g| g == n).ok_or_else(|| smocap::render::RenderError::Content {
                        file: trial.display().to_string(),
                        what: format!("no frame {n}"),
                    })
                })
                .collect::<Result<_, _>>()?,
        };
        let numbers: Vec<usize> = at.iter().map(|&i| take_frames[i]).collect();
        let mut stacks: Vec<Stack> = r.cameras.iter().map(|_| Stack::default()).collect();
        let mut images = vec![Images::default(); r.cameras.len()];
        let mut kp = Keypoints::default();
        for &i in &at {
            r.draw(i, &mut images)?;
            for (c, (img, s)) in images.iter().zip(&mut stacks).enumerate() {
                s.rgb.extend_from_slice(&img.rgb);
                s.mask.extend_from_slice(&img.mask);
                s.depth.extend_from_slice(&img.depth_m);
                r.keypoints(0, i, c, img, &mut kp);
                s.keypoints.extend_from_slice(&kp.xyv);
                s.depths.extend_from_slice(&kp.depths_m);
            }
        }
        Ok((r, numbers, stacks))
    };
    let (r, numbers, stacks) = py.detach(run).map_err(to_py::<SmocapError>)?;
    let out = PyDict::new(py);
    let n = numbers.len();
    let (names, kinds) = r.keypoint_names(0);
    let k = names.len();
    for (cam, s) in r.cameras.iter().zip(stacks) {
        let (w, h) = (cam.width_px as usize, cam.height_px as usize);
        let d = PyDict::new(py);
        d.set_item("rgb", PyArray1::from_vec(py, s.rgb).reshape([n, h, w, 3])?)?;
        d.set_item("mask", PyArray1::from_vec(py, s.mask).reshape([n, h, w])?)?;
        d.set_item("depth", PyArray1::from_vec(py, s.depth).reshape([n, h, w])?)?;
        d.set_item("keypoints", PyArray1::from_vec(py, s.keypoints).reshape([n, k, 3])?)?;
        d.set_item("keypoint_depths_m", PyArray1::from_vec(py, s.depths).reshape([n, k])?)?;
        d.set_item("camera", crate::to_python(py, &smocap::render::project::camera_json(cam))?)?;
        out.set_item(&cam.name, d)?;
    }
    out.set_item("frames", numbers)?;
    out.set_item("keypoint_names", names)?;
    out.set_item("keypoint_kinds", kinds)?;
    Ok(out)
}
