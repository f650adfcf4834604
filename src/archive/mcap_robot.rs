//! A robot beside the human in a converted trial's MCAP file (issue 31): `/robot/tf` (every
//! robot body's pose per frame) and `/robot/scene` (its collision capsules, once), plus a
//! `smocap.robot` metadata record, added to a file `smocap convert` (or `solve --mcap`) wrote.
//!
//! Frames: `world → <robot>/world` is the robot's lateral offset ([`RobotTrack::offset`], a pure
//! translation, Z up; 0 by default: the robot walks where the human walks), then each body
//! `<robot>/<parent> → <robot>/<body>` is the body's pose in its parent body's frame (the root's
//! in `<robot>/world`): the kinematic tree, as the human's `/tf` is written. Composed, the poses
//! are MuJoCo's `xpos`/`xquat` (the robot's world is the human's `world`: Z up, the same
//! origin). A hinge child's translation is the same in every frame, so the chunks compress to
//! half the size of world poses. Log times: each robot frame at the log time of the human frame
//! it was retargeted from (that frame's `/smocap/state` message), so the two play in step.
//!
//! Two ways in: `smocap convert --robot` writes the robot into the trial's file as it is
//! finished ([`write_track`]: the robot's messages after the human's, in their own chunks);
//! `smocap retarget --into-mcap` adds it to a finished file ([`add_robot`]).
//! That file is rewritten, never edited: every schema, channel (same ids), message (same
//! sequence and times), metadata record and attachment is copied unchanged into
//! `<file>.partial`, the robot's channels and metadata are added, and the temporary file is
//! renamed over the original once complete. Channels under `/robot/` and the `smocap.robot`
//! record of an earlier run are left out: adding a robot again replaces it (one robot per file).
//! This module knows poses and capsules only; `cli` fills them from `crate::retarget`.

use super::mcap_out::{partial_path, quat, v3, McapOutError, WriterOptions};
use super::proto::{self, Timestamp};
use super::schemas::{ChannelSpec, FOXGLOVE_DESCRIPTORS};
use mcap::records::{MessageHeader, Metadata};
use nalgebra::{UnitQuaternion, Vector3};
use prost::Message as _;
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// `/robot/tf`: per frame, every robot body in its parent's frame (the root in `<robot>/world`),
/// and that frame in `world`.
pub const ROBOT_TF: ChannelSpec = ChannelSpec {
    topic: "/robot/tf",
    schema: "foxglove.FrameTransforms",
    descriptors: FOXGLOVE_DESCRIPTORS,
    frame: "world",
    per_frame: true,
};
/// `/robot/scene`: the robot's collision capsules, one frame-locked entity per body, once.
pub const ROBOT_SCENE: ChannelSpec = ChannelSpec {
    topic: "/robot/scene",
    schema: "foxglove.SceneUpdate",
    descriptors: FOXGLOVE_DESCRIPTORS,
    frame: "robot body frames",
    per_frame: false,
};
/// Topics under this prefix belong to the robot (replaced when a robot is added again).
pub const ROBOT_PREFIX: &str = "/robot/";
/// The metadata record naming the robot and summarising its retargeting.
pub const ROBOT_METADATA: &str = "smocap.robot";

/// A collision capsule on a robot body (a sphere when `a == b`): ends in the body's frame (m).
#[derive(Clone, Debug)]
pub struct TrackCapsule {
    pub body: usize,
    pub a: Vector3<f64>,
    pub b: Vector3<f64>,
    pub radius: f64,
}

/// Per frame, per body: orientation and origin in the robot's world (Z up, m).
pub type BodyPoses = Vec<Vec<(UnitQuaternion<f64>, Vector3<f64>)>>;

/// A robot's motion as the MCAP file shows it.
#[derive(Clone, Debug)]
pub struct RobotTrack {
    /// The robot's name: its frames are `<name>/world` and `<name>/<body>`.
    pub name: String,
    /// Body names (the robot's body order).
    pub bodies: Vec<String>,
    /// Each body's parent body (`None`: the robot's world).
    pub parents: Vec<Option<usize>>,
    /// The human frame index (`/smocap/state`'s `frame`) each robot frame was retargeted from.
    pub frames: Vec<usize>,
    pub poses: BodyPoses,
    pub capsules: Vec<TrackCapsule>,
    /// Where the robot's world origin sits in `world` (m; e.g. `[0, 1, 0]`: 1 m to the left of a
    /// human walking along +x).
    pub offset: Vector3<f64>,
    /// Extra entries of the `smocap.robot` record (its `robot` entry is [`Self::name`]).
    pub metadata: BTreeMap<String, String>,
}

