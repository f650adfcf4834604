//! The robot beside the human (issue 31): `smocap convert --robot` writes each trial's robot
//! files beside its MCAP file and adds `/robot/tf` and `/robot/scene` to it, copying every other
//! record unchanged; `smocap retarget --into-mcap` replaces the robot rather than adding a
//! second one; resuming redoes a trial's robot only when its outputs are incomplete; a trial
//! whose robot fails keeps its MCAP as converted and gets no robot files.

use smocap::archive::config::SyntheticSpec;
use smocap::archive::inspect::{inspect, verify};
use smocap::archive::proto;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn smocap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().expect("run smocap")
}

/// A synthetic archive of one subject with `trials` trials of 120 frames, and its datasets.toml.
fn archive(name: &str, trials: usize) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("smocap-robot-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let spec = SyntheticSpec { subjects: 1, trials, frames: 120, seed: 7 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(&toml, "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\nstatic = \"{subject}/static.trc\"\n").unwrap();
    (dir, toml)
}

fn convert(toml: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--jobs", "2", "-q"];
    args.extend_from_slice(extra);
    smocap(&args)
}

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Every message of `path`: (topic, channel id, sequence, log time, data), in file order.
fn messages(path: &Path) -> Vec<(String, u16, u32, u64, Vec<u8>)> {
    let buf = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&buf)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            (m.channel.topic.clone(), m.channel.id, m.sequence, m.log_time, m.data.to_vec())
        })
        .collect()
}

/// The `/robot/tf` messages of `path`, decoded.
fn robot_tf(path: &Path) -> Vec<proto::FrameTransforms> {
    use prost::Message as _;
    let tf = messages(path).into_iter().filter(|m| m.0 == "/robot/tf");
    tf.map(|m| proto::FrameTransforms::decode(&m.4[..]).unwrap()).collect()
}

/// Every frame's origin in `g1/world` (m), composed down the tree of one `/robot/tf` message
/// (each body in its parent's frame, parents first).
fn robot_origins(msg: &proto::FrameTransforms) -> BTreeMap<String, nalgebra::Vector3<f64>> {
    use nalgebra::{Quaternion, UnitQuaternion, Vector3};
    let mut at = BTreeMap::from([("g1/world".to_string(), (UnitQuaternion::identity(), Vector3::zeros()))]);
    for t in &msg.transforms[1..] {
        let (r, p) = at[&t.parent_frame_id];
        let (q, v) = (t.rotation.unwrap(), t.translation.unwrap());
        let local = UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z));
        at.insert(t.child_frame_id.clone(), (r * local, p + r * Vector3::new(v.x, v.y, v.z)));
    }
    at.into_iter().map(|(k, (_, p))| (k, p)).collect()
}

/// How far a composed origin may be from the body's position: each link's transform is on the
/// 2⁻¹⁵ grid (30 µm, 30 µrad per quaternion component), composed over chains of up to 8 links
/// a few decimetres long.
const TREE_TOLERANCE: f64 = 5e-4;

const EXTS: [&str; 4] = ["pkl", "csv", "npz", "json"];

