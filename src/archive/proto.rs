//! Protobuf messages of the MCAP channels, as `prost` structs mirroring `proto/`: Foxglove's
//! well-known schemas (package `foxglove`, only the fields and messages smocap writes; the
//! descriptor sets embedded in each file describe them fully) and smocap's own (package
//! `smocap`). Enum fields are plain `i32` (their wire encoding). Field numbers must match
//! `proto/foxglove/schemas.proto`, `proto/smocap/smocap.proto` and `proto/smocap/unfittable.proto`;
//! `scripts/check_mcap.py` (`tests/python_checks.rs`) decodes every message with the descriptors.

/// `google.protobuf.Timestamp`: seconds and nanoseconds since the Unix epoch.
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct Timestamp {
    #[prost(int64, tag = "1")]
    pub seconds: i64,
    #[prost(int32, tag = "2")]
    pub nanos: i32,
}

impl Timestamp {
    /// From nanoseconds since the Unix epoch.
    pub fn from_ns(ns: u64) -> Timestamp {
        Timestamp { seconds: (ns / 1_000_000_000) as i64, nanos: (ns % 1_000_000_000) as i32 }
    }
}

/// `google.protobuf.Duration`.
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct Duration {
    #[prost(int64, tag = "1")]
    pub seconds: i64,
    #[prost(int32, tag = "2")]
    pub nanos: i32,
}

/// `foxglove.Vector3`.
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct Vector3 {
    #[prost(double, tag = "1")]
    pub x: f64,
    #[prost(double, tag = "2")]
    pub y: f64,
    #[prost(double, tag = "3")]
    pub z: f64,
}

/// `foxglove.Point3` (same wire layout as [`Vector3`]).
pub type Point3 = Vector3;

/// `foxglove.Quaternion`.
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct Quaternion {
    #[prost(double, tag = "1")]
    pub x: f64,
    #[prost(double, tag = "2")]
    pub y: f64,
    #[prost(double, tag = "3")]
    pub z: f64,
    #[prost(double, tag = "4")]
    pub w: f64,
}

impl Quaternion {
    pub const IDENTITY: Quaternion = Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 };
}

/// `foxglove.Pose`.
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct Pose {
    #[prost(message, optional, tag = "1")]
    pub position: Option<Vector3>,
    #[prost(message, optional, tag = "2")]
    pub orientation: Option<Quaternion>,
}

impl Pose {
    /// The identity pose (explicit, so readers see a unit quaternion).
    pub fn identity() -> Pose {
        Pose { position: Some(Vector3::default()), orientation: Some(Quaternion::IDENTITY) }
    }
}

/// `foxglove.Color` (RGBA in [0, 1]).
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct Color {
    #[prost(double, tag = "1")]
    pub r: f64,
    #[prost(double, tag = "2")]
    pub g: f64,
    #[prost(double, tag = "3")]
    pub b: f64,
    #[prost(double, tag = "4")]
    pub a: f64,
}

/// `foxglove.FrameTransform`: the pose of `child_frame_id` in `parent_frame_id`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct FrameTransform {
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<Timestamp>,
    #[prost(string, tag = "2")]
    pub parent_frame_id: String,
    #[prost(string, tag = "3")]
    pub child_frame_id: String,
    #[prost(message, optional, tag = "4")]
    pub translation: Option<Vector3>,
    #[prost(message, optional, tag = "5")]
    pub rotation: Option<Quaternion>,
}

/// `foxglove.FrameTransforms`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct FrameTransforms {
    #[prost(message, repeated, tag = "1")]
    pub transforms: Vec<FrameTransform>,
}

/// `foxglove.PackedElementField.NumericType.FLOAT32`.
pub const FLOAT32: i32 = 7;

/// `foxglove.PackedElementField`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PackedElementField {
    #[prost(string, tag = "1")]
    pub name: String,
    #[prost(fixed32, tag = "2")]
    pub offset: u32,
    #[prost(int32, tag = "3")]
    pub r#type: i32,
}

/// `foxglove.PointCloud`: points packed as `point_stride`-byte records.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PointCloud {
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<Timestamp>,
    #[prost(string, tag = "2")]
    pub frame_id: String,
    #[prost(message, optional, tag = "3")]
    pub pose: Option<Pose>,
    #[prost(fixed32, tag = "4")]
    pub point_stride: u32,
    #[prost(message, repeated, tag = "5")]
    pub fields: Vec<PackedElementField>,
    #[prost(bytes = "vec", tag = "6")]
    pub data: Vec<u8>,
}

/// `foxglove.SpherePrimitive`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SpherePrimitive {
    #[prost(message, optional, tag = "1")]
    pub pose: Option<Pose>,
    #[prost(message, optional, tag = "2")]
    pub size: Option<Vector3>,
    #[prost(message, optional, tag = "3")]
    pub color: Option<Color>,
}

