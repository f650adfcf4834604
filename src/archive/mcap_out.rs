//! One solved trial as an MCAP file: protobuf channels (descriptor sets in the schema records,
//! see [`super::schemas`]) in zstd chunks, a `smocap.run` metadata record, the settings and the
//! scaled model attached (zstd-compressed).
//!
//! Over 600 lines: the writer is one state machine over the file (channels, chunks, metadata,
//! attachments, the per-frame messages); cut in two, each half would need the other's state.
//!
//! Frames: `world` is Z up (Foxglove's convention); `model` is the model's own frame (the marker
//! data rotated into it), placed in `world` by one fixed rotation `world_from_model` (identity for
//! a Z-up model; +90° about x for OpenSim's Y up); each body's frame is given in its parent
//! body's frame, the root body's in `model`. Per frame: `/tf`, `/markers` (observed markers),
//! `/smocap/state`, `/smocap/stats`; once, at the trial's first log time: `/scene` (the skeleton,
//! frame-locked to the body frames, drawn at the calibrated scale) and `/smocap/subject`; once,
//! after the last frame, at its log time, only for a trial with unfittable frames: `/smocap/unfittable`.
//!
//! Log times: [`WriterOptions::epoch_ns`] plus the frame's time since the trial's first sample
//! (the readers record no absolute start time). Frames are written as they are solved: nothing
//! here allocates per frame once the message buffers have their sizes, and memory holds one
//! chunk (≤ [`WriterOptions::chunk_size`] before compression). The file is written as
//! `<name>.partial` and renamed only once its summary is written, so a file with the final name
//! is always complete; a writer dropped unfinished removes its temporary file.

use super::proto::{self, Timestamp};
use super::schemas::{self, ChannelSpec};
use crate::io::MarkerTrial;
use crate::kinematics::cpu::{self, Workspace};
use crate::model::proxy::ProxyKind;
use crate::model::CoordinateKind;
use crate::pipeline::input::label_qc::LabelQc;
use crate::pipeline::running::unfittable::Unfittable;
use crate::pipeline::{Context, SolvedFrame};
use crate::solve::{Calibration, FrameStatus};
use mcap::records::{MessageHeader, Metadata};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Errors writing an MCAP file.
#[derive(Debug, thiserror::Error)]
pub enum McapOutError {
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}: {source}{}", cause(source))]
    Mcap { file: String, source: mcap::McapError },
}

/// The underlying error of an MCAP error (e.g. "no space left on device"), as ": <cause>".
fn cause(e: &mcap::McapError) -> String {
    std::error::Error::source(e).map(|c| format!(": {c}")).unwrap_or_default()
}

/// What the `smocap.run` metadata record holds (all strings).
pub type RunInfo = BTreeMap<String, String>;

/// The temporary name a trial's output is written under.
pub fn partial_path(out: &Path) -> PathBuf {
    let mut s = out.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// The default epoch: 2000-01-01T00:00:00Z, in ns since the Unix epoch.
pub const DEFAULT_EPOCH_NS: u64 = 946_684_800 * 1_000_000_000;

/// The chunks' zstd level, chosen by measurement (BENCHMARKS.md, issue 13): on a 2000-frame
/// trial level 1 gave 2.92 MB, 3 2.99 MB, 5 3.00 MB, 9 2.94 MB; 1 is also the fastest.
pub const DEFAULT_ZSTD_LEVEL: u32 = 1;

/// The scaled model's attachment name (zstd-compressed `.osim` text).
pub const SCALED_MODEL_ATTACHMENT: &str = "scaled_model.osim.zst";

/// How a trial's file is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriterOptions {
    /// Log time of each trial's first sample (ns since the Unix epoch).
    pub epoch_ns: u64,
    /// zstd level of the chunks (1–22).
    pub zstd_level: u32,
    /// Uncompressed chunk size (bytes).
    pub chunk_size: u64,
    /// Record each frame's wall-clock solve time (`SolverStats.solve_s`); off, files of the
    /// same input are byte-identical across runs (the summary keeps per-trial timings).
    pub timings: bool,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            epoch_ns: DEFAULT_EPOCH_NS,
            zstd_level: DEFAULT_ZSTD_LEVEL,
            chunk_size: 1 << 20,
            timings: false,
        }
    }
}

