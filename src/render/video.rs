//! Rendering solved subjects through a camera rig: per frame and camera the images of
//! [`super::raster`] and each subject's keypoints (model markers, then joint centres) with their
//! visibility ([`super::visibility`]) and depths. [`Renderer`] draws frames into memory (the
//! Python binding uses it as is); [`super::video_out`] writes them to a folder.

use super::raster::{Gpu, Images, RasterError, Rasterizer, Scene};
use super::rig::{Camera, Pixel};
use super::take::Take;
use super::visibility::{self, Kind, Labels};
use crate::body::{BodyAsset, Dressed, PoseWorkspace, SubjectBody};
use crate::kinematics::Workspace;
use nalgebra::Vector3;

/// A subject to draw: its take and its body dressed on the take's model.
pub struct Actor {
    pub take: Take,
    pub body: Dressed,
}

impl Actor {
    /// Dresses `take`'s subject (`sub`: what its file says of it) with the shipped body; the
    /// summary line of [`crate::body::dress_subject`] beside it.
    pub fn dress(take: Take, asset: &BodyAsset, sub: &SubjectBody) -> Result<(Actor, String), crate::body::BindError> {
        let (body, line) = crate::body::dress_subject(&take.model, &take.world_from_model, asset, &take.scales, sub)?;
        Ok((Actor { take, body }, line))
    }
}

/// One subject's keypoints in one image.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Keypoints {
    /// `[x, y, v]` per keypoint (COCO; x = y = 0 where v = 0).
    pub xyv: Vec<f64>,
    /// Depth along the camera axis (m) per keypoint.
    pub depths_m: Vec<f64>,
    /// Keypoints with v > 0.
    pub labelled: usize,
    /// `[x, y, w, h]` (px, pixel edges) of the subject's mask pixels and visible keypoints.
    pub bbox: [f64; 4],
    /// The subject's mask pixels.
    pub area: usize,
}

/// Draws frames of one scene: the actors share the cameras, the floor and the lighting.
pub struct Renderer {
    pub actors: Vec<Actor>,
    pub cameras: Vec<Camera>,
    pub scene: Scene,
    pub labels: Vec<Labels>,
    raster: Rasterizer,
    origin: Vector3<f64>,
    vertices: Vec<[f32; 3]>,
    pose: Vec<(PoseWorkspace, Vec<f64>)>,
    kin: Vec<Workspace>,
}

/// Per subject, whether each model body carries skin (is some vertex's largest influence).
fn skinned(actor: &Actor) -> Vec<bool> {
    let mut s = vec![false; actor.take.model.nb()];
    for inf in &actor.body.binding.influences {
        s[inf[0].body as usize] = true;
    }
    s
}

impl Renderer {
    /// A renderer of `actors` (their frames matched by position) through `cameras`, each
    /// subject's look from `seed` ([`super::look`]); `scene` surrounds them. Labels: subject
    /// `k`'s body `b` is `1 + Σ_{j<k} bodies_j + b`.
    pub fn new(gpu: Gpu, actors: Vec<Actor>, cameras: Vec<Camera>, scene: Scene, seed: u64) -> Renderer {
        let asset = BodyAsset::shipped().expect("the shipped body asset was read to dress the actors");
        let (mut fixed, mut triangles, mut labels) = (Vec::new(), Vec::new(), Vec::new());
        let mut first = 1u16;
        for (k, a) in actors.iter().enumerate() {
            let base = fixed.len() as u32;
            super::look::fixed_attributes(&asset, &a.body, &super::look::Look::seeded(seed, k), first, &mut fixed);
            triangles.extend(a.body.triangles.iter().map(|t| t.map(|i| i + base)));
            labels.push(Labels::new(&a.take.model, first, &skinned(a)));
            first += a.take.model.nb() as u16;
        }
        let raster = Rasterizer::new(gpu, &fixed, &triangles);
        let frame = super::subject_frame(&actors[0].take);
        let origin = frame.origin + Vector3::z() * frame.root_height;
        let pose = actors.iter().map(|a| (PoseWorkspace::new(&a.take.model, &a.body), vec![0.0; a.take.model.ny()]));
        let kin = actors.iter().map(|a| Workspace::new(&a.take.model)).collect();
        Renderer {
            pose: pose.collect(),
            kin,
            vertices: Vec::with_capacity(fixed.len()),
            actors,
            cameras,
            scene,
            labels,
            raster,
            origin,
        }
    }