/// `foxglove.CylinderPrimitive`: along the `pose`'s z axis, `size` its bounding box (m).
#[derive(Clone, PartialEq, prost::Message)]
pub struct CylinderPrimitive {
    #[prost(message, optional, tag = "1")]
    pub pose: Option<Pose>,
    #[prost(message, optional, tag = "2")]
    pub size: Option<Vector3>,
    /// Diameter of the bottom and top faces as a share of `size` x and y (1: a cylinder).
    #[prost(double, tag = "3")]
    pub bottom_scale: f64,
    #[prost(double, tag = "4")]
    pub top_scale: f64,
    #[prost(message, optional, tag = "5")]
    pub color: Option<Color>,
}

/// `foxglove.LinePrimitive.Type.LINE_LIST`.
pub const LINE_LIST: i32 = 2;

/// `foxglove.LinePrimitive`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct LinePrimitive {
    #[prost(int32, tag = "1")]
    pub r#type: i32,
    #[prost(message, optional, tag = "2")]
    pub pose: Option<Pose>,
    #[prost(double, tag = "3")]
    pub thickness: f64,
    #[prost(bool, tag = "4")]
    pub scale_invariant: bool,
    #[prost(message, repeated, tag = "5")]
    pub points: Vec<Point3>,
    #[prost(message, optional, tag = "6")]
    pub color: Option<Color>,
}

/// `foxglove.KeyValuePair`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct KeyValuePair {
    #[prost(string, tag = "1")]
    pub key: String,
    #[prost(string, tag = "2")]
    pub value: String,
}

/// `foxglove.SceneEntity` (the primitives smocap draws).
#[derive(Clone, PartialEq, prost::Message)]
pub struct SceneEntity {
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<Timestamp>,
    #[prost(string, tag = "2")]
    pub frame_id: String,
    #[prost(string, tag = "3")]
    pub id: String,
    #[prost(message, optional, tag = "4")]
    pub lifetime: Option<Duration>,
    #[prost(bool, tag = "5")]
    pub frame_locked: bool,
    #[prost(message, repeated, tag = "6")]
    pub metadata: Vec<KeyValuePair>,
    #[prost(message, repeated, tag = "9")]
    pub spheres: Vec<SpherePrimitive>,
    #[prost(message, repeated, tag = "10")]
    pub cylinders: Vec<CylinderPrimitive>,
    #[prost(message, repeated, tag = "11")]
    pub lines: Vec<LinePrimitive>,
}

/// `foxglove.SceneUpdate` (entities only; smocap deletes none).
#[derive(Clone, PartialEq, prost::Message)]
pub struct SceneUpdate {
    #[prost(message, repeated, tag = "2")]
    pub entities: Vec<SceneEntity>,
}

/// `smocap.State`: one frame's coordinates and scale proxies.
#[derive(Clone, PartialEq, prost::Message)]
pub struct State {
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<Timestamp>,
    #[prost(uint32, tag = "2")]
    pub frame: u32,
    /// Frame time (s) since the trial's first sample.
    #[prost(double, tag = "3")]
    pub time: f64,
    /// Coordinates in model order (rad or m).
    #[prost(double, repeated, tag = "4")]
    pub q: Vec<f64>,
    /// Drift of the scale proxies from the calibrated ones (ppm), `Subject.scale_proxies` order.
    #[prost(sint32, repeated, tag = "5")]
    pub scale_drift_ppm: Vec<i32>,
}

/// `smocap.SolverStats.Status` values, in [`crate::solve::FrameStatus`] order.
pub const STATUS_NAMES: [&str; 5] = ["Converged", "MaxIterations", "TooFewMarkers", "QpFailed", "Stalled"];

/// `smocap.SolverStats`: how one frame's solve went.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SolverStats {
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<Timestamp>,
    #[prost(uint32, tag = "2")]
    pub frame: u32,
    #[prost(uint32, tag = "3")]
    pub iterations: u32,
    #[prost(uint32, tag = "4")]
    pub accepted_steps: u32,
    #[prost(double, tag = "5")]
    pub energy: f64,
    /// Weighted marker RMSE (m).
    #[prost(double, tag = "6")]
    pub rmse: f64,
    #[prost(uint32, tag = "7")]
    pub markers_used: u32,
    /// Wall-clock solve time (s).
    #[prost(float, tag = "8")]
    pub solve_s: f32,
    #[prost(int32, tag = "9")]
    pub status: i32,
    #[prost(bool, tag = "10")]
    pub bridged: bool,
    /// Unweighted RMS of observed − model marker positions (m), NaN when none is observed.
    #[prost(double, tag = "11")]
    pub marker_rmse: f64,
    #[prost(uint32, tag = "12")]
    pub markers_observed: u32,
}