/// Parses an epoch: `YYYY-MM-DDTHH:MM:SSZ` (UTC; `T` may be a space; seconds may have a
/// fraction) or a number of seconds since the Unix epoch; ns since the Unix epoch.
pub fn parse_epoch(s: &str) -> Result<u64, String> {
    let bad = || format!("epoch '{s}': expected YYYY-MM-DDTHH:MM:SSZ (UTC) or seconds since 1970-01-01");
    let s = s.trim();
    if let Ok(secs) = s.parse::<f64>() {
        return (secs.is_finite() && secs >= 0.0).then(|| (secs * 1e9).round() as u64).ok_or_else(bad);
    }
    let t = s.strip_suffix('Z').or_else(|| s.strip_suffix("+00:00")).ok_or_else(bad)?;
    let (date, time) = t.split_once(['T', ' ']).ok_or_else(bad)?;
    let d: Vec<i64> = date.split('-').map(|x| x.parse().map_err(|_| bad())).collect::<Result<_, _>>()?;
    let hms: Vec<&str> = time.split(':').collect();
    if d.len() != 3 || hms.len() != 3 {
        return Err(bad());
    }
    let (h, mi): (u64, u64) = (hms[0].parse().map_err(|_| bad())?, hms[1].parse().map_err(|_| bad())?);
    let sec: f64 = hms[2].parse().map_err(|_| bad())?;
    if !(1970..=9999).contains(&d[0]) || !(1..=12).contains(&d[1]) || !(1..=31).contains(&d[2]) {
        return Err(bad());
    }
    if h > 23 || mi > 59 || !(0.0..61.0).contains(&sec) {
        return Err(bad());
    }
    // Days from civil (Howard Hinnant's algorithm).
    let (y, m) = if d[1] <= 2 { (d[0] - 1, d[1] + 9) } else { (d[0], d[1] - 3) };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * m + 2) / 5 + d[2] - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = (era * 146_097 + doe - 719_468) as u64;
    Ok(((days * 86_400 + h * 3600 + mi * 60) as f64 * 1e9 + (sec * 1e9).round()) as u64)
}

/// The rotation taking the model's up direction to +z (identity when the model has none).
pub fn world_from_model(up: Option<Vector3<f64>>) -> UnitQuaternion<f64> {
    let Some(up) = up.filter(|u| u.norm() > 0.0) else { return UnitQuaternion::identity() };
    let r = crate::model::math::rotation_between(&up, &Vector3::z());
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r))
}

/// A quaternion with w ≥ 0, its components on the [`TF_GRID`] (visualisation only).
pub(super) fn quat(r: &UnitQuaternion<f64>) -> proto::Quaternion {
    let s = if r.w < 0.0 { -1.0 } else { 1.0 };
    proto::Quaternion { x: grid(s * r.i), y: grid(s * r.j), z: grid(s * r.k), w: grid(s * r.w) }
}

/// The grid `/tf` values are rounded to: 2⁻¹⁵ (≈ 30 µm, ≈ 30 µrad ≈ 0.002°). A viewer needs no more, and
/// the zero low bits of the doubles compress.
pub const TF_GRID: f64 = 1.0 / (1u64 << 15) as f64;

/// `x` rounded to the [`TF_GRID`] (+0 for −0).
fn grid(x: f64) -> f64 {
    (x / TF_GRID).round() * TF_GRID + 0.0
}

pub(super) fn v3(v: &Vector3<f64>) -> proto::Vector3 {
    proto::Vector3 { x: grid(v.x), y: grid(v.y), z: grid(v.z) }
}

/// The pose of body `b` in its parent's frame (in `model` for a root body).
fn relative(model: &crate::model::Model, ws: &Workspace, b: usize) -> (Matrix3<f64>, Vector3<f64>) {
    match model.bodies[b].parent {
        Some(p) => {
            let rt = ws.body_rot[p].transpose();
            (rt * ws.body_rot[b], rt * (ws.body_pos[b] - ws.body_pos[p]))
        }
        None => (ws.body_rot[b], ws.body_pos[b]),
    }
}

fn rot(m: &Matrix3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*m))
}

/// Names of a converted trial, for `/smocap/subject`.
#[derive(Clone, Debug, Default)]
pub struct TrialNames {
    pub dataset: String,
    pub subject: String,
    pub trial: String,
}

/// Channel ids, in [`schemas::CHANNELS`] order.
#[derive(Clone, Copy, Default)]
struct Channels {
    state: u16,
    stats: u16,
    tf: u16,
    markers: u16,
}

