//! Camera rigs: pinhole cameras in the OpenCV convention (camera frame x right, y down, z
//! forward; `x_cam = R · x_world + t`; pixel `u = fx·x/z + cx`, `v = fy·y/z + cy` with pixel
//! centres at integer coordinates; no distortion), read from a TOML rig file or built by default
//! around a trial.
//!
//! A rig file (`--cameras RIG.toml`):
//! ```toml
//! frame = "world"          # or "subject": coordinates in the trial's subject frame (see below)
//! [[cameras]]
//! name = "front"
//! position = [4.0, 0.0, 1.1]      # m
//! look_at = [0.0, 0.0, 1.0]       # m; or `rotation` (below), exactly one of the two
//! up = [0.0, 0.0, 1.0]            # optional with look_at: the image's up direction (default +z)
//! # rotation = [[0,-1,0],[0,0,-1],[1,0,0]]   # R: rows are the camera's x, y, z axes in the frame
//! focal_mm = 33.0
//! sensor_width_mm = 36.0          # the sensor's width spans the image's (horizontal fit)
//! width_px = 1080
//! height_px = 720
//! ```
//! Coordinates are in the Z-up `world` of the converted trial (metres), or, with
//! `frame = "subject"`, in the trial's subject frame: origin on the floor (z = 0) below the mean
//! position of the root body (pelvis), x along the walking direction, y to the subject's left, z up.

use super::RenderError;
use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::{RngExt, SeedableRng};
use serde::Deserialize;
use std::path::Path;

/// One camera: intrinsics `K`, extrinsics `R`, `t` (OpenCV), image size.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub name: String,
    /// Intrinsic matrix: `fx = fy = focal_mm / sensor_width_mm · width_px`, principal point at
    /// the image centre, `((width − 1)/2, (height − 1)/2)` px.
    pub k: Matrix3<f64>,
    /// World → camera rotation (rows: the camera's x right, y down, z forward axes in `world`).
    pub r: Matrix3<f64>,
    /// World → camera translation (m): `t = −R·c` for the camera centre `c`.
    pub t: Vector3<f64>,
    pub width_px: u32,
    pub height_px: u32,
    pub focal_mm: f64,
    pub sensor_width_mm: f64,
}

/// A point projected into a camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pixel {
    /// Pixel coordinates (px; OpenCV: pixel centres at integers, u right, v down).
    pub u: f64,
    pub v: f64,
    /// Distance along the optical axis (m); not positive: behind the camera.
    pub depth: f64,
    /// In front of the camera and within the image (`−0.5 ≤ u < width − 0.5`, likewise v).
    pub in_image: bool,
}

impl Camera {
    /// A camera at `centre` with rotation `r` (world → camera) and the given optics.
    pub fn new(
        name: &str,
        centre: Vector3<f64>,
        r: Matrix3<f64>,
        focal_mm: f64,
        sensor_width_mm: f64,
        width_px: u32,
        height_px: u32,
    ) -> Camera {
        let f = focal_mm / sensor_width_mm * width_px as f64;
        let (cx, cy) = ((width_px as f64 - 1.0) / 2.0, (height_px as f64 - 1.0) / 2.0);
        let k = Matrix3::new(f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0);
        Camera { name: name.into(), k, r, t: -(r * centre), width_px, height_px, focal_mm, sensor_width_mm }
    }

    /// The camera centre in `world` (m).
    pub fn centre(&self) -> Vector3<f64> {
        -(self.r.transpose() * self.t)
    }

    /// Vertical field of view (rad).
    pub fn yfov(&self) -> f64 {
        2.0 * crate::model::math::atan((self.height_px as f64 / 2.0) / self.k[(1, 1)])
    }

    /// Projects a `world` point (m).
    pub fn project(&self, p: &Vector3<f64>) -> Pixel {
        let c = self.r * p + self.t;
        let (u, v) = (self.k[(0, 0)] * c.x / c.z + self.k[(0, 2)], self.k[(1, 1)] * c.y / c.z + self.k[(1, 2)]);
        let inside = |x: f64, n: u32| x >= -0.5 && x < n as f64 - 0.5;
        Pixel { u, v, depth: c.z, in_image: c.z > 0.0 && inside(u, self.width_px) && inside(v, self.height_px) }
    }
}

/// The rotation (world → camera) of a camera at `centre` looking at `target` with `up` up in
/// the image; `None` when the two points coincide or the view is along `up`.
pub fn look_at(centre: &Vector3<f64>, target: &Vector3<f64>, up: &Vector3<f64>) -> Option<Matrix3<f64>> {
    let z = (target - centre).try_normalize(1e-12)?;
    let x = z.cross(up).try_normalize(1e-9)?;
    let y = z.cross(&x);
    Some(Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]))
}