#[test]
fn convert_with_a_robot_adds_its_files_and_channels_and_copies_every_other_record_unchanged() {
    let (dir, toml) = archive("convert", 2);
    let plain = dir.join("plain");
    let with = dir.join("robot");
    assert!(convert(&toml, &plain, &[]).status.success());
    let rj = dir.join("robot.json");
    let o = convert(&toml, &with, &["--robot", "g1", "--report-json", rj.to_str().unwrap()]);
    assert!(matches!(o.status.code(), Some(0)), "{}", String::from_utf8_lossy(&o.stderr));
    for t in ["walk01", "walk02"] {
        let (a, b) = (plain.join(format!("lab/subj01/{t}.mcap")), with.join(format!("lab/subj01/{t}.mcap")));
        for e in EXTS {
            assert!(with.join(format!("lab/subj01/{t}.g1.{e}")).is_file(), "{t}.g1.{e}");
        }
        let info = verify(&b).unwrap();
        let count = |topic: &str| info.channels.iter().filter(|c| c.topic == topic).map(|c| c.messages).sum::<u64>();
        assert_eq!((count("/robot/tf"), count("/robot/scene")), (120, 1));
        assert_eq!(info.metadata["smocap.robot"]["robot"], "g1");
        // Everything else as converted without a robot: messages (channel ids, sequences, log
        // times, bytes), metadata and attachments.
        let human: Vec<_> = messages(&b).into_iter().filter(|m| !m.0.starts_with("/robot/")).collect();
        assert_eq!(human, messages(&a));
        let plain_info = inspect(&a).unwrap();
        let mut meta = info.metadata.clone();
        meta.remove("smocap.robot");
        assert_eq!(meta, plain_info.metadata);
        assert_eq!(info.attachments, plain_info.attachments);
        // Each robot frame at its human frame's log time.
        let state: Vec<u64> = messages(&a).into_iter().filter(|m| m.0 == "/smocap/state").map(|m| m.3).collect();
        let robot: Vec<u64> = messages(&b).into_iter().filter(|m| m.0 == "/robot/tf").map(|m| m.3).collect();
        assert_eq!(robot, state);
        // Retargeted from the solved motion while the file was written, the robot is the one
        // `smocap retarget` makes from the finished file (scaled model against model + scales:
        // the same poses to far below the /tf grid, 2^-15 m).
        let setup = smocap::cli::robot::RobotSetup::load("g1", None, None).unwrap();
        let rec = smocap::archive::export::read_trial_record(&b).unwrap();
        let done = setup.retarget(&smocap::render::Take::from_record(&rec, &b).unwrap()).unwrap();
        let tf = robot_tf(&b);
        assert_eq!(tf.len(), done.motion.body_pos_w.len());
        for (k, msg) in tf.iter().enumerate() {
            let origins = robot_origins(msg);
            for (name, want) in done.motion.body_names.iter().zip(&done.motion.body_pos_w[k]) {
                let p = origins[&format!("g1/{name}")];
                let err = (p - nalgebra::Vector3::from(*want)).amax();
                assert!(err <= TREE_TOLERANCE, "{t} frame {k} body {name}: off by {err} m");
            }
        }
    }
    let r = report(&rj);
    for t in r["trials"].as_array().unwrap() {
        let status = t["robot"]["status"].as_str().unwrap();
        assert!(status == "ok" || status == "suspect", "{t}");
    }
}

#[test]
fn robot_tf_holds_every_body_pose_of_the_retargeted_motion_beside_the_human() {
    let (dir, toml) = archive("poses", 1);
    let out = dir.join("out");
    assert!(convert(&toml, &out, &[]).status.success());
    let mcap = out.join("lab/subj01/walk01.mcap");
    let m = mcap.to_str().unwrap();
    let o = smocap(&["retarget", m, "--into-mcap", "--robot-offset", "0,1", "-q"]);
    assert!(o.status.code().is_some_and(|c| c == 0 || c == 2), "{}", String::from_utf8_lossy(&o.stderr));
    let tf = robot_tf(&mcap);
    assert_eq!(tf.len(), 120);
    // The offset: `world → g1/world`, then every body in its parent's frame (the pelvis in
    // `g1/world`).
    let first = &tf[0].transforms;
    assert_eq!((first[0].parent_frame_id.as_str(), first[0].child_frame_id.as_str()), ("world", "g1/world"));
    assert_eq!(first[0].translation.unwrap(), proto::Vector3 { x: 0.0, y: 1.0, z: 0.0 });
    // The poses are the retargeted motion's body positions (to the /tf grid, 2^-15 m).
    let setup = smocap::cli::robot::RobotSetup::load("g1", None, None).unwrap();
    let rec = smocap::archive::export::read_trial_record(&mcap).unwrap();
    let take = smocap::render::Take::from_record(&rec, &mcap).unwrap();
    let done = setup.retarget(&take).unwrap();
    let names = &done.motion.body_names;
    assert_eq!(first.len(), 1 + names.len());
    let parents: Vec<&str> = first[1..].iter().map(|t| t.parent_frame_id.as_str()).collect();
    assert_eq!(parents[..2], ["g1/world", "g1/pelvis"]);
    for (k, msg) in tf.iter().enumerate().step_by(17) {
        let origins = robot_origins(msg);
        for (b, name) in names.iter().enumerate() {
            assert_eq!(msg.transforms[b + 1].child_frame_id, format!("g1/{name}"));
            let err = (origins[&format!("g1/{name}")] - nalgebra::Vector3::from(done.motion.body_pos_w[k][b])).amax();
            assert!(err <= TREE_TOLERANCE, "frame {k} body {name}: off by {err} m");
        }
    }
    // Again, with the robot where the human is: replaced, not added.
    let o = smocap(&["retarget", m, "--into-mcap", "-q"]);
    assert!(o.status.code().is_some_and(|c| c == 0 || c == 2));
    let info = verify(&mcap).unwrap();
    let topics: Vec<&str> = info.channels.iter().map(|c| c.topic.as_str()).collect();
    assert_eq!(topics.iter().filter(|t| t.starts_with("/robot/")).count(), 2, "{topics:?}");
    assert_eq!(robot_tf(&mcap)[0].transforms[0].translation.unwrap(), proto::Vector3::default());
    assert!(smocap(&["inspect", m]).status.success());
}