/// A trial's MCAP file being written, frame by frame as frames are solved. Created as
/// `<out>.partial`; [`TrialWriter::finish`] writes the summary and renames it to `out`. Dropped
/// unfinished (an error, a panic), it removes the temporary file.
pub struct TrialWriter<'a> {
    ctx: &'a Context,
    trial: &'a MarkerTrial,
    w: Option<mcap::Writer<BufWriter<std::fs::File>>>,
    tmp: PathBuf,
    out: PathBuf,
    ch: Channels,
    ws: Workspace,
    y: Vec<f64>,
    dphi: Vec<f64>,
    /// Indices of the scale proxies.
    scale_proxies: Vec<usize>,
    /// The calibrated scale factors (`y[nq..]` at the calibration), which `/tf` is drawn with.
    calibrated_scale: Vec<f64>,
    /// The calibrated proxies (scale drift is relative to them).
    calibrated_proxies: Vec<f64>,
    t0: f64,
    epoch_ns: u64,
    timings: bool,
    /// Message buffers, refilled each frame (their strings and vectors keep their capacity).
    tf: proto::FrameTransforms,
    cloud: proto::PointCloud,
    state: proto::State,
    stats: proto::SolverStats,
    buf: Vec<u8>,
    /// The motion as written, when kept ([`TrialWriter::keep_motion`]).
    kept: Option<KeptMotion>,
}

/// A trial's motion as its file records it ([`TrialWriter::keep_motion`]): per frame written,
/// `/smocap/state`'s coordinates (model order), time since the first sample (s) and frame index.
#[derive(Clone, Debug, Default)]
pub struct KeptMotion {
    pub q: Vec<Vec<f64>>,
    pub times: Vec<f64>,
    pub frames: Vec<usize>,
}

