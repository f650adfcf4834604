//! Rendering solved subjects through a camera rig: per frame and camera the images of
//! [`super::raster`] and each subject's keypoints with their visibility ([`super::visibility`])
//! and depths: the body's surface keypoints (COCO-17 + feet, [`crate::body::keypoints`]; its
//! joints, shoulders to ankles, lie inside the body), the model's joint centres, its markers. [`Renderer`] draws frames into memory (the
//! Python binding uses it as is); [`super::video_out`] writes them to a folder.

use super::raster::{Gpu, Images, RasterError, Rasterizer, Scene};
use super::rig::{Camera, Pixel};
use super::take::Take;
use super::visibility::{self, Kind, Labels};
use crate::body::keypoints::SurfaceKeypoints;
use crate::body::{BodyAsset, Dressed, PoseWorkspace, SubjectBody};
use crate::kinematics::Workspace;
use nalgebra::Vector3;

/// A subject to draw: its take and its body dressed on the take's model.
pub struct Actor {
    pub take: Take,
    pub body: Dressed,
}

impl Actor {
    /// Dresses `take`'s subject (`sub`: what its file says of it) with the shipped body, fitted
    /// to its markers as `smocap export` fits it ([`Take::dress`], default settings); the
    /// summary line beside it.
    pub fn dress(take: Take, asset: &BodyAsset, sub: &SubjectBody) -> Result<(Actor, String), crate::body::BindError> {
        let (body, line) = take.dress(asset, sub, &crate::body::FitSettings::default())?;
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

/// Wall time (s) of [`Renderer::draw`]'s phases, summed over frames.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Phases {
    /// Posing (forward kinematics, skinning), surface keypoints, vertex normals and the upload.
    pub pose_s: f64,
    /// The render passes and the read-back (on lavapipe: the rasterization itself).
    pub draw_s: f64,
}

/// Draws frames of one scene: the actors share the cameras, the floor and the lighting.
pub struct Renderer {
    pub actors: Vec<Actor>,
    /// Time spent so far, by phase.
    pub phases: Phases,
    /// A picture behind the bodies instead of the floor and background colour.
    pub backdrop: Option<super::backdrop::Backdrop>,
    pub cameras: Vec<Camera>,
    pub scene: Scene,
    pub labels: Vec<Labels>,
    raster: Rasterizer,
    origin: Vector3<f64>,
    vertices: Vec<[f32; 3]>,
    pose: Vec<(PoseWorkspace, Vec<f64>)>,
    kin: Vec<Workspace>,
    /// Per subject, the bodies, joints and markers of the frame drawn last.
    posed: Vec<Option<super::take::Pose>>,
    surface: SurfaceKeypoints,
    /// Per subject, each surface keypoint's kind (inside: its body, the largest influence's).
    surface_kinds: Vec<Vec<Kind>>,
    /// Per subject, the surface keypoints of the frame drawn last (`world`, m), and that frame.
    surface_at: Vec<Vec<[f64; 3]>>,
    drawn: Option<usize>,
}

/// The kinds of `surface`'s keypoints on `body`: a single vertex is on the skin; a combination
/// (a joint regressor) is inside, at the body carrying most of its weight.
fn surface_kinds(surface: &SurfaceKeypoints, body: &Dressed, nb: usize) -> Vec<Kind> {
    let mut weight = vec![0.0f64; nb];
    surface
        .combos
        .iter()
        .map(|c| {
            if c.len() == 1 {
                return Kind::Skin;
            }
            weight.iter_mut().for_each(|w| *w = 0.0);
            for &(v, w) in c {
                weight[body.binding.influences[v as usize][0].body as usize] += w as f64;
            }
            Kind::Inside((0..nb).fold(0, |b, k| if weight[k] > weight[b] { k } else { b }))
        })
        .collect()
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
        let surface = SurfaceKeypoints::new(&asset);
        let kinds = actors.iter().map(|a| surface_kinds(&surface, &a.body, a.take.model.nb())).collect();
        let frame = super::subject_frame(&actors[0].take);
        let origin = frame.origin + Vector3::z() * frame.root_height;
        let pose = actors.iter().map(|a| (PoseWorkspace::new(&a.take.model, &a.body), vec![0.0; a.take.model.ny()]));
        let kin = actors.iter().map(|a| Workspace::new(&a.take.model)).collect();
        Renderer {
            phases: Phases::default(),
            backdrop: None,
            pose: pose.collect(),
            kin,
            posed: actors.iter().map(|_| None).collect(),
            surface_at: vec![Vec::new(); actors.len()],
            surface_kinds: kinds,
            surface,
            drawn: None,
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
        let t = std::time::Instant::now();
        self.vertices.clear();
        for (k, (a, (ws, y))) in self.actors.iter().zip(&mut self.pose).enumerate() {
            let nq = a.take.model.nq();
            y[..nq].copy_from_slice(&a.take.q[i]);
            y[nq..].copy_from_slice(&a.take.scales);
            a.body.pose(&a.take.model, y, ws);
            self.vertices.extend_from_slice(&ws.vertices);
            self.surface.evaluate(&ws.vertices, &mut self.surface_at[k]);
            self.posed[k] = Some(a.take.pose(i, &mut self.kin[k]));
        }
        self.drawn = Some(i);
        self.raster.set_pose(&self.vertices, self.origin);
        self.phases.pose_s += t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        self.raster.draw(&self.cameras, &self.scene, out)?;
        self.phases.draw_s += t.elapsed().as_secs_f64();
        if let Some(b) = &self.backdrop {
            out.iter_mut().for_each(|img| b.composite(img));
        }
        Ok(())
    }

    /// The keypoint names of subject `k` (surface keypoints, joint centres named by their body,
    /// `joint:<body>` where another keypoint has that name, markers) and their kinds (`surface`,
    /// `inside` for the surface set's joints, `joint`, `marker`).
    pub fn keypoint_names(&self, k: usize) -> (Vec<String>, Vec<&'static str>) {
        let m = &self.actors[k].take.model;
        let mut names: Vec<String> = crate::body::keypoints::NAMES.iter().map(|s| s.to_string()).collect();
        let mut kinds: Vec<&str> =
            self.surface_kinds[k].iter().map(|x| if *x == Kind::Skin { "surface" } else { "inside" }).collect();
        for b in &m.bodies {
            let clash = m.markers.iter().any(|x| x.name == b.name) || names.contains(&b.name);
            names.push(if clash { format!("joint:{}", b.name) } else { b.name.clone() });
            kinds.push("joint");
        }
        names.extend(m.markers.iter().map(|x| x.name.clone()));
        kinds.extend(m.markers.iter().map(|_| "marker"));
        (names, kinds)
    }

    /// Subject `k`'s keypoints (in [`Renderer::keypoint_names`]' order) at frame `i`, the frame
    /// drawn last, in camera `c`, whose images of it are `img`: each point projected, its
    /// visibility tested on the images, the box and area from the mask.
    pub fn keypoints(&mut self, k: usize, i: usize, c: usize, img: &Images, out: &mut Keypoints) {
        assert_eq!(self.drawn, Some(i), "keypoints of the frame drawn last");
        let pose = self.posed[k].as_ref().expect("drawn");
        let ns = self.surface_at[k].len();
        let surface = self.surface_at[k].iter().map(|p| Vector3::new(p[0], p[1], p[2]));
        let cam = &self.cameras[c];
        let labels = &self.labels[k];
        out.xyv.clear();
        out.depths_m.clear();
        out.labelled = 0;
        let (bx, area) = visibility::mask_box(img, labels).unwrap_or(([0.0; 4], 0));
        let (mut lo, mut hi) = ([bx[0], bx[1]], [bx[0] + bx[2], bx[1] + bx[3]]);
        if area == 0 {
            (lo, hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        }
        let nb = pose.joints.len();
        for (j, p) in surface.chain(pose.joints.iter().copied()).chain(pose.markers.iter().copied()).enumerate() {
            let px: Pixel = cam.project(&p);
            let kind = match j {
                j if j < ns => self.surface_kinds[k][j],
                j if j < ns + nb => Kind::Inside(j - ns),
                _ => Kind::Marker,
            };
            let meshes = || -> Vec<visibility::Mesh> {
                self.actors
                    .iter()
                    .zip(&self.pose)
                    .map(|(a, (ws, _))| (&ws.vertices[..], &a.body.triangles[..]))
                    .collect()
            };
            let v = visibility::visibility(&px, kind, img, labels, || {
                visibility::occluded_on_meshes(cam, &p, px.depth, &meshes())
            });
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

/// `seed` mixed with a scene's name (FNV-1a): each trial of an archive gets its own looks.
pub fn scene_seed(seed: u64, name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325u64 ^ seed, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// The renderer `smocap render` makes of converted trials `files` (one scene; the first one's
/// subject frame places the default rig): each subject dressed (its summary line on stderr), the
/// rig `rig` or the default one perturbed by `seed`, at `size`, the looks of `seed` mixed with
/// `name`, and where `backgrounds` names a folder one of its PNG pictures behind the bodies.
pub fn scene_renderer(
    files: &[std::path::PathBuf],
    rig: Option<&std::path::Path>,
    size: Option<(u32, u32)>,
    seed: u64,
    name: &str,
    backgrounds: Option<&std::path::Path>,
) -> Result<Renderer, super::RenderError> {
    let asset = BodyAsset::shipped()?;
    let mut actors = Vec::with_capacity(files.len());
    for f in files {
        let rec = crate::archive::export::read_trial_record(f)?;
        let take = Take::from_record(&rec, f)?;
        let sub = SubjectBody { stature_m: rec.subject_stature_m, info: rec.subject_info };
        let (a, line) = Actor::dress(take, &asset, &sub)?;
        eprintln!("{}: {line}", a.take.name);
        actors.push(a);
    }
    let first =
        actors.first().ok_or_else(|| super::RenderError::Content { file: name.into(), what: "no trial".into() })?;
    let cams = resized(super::cameras(&first.take, rig, seed)?, size);
    let mixed = scene_seed(seed, name);
    let mut scene = super::look::scene(mixed);
    let backdrop = match backgrounds {
        Some(dir) => {
            let all = super::backdrop::pictures(dir)?;
            scene.lighting.draw_floor = false;
            Some(super::backdrop::Backdrop::read(&all[(mixed % all.len() as u64) as usize])?)
        }
        None => None,
    };
    let mut r = Renderer::new(Gpu::new()?, actors, cams, scene, mixed);
    r.backdrop = backdrop;
    Ok(r)
}

/// The rig's cameras at `size` (px) where given: the same position, orientation, focal length
/// and sensor, the intrinsics of the new image size (horizontal fit, principal point at the
/// centre), as [`Camera::new`] makes them.
pub fn resized(cameras: Vec<Camera>, size: Option<(u32, u32)>) -> Vec<Camera> {
    let Some((w, h)) = size else { return cameras };
    cameras.into_iter().map(|c| Camera::new(&c.name, c.centre(), c.r, c.focal_mm, c.sensor_width_mm, w, h)).collect()
}