#[test]
fn resuming_redoes_a_trials_robot_only_when_its_outputs_are_incomplete() {
    let (dir, toml) = archive("resume", 2);
    let out = dir.join("out");
    assert!(convert(&toml, &out, &["--robot", "g1"]).status.success());
    let gone = out.join("lab/subj01/walk02.g1.npz");
    std::fs::remove_file(&gone).unwrap();
    let kept = out.join("lab/subj01/walk01.g1.npz");
    let before = std::fs::metadata(&kept).unwrap().modified().unwrap();
    let rj = dir.join("resume.json");
    let o = convert(&toml, &out, &["--robot", "g1", "--resume", "--report-json", rj.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(gone.is_file());
    assert_eq!(std::fs::metadata(&kept).unwrap().modified().unwrap(), before);
    let r = report(&rj);
    let by: BTreeMap<&str, &str> = r["trials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| (t["trial"].as_str().unwrap(), t["robot"]["status"].as_str().unwrap()))
        .collect();
    assert_eq!(by["subj01/walk01.trc"], "skipped");
    assert_ne!(by["subj01/walk02.trc"], "skipped");
    // One robot per file still.
    let info = verify(&out.join("lab/subj01/walk02.mcap")).unwrap();
    assert_eq!(info.channels.iter().filter(|c| c.topic == "/robot/tf").count(), 1);
}

#[test]
fn a_trial_whose_robot_fails_keeps_its_converted_mcap_and_gets_no_robot_files() {
    let (dir, toml) = archive("fails", 1);
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The shipped mapping with one human body the model does not have.
    let text = std::fs::read_to_string(repo.join("models/robots/g1/opensim.toml")).unwrap();
    let g1 = repo.join("models/robots/g1/g1.xml");
    let bad = text.replace("robot = \"g1.xml\"", &format!("robot = {:?}", g1.to_str().unwrap()));
    let bad = bad.replacen("human = \"pelvis\"", "human = \"no_such_body\"", 1);
    assert_ne!(bad, text);
    let mapping = dir.join("broken.toml");
    std::fs::write(&mapping, bad).unwrap();
    let out = dir.join("out");
    let o = convert(&toml, &out, &["--robot", mapping.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(3), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("without their robot"));
    let mcap = out.join("lab/subj01/walk01.mcap");
    let info = verify(&mcap).unwrap();
    assert!(info.channels.iter().all(|c| !c.topic.starts_with("/robot/")));
    for e in EXTS {
        assert!(!out.join(format!("lab/subj01/walk01.broken.{e}")).exists(), "{e}");
    }
    let partial = out.join("lab/subj01/walk01.mcap.partial");
    assert!(!partial.exists());
}

#[test]
fn robot_offsets_parse_as_two_or_three_metres_and_robot_files_keep_the_trial_stems_dots() {
    use smocap::cli::robot::{beside, parse_offset};
    assert_eq!(parse_offset("0,1"), Ok([0.0, 1.0, 0.0]));
    assert_eq!(parse_offset("0.5, -1, 0.1"), Ok([0.5, -1.0, 0.1]));
    assert!(parse_offset("1").is_err() && parse_offset("a,b").is_err() && parse_offset("nan,0").is_err());
    assert_eq!(beside(Path::new("out/walk.01.g1"), "pkl"), PathBuf::from("out/walk.01.g1.pkl"));
}