/// Errors adding a robot to a trial's file.
#[derive(Debug, thiserror::Error)]
pub enum RobotMcapError {
    #[error(transparent)]
    Read(#[from] super::inspect::InspectError),
    #[error(transparent)]
    Write(#[from] McapOutError),
    #[error("{file}: {what}")]
    Content { file: String, what: String },
}

/// The robot recorded in a complete converted trial (`smocap.robot` → `robot`), if any.
pub fn recorded_robot(path: &Path) -> Option<String> {
    let mut info = super::inspect::verify(path).ok()?;
    info.metadata.remove(ROBOT_METADATA)?.remove("robot")
}

/// Rewrites the trial `path` with `track` added (replacing any robot it had); the chunks are
/// compressed as `opt` says.
pub fn add_robot(path: &Path, track: &RobotTrack, opt: &WriterOptions) -> Result<(), RobotMcapError> {
    add_robot_to(&super::inspect::read_checked(path)?, path, track, opt)
}

/// [`add_robot`] of the file's bytes `buf`, already read (and checked, [`super::inspect::read_checked`]).
pub fn add_robot_to(buf: &[u8], path: &Path, track: &RobotTrack, opt: &WriterOptions) -> Result<(), RobotMcapError> {
    let file = path.display().to_string();
    let bad = |what: String| RobotMcapError::Content { file: file.clone(), what };
    if track.poses.len() != track.frames.len() || track.poses.iter().any(|p| p.len() != track.bodies.len()) {
        return Err(bad("robot poses do not match its frames and bodies".into()));
    }
    let mc = |source| McapOutError::Mcap { file: file.clone(), source };
    let summary = mcap::Summary::read(buf).map_err(mc)?.ok_or_else(|| bad("no summary section".into()))?;
    let index: BTreeMap<usize, usize> = track.frames.iter().enumerate().map(|(k, &f)| (f, k)).collect();
    let mut out = Rewrite::create(path, opt)?;
    let kept = out.copy_channels(&summary)?;
    let (tf_ch, scene_ch) = (out.channel(&ROBOT_TF, track)?, out.channel(&ROBOT_SCENE, track)?);
    // Each robot frame right after its human frame's `/smocap/state` message, at its log time;
    // the scene before the first.
    let mut written = 0;
    for m in mcap::MessageStream::new(buf).map_err(mc)? {
        let m = m.map_err(mc)?;
        if !kept.contains(&m.channel.id) {
            continue;
        }
        out.message(m.channel.id, m.sequence, m.log_time, &m.data)?;
        let Some(k) = state_frame(&m).and_then(|f| index.get(&f).copied()) else { continue };
        if written == 0 {
            out.message(scene_ch, 0, m.log_time, &scene(track, m.log_time).encode_to_vec())?;
        }
        out.message(tf_ch, track.frames[k] as u32, m.log_time, &tf(track, k, m.log_time).encode_to_vec())?;
        written += 1;
    }
    if written != track.frames.len() {
        return Err(bad(format!(
            "{written} of the robot's {} frames have a /smocap/state message",
            track.frames.len()
        )));
    }
    out.copy_records(buf, &summary, track)?;
    out.finish(path)
}

/// Writes `track` into a trial's file being written (`smocap convert --robot`): its channels,
/// `/robot/scene` and each `/robot/tf` message at `log_ns[k]` (the log time of the human frame
/// robot frame `k` was retargeted from), and the `smocap.robot` record. `file` names the file in
/// errors.
pub fn write_track<W: std::io::Write + std::io::Seek>(
    w: &mut mcap::Writer<W>,
    track: &RobotTrack,
    log_ns: &[u64],
    file: &str,
) -> Result<(), McapOutError> {
    let bad = |what: String| McapOutError::Io { file: file.into(), source: std::io::Error::other(what) };
    if track.poses.len() != log_ns.len() || track.poses.iter().any(|p| p.len() != track.bodies.len()) {
        return Err(bad("robot poses do not match its frames and bodies".into()));
    }
    let mc = |source| McapOutError::Mcap { file: file.into(), source };
    let tf_ch = track_channel(w, &ROBOT_TF, track).map_err(mc)?;
    let scene_ch = track_channel(w, &ROBOT_SCENE, track).map_err(mc)?;
    let mut buf = Vec::with_capacity(1 << 12);
    let mut put = |w: &mut mcap::Writer<W>, ch: u16, sequence: u32, ns: u64, msg: &dyn Fn(&mut Vec<u8>)| {
        buf.clear();
        msg(&mut buf);
        let header = MessageHeader { channel_id: ch, sequence, log_time: ns, publish_time: ns };
        w.write_to_known_channel(&header, &buf).map_err(mc)
    };
    let grows = "a Vec grows as needed";
    if let Some(&ns) = log_ns.first() {
        let msg = scene(track, ns);
        put(w, scene_ch, 0, ns, &|b| msg.encode(b).expect(grows))?;
    }
    // One message refilled per frame: the frame names are built once.
    let mut msg = tf(track, 0, log_ns.first().copied().unwrap_or(0));
    for (k, &ns) in log_ns.iter().enumerate() {
        refill_tf(&mut msg, track, k, ns);
        put(w, tf_ch, track.frames[k] as u32, ns, &|b| msg.encode(b).expect(grows))?;
    }
    w.write_metadata(&track_record(track)).map_err(mc)
}

/// Adds robot channel `c` (and its schema) with its metadata (units, frames, the robot).
fn track_channel<W: std::io::Write + std::io::Seek>(
    w: &mut mcap::Writer<W>,
    c: &ChannelSpec,
    track: &RobotTrack,
) -> Result<u16, mcap::McapError> {
    let o = track.offset;
    let meta: BTreeMap<String, String> = [
        ("length_unit", "m".to_string()),
        ("robot", track.name.clone()),
        ("frame", format!("{}/world", track.name)),
        ("offset", format!("[{}, {}, {}] (m, the robot's world in world, Z up)", o.x, o.y, o.z)),
        ("log_time", "the log time of the human frame the robot frame was retargeted from".into()),
        ("rate", if c.per_frame { "one message per frame" } else { "one message, at the first frame" }.into()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    let s = w.add_schema(c.schema, "protobuf", c.descriptors)?;
    w.add_channel(s, c.topic, "protobuf", &meta)
}

/// The `smocap.robot` record of `track`.
fn track_record(track: &RobotTrack) -> Metadata {
    let mut meta = track.metadata.clone();
    meta.insert("robot".into(), track.name.clone());
    Metadata { name: ROBOT_METADATA.into(), metadata: meta }
}

/// The frame index of a `/smocap/state` message (protobuf, or the JSON encoding of older
/// files); `None` for other messages.
fn state_frame(m: &mcap::Message) -> Option<usize> {
    if m.channel.topic != super::schemas::STATE.topic {
        return None;
    }
    match m.channel.message_encoding.as_str() {
        "protobuf" => proto::State::decode(&m.data[..]).ok().map(|s| s.frame as usize),
        _ => serde_json::from_slice::<super::export::StateMsg>(&m.data).ok().map(|s| s.frame),
    }
}

/// Frame `k`'s `/robot/tf` message: `world → <robot>/world`, then every body in its parent's
/// frame (bodies in the robot's order: parents first).
fn tf(track: &RobotTrack, k: usize, ns: u64) -> proto::FrameTransforms {
    let stamp = Some(Timestamp::from_ns(ns));
    let root = format!("{}/world", track.name);
    let mut transforms = vec![proto::FrameTransform {
        timestamp: stamp,
        parent_frame_id: "world".into(),
        child_frame_id: root.clone(),
        translation: Some(v3(&track.offset)),
        rotation: Some(proto::Quaternion::IDENTITY),
    }];
    transforms.extend(track.bodies.iter().zip(&track.parents).map(|(b, parent)| proto::FrameTransform {
        timestamp: stamp,
        parent_frame_id: parent.map_or(root.clone(), |p| format!("{}/{}", track.name, track.bodies[p])),
        child_frame_id: format!("{}/{b}", track.name),
        translation: None,
        rotation: None,
    }));
    let mut msg = proto::FrameTransforms { transforms };
    refill_tf(&mut msg, track, k, ns);
    msg
}

/// [`tf`] of frame `k` written over `msg` (a [`tf`] of the same track): times and poses only.
fn refill_tf(msg: &mut proto::FrameTransforms, track: &RobotTrack, k: usize, ns: u64) {
    let stamp = Some(Timestamp::from_ns(ns));
    msg.transforms[0].timestamp = stamp;
    let poses = &track.poses[k];
    for ((t, (r, p)), parent) in msg.transforms[1..].iter_mut().zip(poses).zip(&track.parents) {
        t.timestamp = stamp;
        // In the parent body's frame: `(R_pᵀ R, R_pᵀ (p − p_p))`.
        let (r, p) = match parent {
            Some(i) => {
                let (rp, pp) = &poses[*i];
                let to_parent = rp.inverse();
                (to_parent * r, to_parent * (p - pp))
            }
            None => (*r, *p),
        };
        t.translation = Some(v3(&p));
        t.rotation = Some(quat(&r));
    }
}

/// The `/robot/scene` message: per body with capsules, an entity in its frame with a cylinder and
/// two end spheres per capsule.
fn scene(track: &RobotTrack, ns: u64) -> proto::SceneUpdate {
    let stamp = Some(Timestamp::from_ns(ns));
    let color = Some(proto::Color { r: 0.35, g: 0.55, b: 0.85, a: 0.8 });
    let at = |p: &Vector3<f64>, r: UnitQuaternion<f64>| proto::Pose {
        position: Some(proto::Vector3 { x: p.x, y: p.y, z: p.z }),
        orientation: Some(proto::Quaternion { x: r.i, y: r.j, z: r.k, w: r.w }),
    };
    let entities = (0..track.bodies.len())
        .filter(|&b| track.capsules.iter().any(|c| c.body == b))
        .map(|b| {
            let caps: Vec<&TrackCapsule> = track.capsules.iter().filter(|c| c.body == b).collect();
            let d = |c: &TrackCapsule| 2.0 * c.radius;
            let spheres = caps
                .iter()
                .flat_map(|c| if c.a == c.b { vec![c.a] } else { vec![c.a, c.b] }.into_iter().map(move |p| (p, c)))
                .map(|(p, c)| proto::SpherePrimitive {
                    pose: Some(at(&p, UnitQuaternion::identity())),
                    size: Some(proto::Vector3 { x: d(c), y: d(c), z: d(c) }),
                    color,
                })
                .collect();
            let cylinders = caps
                .iter()
                .filter(|c| c.a != c.b)
                .map(|c| {
                    let axis = c.b - c.a;
                    let r = UnitQuaternion::rotation_between(&Vector3::z(), &axis)
                        .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
                    proto::CylinderPrimitive {
                        pose: Some(at(&((c.a + c.b) / 2.0), r)),
                        size: Some(proto::Vector3 { x: d(c), y: d(c), z: axis.norm() }),
                        bottom_scale: 1.0,
                        top_scale: 1.0,
                        color,
                    }
                })
                .collect();
            proto::SceneEntity {
                timestamp: stamp,
                frame_id: format!("{}/{}", track.name, track.bodies[b]),
                id: format!("{}/{}", track.name, track.bodies[b]),
                lifetime: Some(proto::Duration::default()),
                frame_locked: true,
                metadata: Vec::new(),
                spheres,
                cylinders,
                lines: Vec::new(),
            }
        })
        .collect();
    proto::SceneUpdate { entities }
}

/// The new file being written as `<file>.partial`; dropped unfinished, it removes that file.
struct Rewrite {
    w: Option<mcap::Writer<BufWriter<std::fs::File>>>,
    tmp: PathBuf,
}

impl Rewrite {
    fn create(path: &Path, opt: &WriterOptions) -> Result<Rewrite, McapOutError> {
        let tmp = partial_path(path);
        let file = tmp.display().to_string();
        let f = std::fs::File::create(&tmp).map_err(|source| McapOutError::Io { file: file.clone(), source })?;
        let mut r = Rewrite { w: None, tmp };
        let w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(opt.zstd_level)
            .compression_threads(0)
            .chunk_size(Some(opt.chunk_size))
            .profile("")
            .library(format!("smocap {}", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::with_capacity(1 << 16, f))
            .map_err(|source| McapOutError::Mcap { file, source })?;
        r.w = Some(w);
        Ok(r)
    }

    fn err(&self) -> impl Fn(mcap::McapError) -> McapOutError + '_ {
        |source| McapOutError::Mcap { file: self.tmp.display().to_string(), source }
    }

    fn w(&mut self) -> &mut mcap::Writer<BufWriter<std::fs::File>> {
        self.w.as_mut().expect("present until finished")
    }

    /// Every channel not under [`ROBOT_PREFIX`] with its schema, under the same ids; their ids.
    fn copy_channels(&mut self, summary: &mcap::Summary) -> Result<Vec<u16>, McapOutError> {
        let mut channels: Vec<_> =
            summary.channels.values().filter(|c| !c.topic.starts_with(ROBOT_PREFIX)).cloned().collect();
        channels.sort_by_key(|c| c.id);
        let mut kept = Vec::new();
        for c in channels {
            let w = self.w.as_mut().expect("present until finished");
            let schema = match &c.schema {
                Some(s) => w.add_schema_with_id(s.id, &s.name, &s.encoding, &s.data),
                None => Ok(0),
            };
            let added = schema
                .and_then(|s| w.add_channel_with_id(c.id, s, &c.topic, &c.message_encoding, &c.metadata))
                .map_err(self.err())?;
            kept.push(added);
        }
        Ok(kept)
    }

    /// Adds robot channel `c` with its metadata (units, frames, the robot).
    fn channel(&mut self, c: &ChannelSpec, track: &RobotTrack) -> Result<u16, McapOutError> {
        let r = track_channel(self.w(), c, track);
        r.map_err(self.err())
    }

    fn message(&mut self, ch: u16, sequence: u32, ns: u64, data: &[u8]) -> Result<(), McapOutError> {
        let header = MessageHeader { channel_id: ch, sequence, log_time: ns, publish_time: ns };
        let r = self.w().write_to_known_channel(&header, data);
        r.map_err(self.err())
    }

    /// The metadata records (but an earlier `smocap.robot`) and attachments in file order, then
    /// the robot's `smocap.robot` record.
    fn copy_records(&mut self, buf: &[u8], s: &mcap::Summary, track: &RobotTrack) -> Result<(), McapOutError> {
        enum Rec<'s> {
            Meta(&'s mcap::records::MetadataIndex),
            Attach(&'s mcap::records::AttachmentIndex),
        }
        let mut recs: Vec<(u64, Rec)> = s.metadata_indexes.iter().map(|m| (m.offset, Rec::Meta(m))).collect();
        recs.extend(s.attachment_indexes.iter().map(|a| (a.offset, Rec::Attach(a))));
        recs.sort_by_key(|r| r.0);
        for (_, rec) in recs {
            let r = match rec {
                Rec::Meta(m) if m.name == ROBOT_METADATA => Ok(()),
                Rec::Meta(m) => mcap::read::metadata(buf, m).and_then(|m| self.w().write_metadata(&m)),
                Rec::Attach(a) => mcap::read::attachment(buf, a).and_then(|a| self.w().attach(&a)),
            };
            r.map_err(self.err())?;
        }
        let r = self.w().write_metadata(&track_record(track));
        r.map_err(self.err())
    }

    /// Writes the summary, syncs, and renames the file over `path`.
    fn finish(mut self, path: &Path) -> Result<(), RobotMcapError> {
        let file = self.tmp.display().to_string();
        let io = |source| McapOutError::Io { file: file.clone(), source };
        let mut w = self.w.take().expect("present until finished");
        w.finish().map_err(|source| McapOutError::Mcap { file: file.clone(), source })?;
        let f = w.into_inner().into_inner().map_err(|e| io(e.into_error()))?;
        f.sync_all().map_err(io)?;
        drop(f);
        std::fs::rename(&self.tmp, path)
            .map_err(|source| McapOutError::Io { file: path.display().to_string(), source })?;
        self.tmp = PathBuf::new();
        Ok(())
    }
}

impl Drop for Rewrite {
    fn drop(&mut self) {
        drop(self.w.take());
        if !self.tmp.as_os_str().is_empty() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}