impl<'a> TrialWriter<'a> {
    /// Starts `out` (as its temporary file) for `trial`, solved with `ctx` for a
    /// subject calibrated as `calibration`; writes the schemas, channels and the once-per-trial
    /// messages (`/scene`, `/smocap/subject`, `/smocap/label_qc` from `label_qc`: mode `off`
    /// when `None`).
    pub fn create(
        out: &Path,
        ctx: &'a Context,
        trial: &'a MarkerTrial,
        calibration: &Calibration,
        names: &TrialNames,
        label_qc: Option<&LabelQc>,
        opt: &WriterOptions,
    ) -> Result<Self, McapOutError> {
        let tmp = partial_path(out);
        let file = tmp.display().to_string();
        let io = |source| McapOutError::Io { file: file.clone(), source };
        let mc = |source| McapOutError::Mcap { file: file.clone(), source };
        let f = std::fs::File::create(&tmp).map_err(io)?;
        let opts = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(opt.zstd_level)
            .compression_threads(0)
            .chunk_size(Some(opt.chunk_size))
            .profile("")
            .library(format!("smocap {}", env!("CARGO_PKG_VERSION")));
        let w = opts.create(BufWriter::with_capacity(1 << 16, f)).map_err(mc);
        let model = &ctx.model;
        let root = world_from_model(ctx.up);
        let parent_name = |b: usize| model.bodies[b].parent.map_or("model", |p| model.bodies[p].name.as_str());
        let mut transforms = vec![proto::FrameTransform {
            timestamp: Some(Timestamp::default()),
            parent_frame_id: "world".into(),
            child_frame_id: "model".into(),
            translation: Some(proto::Vector3::default()),
            // Exact: constant, so it costs nothing after compression.
            rotation: Some(proto::Quaternion { x: root.i + 0.0, y: root.j + 0.0, z: root.k + 0.0, w: root.w }),
        }];
        transforms.extend(model.bodies.iter().enumerate().map(|(b, body)| proto::FrameTransform {
            timestamp: Some(Timestamp::default()),
            parent_frame_id: parent_name(b).into(),
            child_frame_id: body.name.clone(),
            translation: Some(proto::Vector3::default()),
            rotation: Some(proto::Quaternion::IDENTITY),
        }));
        let field = |n: &str, offset| proto::PackedElementField { name: n.into(), offset, r#type: proto::FLOAT32 };
        let cloud = proto::PointCloud {
            timestamp: Some(Timestamp::default()),
            frame_id: "model".into(),
            pose: Some(proto::Pose::identity()),
            point_stride: 12,
            fields: vec![field("x", 0), field("y", 4), field("z", 8)],
            data: Vec::with_capacity(12 * model.markers.len()),
        };
        let scale_proxies: Vec<usize> =
            ctx.proxy.proxies.iter().enumerate().filter(|(_, p)| p.kind == ProxyKind::Scale).map(|(k, _)| k).collect();
        let mut tw = TrialWriter {
            ctx,
            trial,
            w: None,
            tmp: tmp.clone(),
            out: out.to_path_buf(),
            ch: Channels::default(),
            ws: Workspace::new(model),
            y: vec![0.0; model.ny()],
            dphi: vec![0.0; ctx.proxy.terms.len()],
            t0: trial.times.first().copied().unwrap_or(0.0),
            epoch_ns: opt.epoch_ns,
            timings: opt.timings,
            tf: proto::FrameTransforms { transforms },
            cloud,
            state: proto::State {
                q: Vec::with_capacity(model.nq()),
                scale_drift_ppm: Vec::with_capacity(scale_proxies.len()),
                ..Default::default()
            },
            stats: proto::SolverStats::default(),
            scale_proxies,
            calibrated_scale: ctx.proxy.state(&calibration.proxies)[model.nq()..].to_vec(),
            calibrated_proxies: calibration.proxies.clone(),
            buf: Vec::with_capacity(1 << 12),
            kept: None,
        };
        // From here on, dropping `tw` removes the temporary file.
        tw.w = Some(w?);
        let up = ctx.up.map_or("none".into(), |u| format!("[{}, {}, {}]", u.x + 0.0, u.y + 0.0, u.z + 0.0));
        let wfm = format!("[{}, {}, {}, {}]", root.i + 0.0, root.j + 0.0, root.k + 0.0, root.w);
        let w = tw.w.as_mut().expect("just set");
        let mut ids = [0u16; schemas::CHANNELS.len()];
        for (id, c) in ids.iter_mut().zip(schemas::CHANNELS) {
            *id = add_channel(w, &c, &up, &wfm).map_err(mc)?;
        }
        tw.ch = Channels { state: ids[0], stats: ids[1], tf: ids[2], markers: ids[3] };
        let start = Timestamp::from_ns(tw.epoch_ns);
        let scene = tw.scene(calibration, start);
        let subject = tw.subject(calibration, names, &root, start);
        tw.write(ids[4], 0, tw.epoch_ns, &scene)?;
        tw.write(ids[5], 0, tw.epoch_ns, &subject)?;
        let qc = tw.label_qc(label_qc.unwrap_or(&LabelQc::off()), start);
        tw.write(ids[6], 0, tw.epoch_ns, &qc)?;
        Ok(tw)
    }

    /// The skeleton at the calibrated state: per body, a frame-locked entity in its frame with
    /// lines to its children's origins (bones) and spheres at its model markers.
    fn scene(&mut self, calibration: &Calibration, stamp: Timestamp) -> proto::SceneUpdate {
        let model = &self.ctx.model;
        self.ctx.proxy.apply(&calibration.proxies, &mut self.y, &mut self.dphi);
        cpu::forward(model, &self.y, &mut self.ws);
        let ws = &self.ws;
        let color = |r, g, b| Some(proto::Color { r, g, b, a: 1.0 });
        let local = |b: usize, p: Vector3<f64>| {
            let v = ws.body_rot[b].transpose() * (p - ws.body_pos[b]);
            proto::Vector3 { x: v.x, y: v.y, z: v.z }
        };
        let entities = model
            .bodies
            .iter()
            .enumerate()
            .map(|(b, body)| {
                let bones: Vec<proto::Point3> = model
                    .bodies
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| c.parent == Some(b))
                    .flat_map(|(c, _)| [proto::Point3::default(), local(b, ws.body_pos[c])])
                    .collect();
                let spheres = model
                    .markers
                    .iter()
                    .enumerate()
                    .filter(|(_, m)| m.body == b)
                    .map(|(m, _)| proto::SpherePrimitive {
                        pose: Some(proto::Pose {
                            position: Some(local(b, Vector3::from_column_slice(&ws.markers[3 * m..3 * m + 3]))),
                            orientation: Some(proto::Quaternion::IDENTITY),
                        }),
                        size: Some(proto::Vector3 { x: 0.02, y: 0.02, z: 0.02 }),
                        color: color(1.0, 0.5, 0.0),
                    })
                    .collect();
                let lines = (!bones.is_empty())
                    .then(|| proto::LinePrimitive {
                        r#type: proto::LINE_LIST,
                        pose: Some(proto::Pose::identity()),
                        thickness: 0.01,
                        scale_invariant: false,
                        points: bones,
                        color: color(0.8, 0.8, 0.8),
                    })
                    .into_iter()
                    .collect();
                proto::SceneEntity {
                    timestamp: Some(stamp),
                    frame_id: body.name.clone(),
                    id: body.name.clone(),
                    lifetime: Some(proto::Duration::default()),
                    frame_locked: true,
                    metadata: Vec::new(),
                    spheres,
                    cylinders: Vec::new(),
                    lines,
                }
            })
            .collect();
        proto::SceneUpdate { entities }
    }