/// `smocap.Subject`: names and calibrated morphology, once per trial.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Subject {
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<Timestamp>,
    #[prost(string, tag = "2")]
    pub dataset: String,
    #[prost(string, tag = "3")]
    pub subject: String,
    #[prost(string, tag = "4")]
    pub trial: String,
    #[prost(string, repeated, tag = "5")]
    pub coordinates: Vec<String>,
    #[prost(string, repeated, tag = "6")]
    pub coordinate_units: Vec<String>,
    #[prost(string, repeated, tag = "7")]
    pub bodies: Vec<String>,
    #[prost(string, repeated, tag = "8")]
    pub body_parents: Vec<String>,
    #[prost(double, repeated, tag = "9")]
    pub body_scale: Vec<f64>,
    #[prost(string, repeated, tag = "10")]
    pub scale_proxies: Vec<String>,
    #[prost(double, repeated, tag = "17")]
    pub calibrated_scale: Vec<f64>,
    #[prost(sint32, repeated, tag = "11")]
    pub body_scale_proxy: Vec<i32>,
    #[prost(string, repeated, tag = "12")]
    pub markers: Vec<String>,
    #[prost(string, repeated, tag = "13")]
    pub marker_bodies: Vec<String>,
    #[prost(string, repeated, tag = "14")]
    pub proxies: Vec<String>,
    #[prost(double, repeated, tag = "15")]
    pub calibrated_proxies: Vec<f64>,
    #[prost(double, repeated, tag = "16")]
    pub world_from_model: Vec<f64>,
}

/// `smocap.LabelQc`: the trial's label quality control, once per trial.
#[derive(Clone, PartialEq, prost::Message)]
pub struct LabelQc {
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<Timestamp>,
    #[prost(string, tag = "2")]
    pub mode: String,
    #[prost(uint32, tag = "3")]
    pub rigid_pairs: u32,
    #[prost(message, repeated, tag = "4")]
    pub events: Vec<LabelEvent>,
    #[prost(uint32, tag = "5")]
    pub masked_frames: u32,
    #[prost(double, tag = "6")]
    pub masked_share: f64,
    #[prost(string, tag = "7")]
    pub suspect: String,
}

/// `smocap.LabelEvent`: one labelling error.
#[derive(Clone, PartialEq, prost::Message)]
pub struct LabelEvent {
    #[prost(string, tag = "1")]
    pub kind: String,
    #[prost(string, repeated, tag = "2")]
    pub markers: Vec<String>,
    #[prost(uint32, tag = "3")]
    pub first_frame: u32,
    #[prost(uint32, tag = "4")]
    pub last_frame: u32,
    #[prost(message, optional, tag = "5")]
    pub first_time: Option<Timestamp>,
    #[prost(message, optional, tag = "6")]
    pub last_time: Option<Timestamp>,
    #[prost(uint32, tag = "7")]
    pub detected_frames: u32,
    #[prost(string, tag = "8")]
    pub action: String,
    #[prost(double, tag = "9")]
    pub residual_before_mm: f64,
    #[prost(double, tag = "10")]
    pub residual_after_mm: f64,
}

/// `smocap.Unfittable`: a trial's runs of unfittable frames (`/smocap/unfittable`), once per trial.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Unfittable {
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<Timestamp>,
    #[prost(message, repeated, tag = "2")]
    pub runs: Vec<UnfittableRun>,
    #[prost(string, tag = "3")]
    pub reason: String,
}

/// `smocap.UnfittableRun`: one run of unfittable frames (mm).
#[derive(Clone, PartialEq, prost::Message)]
pub struct UnfittableRun {
    #[prost(uint32, tag = "1")]
    pub first_frame: u32,
    #[prost(uint32, tag = "2")]
    pub last_frame: u32,
    #[prost(message, optional, tag = "3")]
    pub first_time: Option<Timestamp>,
    #[prost(message, optional, tag = "4")]
    pub last_time: Option<Timestamp>,
    #[prost(uint32, tag = "5")]
    pub frames: u32,
    #[prost(double, tag = "6")]
    pub peak_rmse_mm: f64,
    #[prost(double, tag = "7")]
    pub limit_mm: f64,
    #[prost(string, repeated, tag = "8")]
    pub markers: Vec<String>,
    #[prost(double, repeated, tag = "9")]
    pub marker_error_mm: Vec<f64>,
    #[prost(double, tag = "10")]
    pub rigid_move_mm: f64,
    #[prost(string, tag = "11")]
    pub cause: String,
    #[prost(string, tag = "12")]
    pub why: String,
}