    /// Frames the actors have in common (the shortest take's).
    pub fn len(&self) -> usize {
        self.actors.iter().map(|a| a.take.len()).min().unwrap_or(0)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The adapter drawn on.
    pub fn adapter(&self) -> &str {
        self.raster.adapter()
    }

    /// The largest label in the mask.
    pub fn max_label(&self) -> u16 {
        self.labels.last().map_or(0, |l| l.first + l.count - 1)
    }

    /// Draws frame `i` (position in the takes) through every camera into `out`.
    pub fn draw(&mut self, i: usize, out: &mut [Images]) -> Result<(), RasterError> {
        self.vertices.clear();
        for (a, (ws, y)) in self.actors.iter().zip(&mut self.pose) {
            let nq = a.take.model.nq();
            y[..nq].copy_from_slice(&a.take.q[i]);
            y[nq..].copy_from_slice(&a.take.scales);
            a.body.pose(&a.take.model, y, ws);
            self.vertices.extend_from_slice(&ws.vertices);
        }
        self.raster.set_pose(&self.vertices, self.origin);
        self.raster.draw(&self.cameras, &self.scene, out)
    }

    /// Subject `k`'s keypoints at frame `i` in camera `c`, whose images of that frame are
    /// `img`: each point projected, its visibility tested on the images, the box and area from
    /// the mask.
    pub fn keypoints(&mut self, k: usize, i: usize, c: usize, img: &Images, out: &mut Keypoints) {
        let take = &self.actors[k].take;
        let pose = take.pose(i, &mut self.kin[k]);
        let cam = &self.cameras[c];
        let labels = &self.labels[k];
        let nm = pose.markers.len();
        out.xyv.clear();
        out.depths_m.clear();
        out.labelled = 0;
        let (bx, area) = visibility::mask_box(img, labels).unwrap_or(([0.0; 4], 0));
        let (mut lo, mut hi) = ([bx[0], bx[1]], [bx[0] + bx[2], bx[1] + bx[3]]);
        if area == 0 {
            (lo, hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        }
        for (j, p) in pose.markers.iter().chain(&pose.joints).enumerate() {
            let px: Pixel = cam.project(p);
            let kind = if j < nm { Kind::Surface } else { Kind::Inside(j - nm) };
            let v = visibility::visibility(&px, kind, img, labels);
            out.depths_m.push(px.depth);
            if v == 0 {
                out.xyv.extend([0.0, 0.0, 0.0]);
                continue;
            }
            out.xyv.extend([px.u, px.v, v as f64]);
            out.labelled += 1;
            if v == 2 {
                lo = [lo[0].min(px.u), lo[1].min(px.v)];
                hi = [hi[0].max(px.u), hi[1].max(px.v)];
            }
        }
        out.area = area;
        out.bbox = if lo[0] <= hi[0] { [lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]] } else { [0.0; 4] };
    }
}

/// The rig's cameras at `size` (px) where given: the same position, orientation, focal length
/// and sensor, the intrinsics of the new image size (horizontal fit, principal point at the
/// centre), as [`Camera::new`] makes them.
pub fn resized(cameras: Vec<Camera>, size: Option<(u32, u32)>) -> Vec<Camera> {
    let Some((w, h)) = size else { return cameras };
    cameras.into_iter().map(|c| Camera::new(&c.name, c.centre(), c.r, c.focal_mm, c.sensor_width_mm, w, h)).collect()
}