    fn subject(
        &self,
        calibration: &Calibration,
        names: &TrialNames,
        root: &UnitQuaternion<f64>,
        stamp: Timestamp,
    ) -> proto::Subject {
        let (ctx, model) = (self.ctx, &self.ctx.model);
        let y = ctx.proxy.state(&calibration.proxies);
        let mut body_scale_proxy = vec![-1i32; 3 * model.nb()];
        for t in &ctx.proxy.terms {
            if let Some(i) = self.scale_proxies.iter().position(|&k| k == t.proxy) {
                if t.y_index >= model.nq() {
                    body_scale_proxy[t.y_index - model.nq()] = i as i32;
                }
            }
        }
        proto::Subject {
            timestamp: Some(stamp),
            dataset: names.dataset.clone(),
            subject: names.subject.clone(),
            trial: names.trial.clone(),
            coordinates: model.coordinates.iter().map(|c| c.name.clone()).collect(),
            coordinate_units: model
                .coordinates
                .iter()
                .map(|c| if c.kind == CoordinateKind::Rotational { "rad" } else { "m" }.to_string())
                .collect(),
            bodies: model.bodies.iter().map(|b| b.name.clone()).collect(),
            body_parents: (0..model.nb())
                .map(|b| model.bodies[b].parent.map_or("model".into(), |p| model.bodies[p].name.clone()))
                .collect(),
            body_scale: y[model.nq()..].to_vec(),
            scale_proxies: self.scale_proxies.iter().map(|&k| ctx.proxy.proxies[k].name.clone()).collect(),
            calibrated_scale: self.scale_proxies.iter().map(|&k| calibration.proxies[k]).collect(),
            body_scale_proxy,
            markers: model.markers.iter().map(|m| m.name.clone()).collect(),
            marker_bodies: model.markers.iter().map(|m| model.bodies[m.body].name.clone()).collect(),
            proxies: ctx.proxy.proxies.iter().map(|p| p.name.clone()).collect(),
            calibrated_proxies: calibration.proxies.clone(),
            world_from_model: vec![root.i, root.j, root.k, root.w],
        }
    }

    /// The `/smocap/label_qc` message: `qc`'s events with their frames' log times.
    fn label_qc(&self, qc: &LabelQc, stamp: Timestamp) -> proto::LabelQc {
        let at = |f: usize| Some(Timestamp::from_ns(self.log_ns(f)));
        proto::LabelQc {
            timestamp: Some(stamp),
            mode: qc.mode.as_str().into(),
            rigid_pairs: qc.rigid_pairs as u32,
            events: qc
                .events
                .iter()
                .map(|e| proto::LabelEvent {
                    kind: e.kind.as_str().into(),
                    markers: e.markers.clone(),
                    first_frame: e.first_frame as u32,
                    last_frame: e.last_frame as u32,
                    first_time: at(e.first_frame),
                    last_time: at(e.last_frame),
                    detected_frames: e.detected_frames as u32,
                    action: e.action.as_str().into(),
                    residual_before_mm: e.residual_before_mm,
                    residual_after_mm: e.residual_after_mm.unwrap_or(f64::NAN),
                })
                .collect(),
            masked_frames: qc.masked_frames as u32,
            masked_share: qc.masked_share,
            suspect: qc.suspect.clone().unwrap_or_default(),
        }
    }

