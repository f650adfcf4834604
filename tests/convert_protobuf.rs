//! The protobuf MCAP files of `smocap convert`: every channel decodes with the messages of
//! `proto/` and its schema record carries a descriptor set naming its message; `/tf` is one tree
//! rooted at a Z-up `world` (the head above the feet, for the shipped Z-up model and for an
//! OpenSim Y-up one); the skeleton, the subject and the label QC are sent once; files are byte-identical
//! across runs; `--epoch` sets the log times.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use prost::Message;
use smocap::archive::config::SyntheticSpec;
use smocap::archive::proto;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn smocap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().expect("run smocap")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-proto-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A synthetic archive of the shipped model, converted: the folder and the first trial's file.
fn converted(name: &str, frames: usize, extra: &[&str]) -> (PathBuf, PathBuf) {
    let dir = tmp(name);
    let file = convert_into(&dir, frames, "out", extra);
    (dir, file)
}

/// Generates the archive in `dir` (unless there) and converts it to `dir/<out>`; the first
/// trial's file.
fn convert_into(dir: &Path, frames: usize, out: &str, extra: &[&str]) -> PathBuf {
    let spec = SyntheticSpec { subjects: 1, trials: 1, frames, seed: 5 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(
        &toml,
        "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\nstatic = \"{subject}/static.trc\"\n",
    )
    .unwrap();
    let out = dir.join(out);
    let o = smocap(&[&["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"], extra].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out.join("lab/subj01/walk01.mcap")
}

/// Messages by topic: (log time, data), in file order.
fn messages(path: &Path) -> BTreeMap<String, Vec<(u64, Vec<u8>)>> {
    let buf = std::fs::read(path).unwrap();
    let mut by = BTreeMap::<String, Vec<(u64, Vec<u8>)>>::new();
    for m in mcap::MessageStream::new(&buf).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.channel.message_encoding, "protobuf", "{}", m.channel.topic);
        let s = m.channel.schema.as_ref().unwrap();
        assert_eq!(s.encoding, "protobuf");
        let name = s.name.rsplit('.').next().unwrap();
        assert!(s.data.windows(name.len()).any(|w| w == name.as_bytes()), "{} descriptors name {name}", s.name);
        by.entry(m.channel.topic.clone()).or_default().push((m.log_time, m.data.to_vec()));
    }
    by
}

/// Each frame's pose in `world` (rotation, translation) from one `/tf` message, checking that
/// the transforms form one tree rooted at `world`.
fn world_poses(tf: &proto::FrameTransforms) -> BTreeMap<String, (UnitQuaternion<f64>, Vector3<f64>)> {
    let mut parent = BTreeMap::new();
    for t in &tf.transforms {
        assert!(parent.insert(t.child_frame_id.clone(), t).is_none(), "{} has two parents", t.child_frame_id);
    }
    assert!(!parent.contains_key("world"), "world is the root");
    let mut poses = BTreeMap::new();
    for child in parent.keys() {
        let (mut r, mut p) = (UnitQuaternion::identity(), Vector3::zeros());
        let mut f = child.as_str();
        for _ in 0..=parent.len() {
            let Some(t) = parent.get(f) else { break };
            let q = t.rotation.unwrap();
            let rt = UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z));
            let tr = t.translation.unwrap();
            // pose_in_parent ∘ pose: x_parent = rt · x + tr.
            p = rt * p + Vector3::new(tr.x, tr.y, tr.z);
            r = rt * r;
            f = t.parent_frame_id.as_str();
        }
        assert_eq!(f, "world", "{child} is not under world");
        poses.insert(child.clone(), (r, p));
    }
    poses
}

/// Asserts `top` is well above every one of `feet` in `world` (z up) in the first frame.
fn assert_upright(path: &Path, top: &str, feet: &[&str]) {
    let by = messages(path);
    let tf = proto::FrameTransforms::decode(&by["/tf"][0].1[..]).unwrap();
    let poses = world_poses(&tf);
    let z = |b: &str| poses.get(b).unwrap_or_else(|| panic!("no frame {b}: {:?}", poses.keys())).1.z;
    for foot in feet {
        assert!(z(top) > z(foot) + 0.4, "{top} at z = {} m, {foot} at {} m", z(top), z(foot));
    }
}