/// Where the rig's coordinates are given.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RigFrame {
    /// The converted trial's Z-up `world` (default).
    #[default]
    World,
    /// The trial's [`SubjectFrame`].
    Subject,
}

/// A rig file as written (see the module documentation).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RigFile {
    #[serde(default)]
    frame: RigFrame,
    cameras: Vec<toml::Spanned<CameraSpec>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraSpec {
    name: String,
    position: [f64; 3],
    look_at: Option<[f64; 3]>,
    up: Option<[f64; 3]>,
    rotation: Option<[[f64; 3]; 3]>,
    focal_mm: f64,
    sensor_width_mm: f64,
    width_px: u32,
    height_px: u32,
}

/// The frame a default rig is placed in, from a trial: origin on the floor (z = 0 in `world`)
/// below the root body's mean position, `forward` the horizontal walking direction (the root's
/// displacement from the first to the last frame when it is at least 0.5 m, else the root body's
/// mean heading: its x axis, OpenSim's and the shipped model's forward), `left` = z × forward.
#[derive(Clone, Debug, PartialEq)]
pub struct SubjectFrame {
    pub origin: Vector3<f64>,
    pub forward: Vector3<f64>,
    pub left: Vector3<f64>,
    /// Mean height of the root body (m).
    pub root_height: f64,
    /// Half the root's path length along `forward` (m).
    pub half_path: f64,
}

impl SubjectFrame {
    /// The world frame itself (origin 0, forward +x): for rigs not tied to a trial.
    pub fn world() -> SubjectFrame {
        SubjectFrame {
            origin: Vector3::zeros(),
            forward: Vector3::x(),
            left: Vector3::y(),
            root_height: 1.0,
            half_path: 0.0,
        }
    }

    /// From the root body's `world` positions and x axes per frame.
    pub fn from_root(positions: &[Vector3<f64>], x_axes: &[Vector3<f64>]) -> SubjectFrame {
        if positions.is_empty() {
            return SubjectFrame::world();
        }
        let n = positions.len() as f64;
        let mean = positions.iter().sum::<Vector3<f64>>() / n;
        let horizontal = |v: Vector3<f64>| Vector3::new(v.x, v.y, 0.0);
        let walk = horizontal(positions[positions.len() - 1] - positions[0]);
        let heading = horizontal(x_axes.iter().sum::<Vector3<f64>>());
        let forward = if walk.norm() >= 0.5 { walk } else { heading }.try_normalize(1e-9).unwrap_or(Vector3::x());
        let left = Vector3::z().cross(&forward);
        let along: Vec<f64> = positions.iter().map(|p| (p - mean).dot(&forward)).collect();
        let (lo, hi) = along.iter().fold((0.0f64, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
        SubjectFrame {
            origin: Vector3::new(mean.x, mean.y, 0.0),
            forward,
            left,
            root_height: mean.z,
            half_path: (hi - lo) / 2.0,
        }
    }

    /// The rotation from this frame's axes to `world` (columns forward, left, up).
    pub fn world_from_subject(&self) -> Matrix3<f64> {
        Matrix3::from_columns(&[self.forward, self.left, Vector3::z()])
    }

    /// A point given in this frame, in `world`.
    pub fn to_world(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.origin + self.world_from_subject() * p
    }
}

/// The thesis' focal length (mm), sensor width (mm) and image size (px) of the default rig.
pub const DEFAULT_FOCAL_MM: f64 = 33.0;
pub const DEFAULT_SENSOR_WIDTH_MM: f64 = 36.0;
pub const DEFAULT_SIZE_PX: (u32, u32) = (1080, 720);
/// Nominal camera height above the floor (m) and its perturbation (± m).
pub const DEFAULT_HEIGHT_M: f64 = 1.1;
pub const HEIGHT_JITTER_M: f64 = 0.1;
/// Horizontal perturbation of each camera's position (± m, both horizontal axes).
pub const POSITION_JITTER_M: f64 = 0.1;
/// Least distance from the subject (m) of the frontal camera beyond the path's front end, and
/// of the sagittal camera from the path.
pub const DEFAULT_DISTANCE_M: f64 = 4.0;

/// The default rig of the thesis' setup: a frontal camera (`frontal`, ahead of the subject on
/// its walking direction, 4 m beyond the front end of the root's path, looking back along it)
/// and a sagittal one (`sagittal`, on the subject's right, far enough that the path ±1 m fills
/// at most the image's width, at least 4 m), both 1.1 ± 0.1 m above the floor and aimed at the
/// root's mean position; 33 mm focal length on a 36 mm wide sensor, 1080 × 720 px. Each position
/// is perturbed uniformly within ±0.1 m (height and both horizontal axes) by `seed`.
pub fn default_rig(frame: &SubjectFrame, seed: u64) -> Vec<Camera> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let target = frame.origin + Vector3::z() * frame.root_height;
    let half_width = DEFAULT_SENSOR_WIDTH_MM / 2.0 / DEFAULT_FOCAL_MM;
    let side = DEFAULT_DISTANCE_M.max((frame.half_path + 1.0) / half_width);
    let nominal =
        [("frontal", frame.forward * (frame.half_path + DEFAULT_DISTANCE_M)), ("sagittal", -frame.left * side)];
    nominal
        .into_iter()
        .map(|(name, offset)| {
            let mut jitter = |a: f64| rng.random_range(-a..=a);
            let (dx, dy, dz) = (jitter(POSITION_JITTER_M), jitter(POSITION_JITTER_M), jitter(HEIGHT_JITTER_M));
            let centre = frame.origin + offset + Vector3::new(dx, dy, DEFAULT_HEIGHT_M + dz);
            let r = look_at(&centre, &target, &Vector3::z()).expect("a horizontal offset of metres");
            let (w, h) = DEFAULT_SIZE_PX;
            Camera::new(name, centre, r, DEFAULT_FOCAL_MM, DEFAULT_SENSOR_WIDTH_MM, w, h)
        })
        .collect()
}

/// Reads a rig file; `frame` places rigs written in the subject frame.
pub fn read_rig(path: &Path, frame: &SubjectFrame) -> Result<Vec<Camera>, RenderError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| RenderError::Io { file: file.clone(), source })?;
    parse_rig(&text, &file, frame)
}