    /// Writes `/smocap/unfittable` (adding its channel, [`schemas::UNFITTABLE`]) when `runs` is not
    /// empty: the trial's runs of unfittable frames, at its last frame's log time. Call after the
    /// last frame; a trial without such a run gets neither channel nor message.
    pub fn unfittable(&mut self, runs: &[Unfittable]) -> Result<(), McapOutError> {
        if runs.is_empty() {
            return Ok(());
        }
        let at = |f: usize| Some(Timestamp::from_ns(self.log_ns(f)));
        let ns = self.log_ns(self.trial.n_frames().saturating_sub(1));
        let msg = proto::Unfittable {
            timestamp: Some(Timestamp::from_ns(ns)),
            runs: runs
                .iter()
                .map(|u| proto::UnfittableRun {
                    first_frame: u.first as u32,
                    last_frame: u.last as u32,
                    first_time: at(u.first),
                    last_time: at(u.last),
                    frames: u.frames as u32,
                    peak_rmse_mm: u.peak_rmse_mm,
                    limit_mm: u.limit_mm,
                    markers: u.markers.iter().map(|m| m.0.clone()).collect(),
                    marker_error_mm: u.markers.iter().map(|m| m.1).collect(),
                    rigid_move_mm: u.rigid_move_mm,
                    cause: u.cause.clone(),
                    why: u.why.clone(),
                })
                .collect(),
            reason: crate::pipeline::running::unfittable::reason(runs).unwrap_or_default(),
        };
        let file = self.tmp.display().to_string();
        let w = self.w.as_mut().expect("present until finished");
        let ch = add_channel(w, &schemas::UNFITTABLE, "", "").map_err(|source| McapOutError::Mcap { file, source })?;
        self.write(ch, 0, ns, &msg)
    }

    /// Keeps the motion of the frames written from now on ([`TrialWriter::kept`]).
    pub fn keep_motion(&mut self) {
        self.kept = Some(KeptMotion::default());
    }

    /// The motion kept since [`TrialWriter::keep_motion`].
    pub fn kept(&self) -> Option<&KeptMotion> {
        self.kept.as_ref()
    }

    /// The calibrated scale factors, `3·body + axis` (what `/tf` and `/scene` are drawn with).
    pub fn calibrated_scale(&self) -> &[f64] {
        &self.calibrated_scale
    }

    /// The rotation from `model` to the Z-up `world`.
    pub fn world_from_model(&self) -> UnitQuaternion<f64> {
        world_from_model(self.ctx.up)
    }

    /// The file's MCAP writer, to add channels and messages of its own, and the file's name
    /// (for errors).
    pub fn raw(&mut self) -> (&mut mcap::Writer<BufWriter<std::fs::File>>, String) {
        (self.w.as_mut().expect("present until finished"), self.tmp.display().to_string())
    }

    /// Log time of frame `f` (ns): the epoch plus its time since the trial's first sample.
    pub fn log_ns(&self, f: usize) -> u64 {
        self.epoch_ns + (self.since_start(f).max(0.0) * 1e9).round() as u64
    }

    /// Frame `f`'s time since the trial's first sample (s).
    fn since_start(&self, f: usize) -> f64 {
        self.trial.times.get(f).copied().unwrap_or(f as f64 / self.trial.rate_hz.max(1e-9)) - self.t0
    }

    /// Encodes `msg` and writes it on channel `ch`.
    fn write(&mut self, ch: u16, sequence: u32, ns: u64, msg: &impl prost::Message) -> Result<(), McapOutError> {
        put(&mut self.w, &mut self.buf, &self.tmp, ch, sequence, ns, msg)
    }