#[test]
fn tf_is_one_tree_rooted_at_z_up_world_with_the_head_above_the_feet() {
    let (dir, path) = converted("upright", 30, &[]);
    assert_upright(&path, "head", &["calcn_r", "calcn_l", "toes_r"]);
    let by = messages(&path);
    let tf = proto::FrameTransforms::decode(&by["/tf"][0].1[..]).unwrap();
    assert_eq!(
        (tf.transforms[0].parent_frame_id.as_str(), tf.transforms[0].child_frame_id.as_str()),
        ("world", "model")
    );
    // Every body hangs off its parent body, not off world: the tree has depth.
    let femur = tf.transforms.iter().find(|t| t.child_frame_id == "femur_r").unwrap();
    assert_eq!(femur.parent_frame_id, "pelvis");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_y_up_opensim_model_is_rotated_upright_at_the_root() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets/gait2354_subject01");
    if !root.is_dir() {
        eprintln!("note: ../shared/datasets/gait2354_subject01 absent; skipped");
        return;
    }
    let dir = tmp("gait2354");
    let out = dir.join("out");
    let toml = concat!(env!("CARGO_MANIFEST_DIR"), "/datasets.toml");
    let o = smocap(&["convert", toml, "--dataset", "gait2354_subject01", "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let path = out.join("gait2354_subject01/subject01_walk1.mcap");
    assert_upright(&path, "torso", &["calcn_r", "calcn_l"]);
    let by = messages(&path);
    let tf = proto::FrameTransforms::decode(&by["/tf"][0].1[..]).unwrap();
    let q = tf.transforms[0].rotation.unwrap();
    let s = std::f64::consts::FRAC_1_SQRT_2;
    assert!((q.x - s).abs() < 1e-5 && q.y.abs() < 1e-9 && q.z.abs() < 1e-9 && (q.w - s).abs() < 1e-5, "{q:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_channel_decodes_and_the_skeleton_and_subject_come_once() {
    let frames = 25;
    let (dir, path) = converted("decode", frames, &[]);
    let by = messages(&path);
    let topics: Vec<&str> = by.keys().map(String::as_str).collect();
    assert_eq!(
        topics,
        ["/markers", "/scene", "/smocap/label_qc", "/smocap/state", "/smocap/stats", "/smocap/subject", "/tf"]
    );
    assert_eq!(by["/smocap/label_qc"].len(), 1);
    let qc = proto::LabelQc::decode(&by["/smocap/label_qc"][0].1[..]).unwrap();
    assert_eq!((qc.mode.as_str(), qc.events.len(), qc.suspect.as_str()), ("repair", 0, ""), "{qc:?}");
    let sub = proto::Subject::decode(&by["/smocap/subject"][0].1[..]).unwrap();
    assert_eq!(by["/smocap/subject"].len(), 1);
    assert_eq!(by["/scene"].len(), 1);
    let ctx = smocap::pipeline::Context::shipped().unwrap();
    assert_eq!(sub.coordinates.len(), ctx.model.nq());
    assert_eq!(sub.body_scale.len(), 3 * ctx.model.nb());
    assert_eq!(sub.markers.len(), ctx.model.markers.len());
    assert_eq!(sub.scale_proxies.len(), sub.calibrated_scale.len());
    let scene = proto::SceneUpdate::decode(&by["/scene"][0].1[..]).unwrap();
    assert_eq!(scene.entities.len(), ctx.model.nb());
    assert!(scene.entities.iter().all(|e| e.frame_locked && e.frame_id == e.id));
    let spheres: usize = scene.entities.iter().map(|e| e.spheres.len()).sum();
    assert_eq!(spheres, ctx.model.markers.len(), "one sphere per model marker");
    for topic in ["/markers", "/smocap/state", "/smocap/stats", "/tf"] {
        assert_eq!(by[topic].len(), frames, "{topic}");
    }
    let epoch = smocap::archive::mcap_out::DEFAULT_EPOCH_NS;
    for (f, (t, data)) in by["/smocap/state"].iter().enumerate() {
        let s = proto::State::decode(&data[..]).unwrap();
        assert_eq!(
            (s.frame as usize, s.q.len(), s.scale_drift_ppm.len()),
            (f, sub.coordinates.len(), sub.scale_proxies.len())
        );
        assert_eq!(*t, epoch + (s.time * 1e9).round() as u64, "log time = epoch + frame time");
        let ts = s.timestamp.unwrap();
        assert_eq!(ts.seconds as u64 * 1_000_000_000 + ts.nanos as u64, *t);
    }
    for (_, data) in &by["/markers"] {
        let c = proto::PointCloud::decode(&data[..]).unwrap();
        assert_eq!((c.point_stride, c.data.len(), c.frame_id.as_str()), (12, 12 * sub.markers.len(), "model"));
    }
    for (_, data) in &by["/smocap/stats"] {
        let s = proto::SolverStats::decode(&data[..]).unwrap();
        assert!(s.iterations >= 1 && s.marker_rmse > 0.0 && s.marker_rmse < 0.05, "{s:?}");
        assert_eq!(s.solve_s, 0.0, "no timings without --timings");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn files_are_byte_identical_across_runs_and_epoch_sets_the_log_times() {
    let (dir, a) = converted("same", 40, &[]);
    let b = convert_into(&dir, 40, "again", &["--jobs", "1"]);
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(), "{} and {} differ", a.display(), b.display());
    let c = convert_into(&dir, 40, "epoch", &["--epoch", "2024-05-01T12:00:00Z", "--timings"]);
    let by = messages(&c);
    let first = by["/smocap/state"][0].0;
    assert_eq!(first, 1_714_564_800 * 1_000_000_000);
    assert!(by["/smocap/stats"].iter().any(|(_, d)| proto::SolverStats::decode(&d[..]).unwrap().solve_s > 0.0));
    let _ = std::fs::remove_dir_all(&dir);
}