/// Parses a rig file's text (`file` names it in errors).
pub fn parse_rig(text: &str, file: &str, frame: &SubjectFrame) -> Result<Vec<Camera>, RenderError> {
    let rig: RigFile = toml::from_str(text).map_err(|e| RenderError::Rig { file: file.into(), what: e.to_string() })?;
    let line = |offset: usize| 1 + text[..offset.min(text.len())].matches('\n').count();
    let mut cams: Vec<Camera> = Vec::new();
    for spanned in &rig.cameras {
        let c = spanned.get_ref();
        let bad = |what: String| RenderError::Rig {
            file: file.into(),
            what: format!("line {}: camera '{}': {what}", line(spanned.span().start), c.name),
        };
        if cams.iter().any(|o| o.name == c.name) {
            return Err(bad("a second camera of that name".into()));
        }
        for (key, v) in [("focal_mm", c.focal_mm), ("sensor_width_mm", c.sensor_width_mm)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(format!("{key} = {v}: expected a positive length")));
            }
        }
        if c.width_px == 0 || c.height_px == 0 {
            return Err(bad(format!("image {} × {} px: expected positive sizes", c.width_px, c.height_px)));
        }
        let to_world = |p: &[f64; 3]| match rig.frame {
            RigFrame::World => Vector3::from(*p),
            RigFrame::Subject => frame.to_world(&Vector3::from(*p)),
        };
        let axes = match rig.frame {
            RigFrame::World => Matrix3::identity(),
            RigFrame::Subject => frame.world_from_subject(),
        };
        let centre = to_world(&c.position);
        let r = match (&c.look_at, &c.rotation) {
            (Some(target), None) => {
                let up = axes * Vector3::from(c.up.unwrap_or([0.0, 0.0, 1.0]));
                look_at(&centre, &to_world(target), &up)
                    .ok_or_else(|| bad("look_at is the position itself, or straight along `up`".into()))?
            }
            (None, Some(rows)) => {
                if c.up.is_some() {
                    return Err(bad("`up` goes with look_at, not with rotation".into()));
                }
                let r = Matrix3::from_fn(|i, j| rows[i][j]);
                if (r * r.transpose() - Matrix3::identity()).norm() > 1e-6 || r.determinant() < 0.0 {
                    return Err(bad("rotation is not a rotation matrix (orthonormal rows, determinant +1)".into()));
                }
                // Re-orthonormalised, so that a matrix written to 6 decimals is exactly a rotation.
                Rotation3::from_matrix(&r).into_inner() * axes.transpose()
            }
            (Some(_), Some(_)) => return Err(bad("give look_at or rotation, not both".into())),
            (None, None) => return Err(bad("give look_at = [x, y, z] or rotation = [[..], [..], [..]]".into())),
        };
        cams.push(Camera::new(&c.name, centre, r, c.focal_mm, c.sensor_width_mm, c.width_px, c.height_px));
    }
    if cams.is_empty() {
        return Err(RenderError::Rig { file: file.into(), what: "no [[cameras]]".into() });
    }
    Ok(cams)
}