    /// Writes one solved frame: `/tf`, `/markers`, `/smocap/state` and `/smocap/stats`, log time
    /// = the epoch plus the frame's time since the trial's first sample.
    pub fn frame(&mut self, fr: &SolvedFrame) -> Result<(), McapOutError> {
        let ctx = self.ctx;
        let model = &ctx.model;
        let f = fr.index;
        let t = self.since_start(f);
        let ns = self.log_ns(f);
        let stamp = Some(Timestamp::from_ns(ns));
        ctx.proxy.apply(&fr.proxies, &mut self.y, &mut self.dphi);
        cpu::forward(model, &self.y, &mut self.ws);
        // /markers: observed markers in model order, NaN where not observed; their RMS
        // distance to the model's (at the frame's own scales).
        self.cloud.timestamp = stamp;
        self.cloud.data.clear();
        let (mut sq, mut n) = (0.0, 0u32);
        for m in 0..model.markers.len() {
            let obs = fr.observed.get(3 * m..3 * m + 3).filter(|p| p.iter().all(|v| v.is_finite()));
            let o = obs.map_or([f64::NAN; 3], |p| [p[0], p[1], p[2]]);
            for v in o {
                self.cloud.data.extend_from_slice(&(v as f32).to_le_bytes());
            }
            if obs.is_some() {
                let mp = &self.ws.markers[3 * m..3 * m + 3];
                sq += (0..3).map(|a| (o[a] - mp[a]).powi(2)).sum::<f64>();
                n += 1;
            }
        }
        // /smocap/state before `y` changes below.
        self.state.timestamp = stamp;
        self.state.frame = f as u32;
        self.state.time = t;
        self.state.q.clear();
        self.state.q.extend_from_slice(&self.y[..model.nq()]);
        if let Some(k) = &mut self.kept {
            k.q.push(self.state.q.clone());
            k.times.push(t);
            k.frames.push(f);
        }
        // /tf: the frame's pose on the subject's calibrated scales (as the skeleton in /scene):
        // `world → model` (fixed), then each body in its parent.
        // (When the frame's scales are the calibrated ones, bit for bit, the pose is already
        // the one drawn: the same forward kinematics would give the same bodies.)
        let same = |(a, b): (&f64, &f64)| a.to_bits() == b.to_bits();
        if !self.y[model.nq()..].iter().zip(&self.calibrated_scale).all(same) {
            self.y[model.nq()..].copy_from_slice(&self.calibrated_scale);
            cpu::forward(model, &self.y, &mut self.ws);
        }
        self.tf.transforms[0].timestamp = stamp;
        for b in 0..model.nb() {
            let (r, p) = relative(model, &self.ws, b);
            let tr = &mut self.tf.transforms[b + 1];
            tr.timestamp = stamp;
            tr.translation = Some(v3(&p));
            tr.rotation = Some(quat(&rot(&r)));
        }
        self.state.scale_drift_ppm.clear();
        let cal = &self.calibrated_proxies;
        self.state.scale_drift_ppm.extend(self.scale_proxies.iter().map(|&k| drift_ppm(fr.proxies[k], cal[k])));
        let s = &fr.stats;
        self.stats = proto::SolverStats {
            timestamp: stamp,
            frame: f as u32,
            iterations: s.iterations,
            accepted_steps: s.accepted,
            energy: nan_if_infinite(s.energy),
            rmse: nan_if_infinite(s.rmse_m),
            markers_used: s.markers_used as u32,
            solve_s: if self.timings { fr.seconds as f32 } else { 0.0 },
            status: status_code(s.status),
            bridged: fr.bridged,
            marker_rmse: if n > 0 { (sq / n as f64).sqrt() } else { f64::NAN },
            markers_observed: n,
        };
        let (seq, ch) = (f as u32, self.ch);
        put(&mut self.w, &mut self.buf, &self.tmp, ch.tf, seq, ns, &self.tf)?;
        put(&mut self.w, &mut self.buf, &self.tmp, ch.markers, seq, ns, &self.cloud)?;
        put(&mut self.w, &mut self.buf, &self.tmp, ch.state, seq, ns, &self.state)?;
        put(&mut self.w, &mut self.buf, &self.tmp, ch.stats, seq, ns, &self.stats)
    }

    /// Writes the `smocap.run` metadata (`run`), attaches `settings_json` and the scaled model
    /// (`scaled_model_zst`: `.osim` text, zstd-compressed), writes the summary, syncs, and
    /// renames the file to its final name.
    pub fn finish(
        mut self,
        run: &RunInfo,
        settings_json: &str,
        scaled_model_zst: Option<&[u8]>,
    ) -> Result<(), McapOutError> {
        let file = self.tmp.display().to_string();
        let io = |source| McapOutError::Io { file: file.clone(), source };
        let mc = |source| McapOutError::Mcap { file: file.clone(), source };
        let mut w = self.w.take().expect("present until finished");
        // On an error below, `w` and then `self` drop, which removes the temporary file.
        w.write_metadata(&Metadata { name: "smocap.run".into(), metadata: run.clone() }).map_err(mc)?;
        let attach = |w: &mut mcap::Writer<_>, name: &str, media: &str, data: &[u8]| {
            w.attach(&mcap::Attachment {
                log_time: 0,
                create_time: 0,
                name: name.into(),
                media_type: media.into(),
                data: std::borrow::Cow::Borrowed(data),
            })
        };
        attach(&mut w, "settings.json", "application/json", settings_json.as_bytes()).map_err(mc)?;
        if let Some(m) = scaled_model_zst {
            attach(&mut w, SCALED_MODEL_ATTACHMENT, "application/zstd", m).map_err(mc)?;
        }
        w.finish().map_err(mc)?;
        let f = w.into_inner().into_inner().map_err(|e| io(e.into_error()))?;
        f.sync_all().map_err(io)?;
        drop(f);
        std::fs::rename(&self.tmp, &self.out)
            .map_err(|source| McapOutError::Io { file: self.out.display().to_string(), source })?;
        self.tmp = PathBuf::new();
        Ok(())
    }
}

impl Drop for TrialWriter<'_> {
    fn drop(&mut self) {
        drop(self.w.take());
        if !self.tmp.as_os_str().is_empty() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Encodes `msg` into `buf` and writes it to `w` on channel `ch` (`tmp` names the file in errors).
fn put(
    w: &mut Option<mcap::Writer<BufWriter<std::fs::File>>>,
    buf: &mut Vec<u8>,
    tmp: &Path,
    ch: u16,
    sequence: u32,
    ns: u64,
    msg: &impl prost::Message,
) -> Result<(), McapOutError> {
    buf.clear();
    msg.encode(buf).expect("a Vec grows as needed");
    let header = MessageHeader { channel_id: ch, sequence, log_time: ns, publish_time: ns };
    let w = w.as_mut().expect("present until finished");
    w.write_to_known_channel(&header, buf)
        .map_err(|source| McapOutError::Mcap { file: tmp.display().to_string(), source })
}

/// Adds channel `c` (and its schema) with its metadata: units, frames, log-time convention.
fn add_channel<W: std::io::Write + std::io::Seek>(
    w: &mut mcap::Writer<W>,
    c: &ChannelSpec,
    up: &str,
    world_from_model: &str,
) -> Result<u16, mcap::McapError> {
    let id = w.add_schema(c.schema, "protobuf", c.descriptors)?;
    let mut meta: BTreeMap<String, String> = [
        ("length_unit", "m"),
        ("angle_unit", "rad"),
        ("log_time", "the epoch (smocap.run: epoch_ns) plus the frame's time since the trial's first sample"),
        (
            "rate",
            match (c.per_frame, c.topic == schemas::UNFITTABLE.topic) {
                (true, _) => "one message per frame",
                (false, false) => "one message per trial, at its first log time",
                (false, true) => "one message per trial with unfittable frames, at its last frame's log time",
            },
        ),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v.to_string()))
    .collect();
    if !c.frame.is_empty() {
        meta.insert("frame".into(), c.frame.into());
    }
    if c.topic == schemas::TF.topic || c.topic == schemas::MARKERS.topic {
        meta.insert("world".into(), "z up; the root of the transform tree".into());
        meta.insert("model".into(), format!("the model's frame (the marker data rotated into it), up {up}"));
        meta.insert("world_from_model".into(), format!("{world_from_model} (quaternion x, y, z, w)"));
    }
    w.add_channel(id, c.topic, "protobuf", &meta)
}

/// `(value / calibrated − 1)` in parts per million, rounded (saturating).
pub fn drift_ppm(value: f64, calibrated: f64) -> i32 {
    let d = ((value / calibrated - 1.0) * 1e6).round();
    if d.is_finite() {
        d.clamp(i32::MIN as f64, i32::MAX as f64) as i32
    } else {
        0
    }
}

fn nan_if_infinite(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else {
        f64::NAN
    }
}

/// `smocap.SolverStats.Status` of a frame status.
pub fn status_code(s: FrameStatus) -> i32 {
    match s {
        FrameStatus::Converged => 0,
        FrameStatus::MaxIterations => 1,
        FrameStatus::TooFewMarkers => 2,
        FrameStatus::QpFailed => 3,
        FrameStatus::Stalled => 4,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epochs_parse_as_utc_dates_or_unix_seconds() {
        assert_eq!(parse_epoch("2000-01-01T00:00:00Z"), Ok(DEFAULT_EPOCH_NS));
        assert_eq!(parse_epoch("1970-01-01 00:00:01Z"), Ok(1_000_000_000));
        assert_eq!(parse_epoch("2024-02-29T12:30:15.5Z"), Ok(1_709_209_815_500_000_000));
        assert_eq!(parse_epoch("946684800"), Ok(DEFAULT_EPOCH_NS));
        assert!(parse_epoch("2000-13-01T00:00:00Z").is_err());
        assert!(parse_epoch("yesterday").is_err());
        assert!(parse_epoch("2000-01-01T00:00:00").is_err(), "a zone is required");
    }

    #[test]
    fn y_up_models_get_a_quarter_turn_about_x_and_z_up_none() {
        let q = world_from_model(Some(Vector3::y()));
        assert!((q * Vector3::y() - Vector3::z()).norm() < 1e-12);
        assert!((q * Vector3::z() + Vector3::y()).norm() < 1e-12, "a rotation about x");
        assert_eq!(world_from_model(Some(Vector3::z())), UnitQuaternion::identity());
        assert!((world_from_model(Some(-Vector3::z())) * -Vector3::z() - Vector3::z()).norm() < 1e-12);
        assert_eq!(world_from_model(None), UnitQuaternion::identity());
    }
}
