//! The command line end to end: synth → solve with a report, and clear errors (non-zero exit,
//! no panic) on bad input.

use std::path::PathBuf;
use std::process::{Command, Output};

fn smocap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().expect("run smocap")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A one-marker TRC file (mm, 100 Hz) with the given data rows (`frame\ttime\tx\ty\tz`).
fn one_marker_trc(name: &str, label: &str, rows: &[&str]) -> PathBuf {
    let p = tmp(name);
    let header = format!(
        "PathFileType\t4\t(X/Y/Z)\t{name}\nDataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n100\t100\t{}\t1\tmm\nFrame#\tTime\t{label}\t\t\n\t\tX1\tY1\tZ1\n",
        rows.len()
    );
    std::fs::write(&p, header + &rows.join("\n") + "\n").unwrap();
    p
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn assert_clean_failure(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(!o.status.success(), "expected failure, got success; stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    assert!(err.contains(needle), "stderr should mention {needle:?}: {err}");
}

#[test]
fn synth_then_solve_writes_a_report_with_truth_errors() {
    let (trc, truth, report) = (tmp("walk.trc"), tmp("walk.json"), tmp("report.json"));
    let o = smocap(&[
        "synth",
        "--frames",
        "80",
        "--seed",
        "5",
        "--out",
        trc.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = smocap(&[
        "solve",
        trc.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
        "--threads",
        "2",
        "--report-json",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    for key in ["smocap_version", "backend", "threads", "trials", "totals"] {
        assert!(v.get(key).is_some(), "report lacks {key}");
    }
    let t = &v["trials"][0];
    assert_eq!(t["status"], "ok");
    assert_eq!(t["frames"], 80);
    for key in
        ["marker_rmse_mm", "ms_per_frame", "iterations", "solve_wall_s", "scale", "pose_error_deg", "scale_error_pct"]
    {
        assert!(t.get(key).is_some(), "trial lacks {key}");
    }
    assert!(t["pose_error_deg"]["rmse"].as_f64().unwrap() < 1.0);
    assert!(v["totals"]["frames_per_s"].as_f64().unwrap() > 0.0);
    assert_eq!(v["backend"], "cpu");
}

#[test]
fn a_missing_trial_file_is_an_error_naming_the_file() {
    let o = smocap(&["solve", "no/such/trial.trc"]);
    assert_clean_failure(&o, "no/such/trial.trc");
}

#[test]
fn a_malformed_trc_is_an_error_naming_the_line() {
    let p = one_marker_trc("bad.trc", "A", &["1\t0.0\t1.0\tabc\t3.0"]);
    let o = smocap(&["solve", p.to_str().unwrap()]);
    assert_clean_failure(&o, "bad.trc");
}

#[test]
fn a_model_with_an_unknown_joint_type_is_an_error() {
    let p = tmp("bad_joint.xml");
    std::fs::write(&p, "<mujoco model=\"m\">\n<worldbody>\n<body name=\"a\">\n<joint name=\"j\" type=\"screw\"/>\n</body>\n</worldbody>\n</mujoco>\n").unwrap();
    let trc = one_marker_trc("any.trc", "A", &["1\t0.0\t1.0\t2.0\t3.0"]);
    let o = smocap(&["solve", "--model", p.to_str().unwrap(), trc.to_str().unwrap()]);
    assert_clean_failure(&o, "screw");
}

#[test]
fn a_marker_set_matching_no_model_marker_is_an_error_listing_both_sides() {
    let trc = one_marker_trc("nomatch.trc", "FOO", &["1\t0.0\t1.0\t2.0\t3.0", "2\t0.01\t1.0\t2.0\t3.0"]);
    let o = smocap(&["solve", trc.to_str().unwrap()]);
    assert_clean_failure(&o, "FOO");
    assert!(stderr(&o).contains("LASI"), "{}", stderr(&o));
}

#[test]
fn demo_runs_on_the_embedded_default() {
    let o = smocap(&["demo", "--frames", "60", "--threads", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("RMSE") && out.contains("joint angle RMSE"), "{out}");
}

#[test]
fn a_frame_with_every_marker_missing_is_reported_and_the_rest_solved() {
    let (trc, truth, report) = (tmp("gap.trc"), tmp("gap.json"), tmp("gap_report.json"));
    let o = smocap(&[
        "synth",
        "--frames",
        "40",
        "--seed",
        "6",
        "--out",
        trc.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Blank every marker of frame 11 (file frame numbers start at 1).
    let text = std::fs::read_to_string(&trc).unwrap();
    let blanked: Vec<String> = text
        .lines()
        .map(|l| {
            let cells: Vec<&str> = l.split('\t').collect();
            if cells.first() == Some(&"11") && cells.len() > 2 {
                let mut c: Vec<String> = cells[..2].iter().map(|s| s.to_string()).collect();
                c.extend(std::iter::repeat_n(String::new(), cells.len() - 2));
                c.join("\t")
            } else {
                l.to_string()
            }
        })
        .collect();
    std::fs::write(&trc, blanked.join("\n") + "\n").unwrap();
    let o = smocap(&["solve", trc.to_str().unwrap(), "--threads", "1", "--report-json", report.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("frame 10"), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(v["trials"][0]["bridged_frames"], serde_json::json!([10]));
    assert_eq!(v["trials"][0]["frames"], 40);
}

#[test]
fn markers_summarises_a_file_with_its_gaps_as_json() {
    let p = one_marker_trc("summary.trc", "A", &["1\t0.0\t1.0\t2.0\t3.0", "2\t0.01\t\t\t", "3\t0.02\t1.0\t2.0\t3.0"]);
    let o = smocap(&["markers", p.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["frames"], 3);
    assert_eq!(v["rate_hz"], 100.0);
    assert_eq!(v["markers"][0]["label"], "A");
    assert_eq!(v["markers"][0]["gaps"], 1);
    let o = smocap(&["markers", "trial.xyz"]);
    assert_clean_failure(&o, "unsupported marker file type");
}

#[test]
fn solves_an_opensim_model_with_a_marker_set_and_a_static_trial() {
    let d = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets/gait2354_subject01");
    if !d.exists() {
        eprintln!("skipped: {} is absent", d.display());
        return;
    }
    let (report, mots, scaled) = (tmp("gait2354.json"), tmp("gait2354_mot"), tmp("subject01.osim"));
    let path = |f: &str| d.join(f).to_str().unwrap().to_string();
    let o = smocap(&[
        "solve",
        "--model",
        &path("gait2354_simbody.osim"),
        "--markerset",
        &path("gait2354_Scale_MarkerSet.xml"),
        "--static",
        &path("subject01_static.trc"),
        &path("subject01_walk1.trc"),
        "--report-json",
        report.to_str().unwrap(),
        "--mot-dir",
        mots.to_str().unwrap(),
        "--scaled-model",
        scaled.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(v["trials"][0]["frames"], 151);
    assert!(v["trials"][0]["marker_rmse_mm"]["p50"].as_f64().unwrap() < 60.0);
    // OpenSim outputs: the motion has OpenSim's own IK columns; the subject keeps the marker set.
    let mot = smocap::io::sto::read_sto(&mots.join("subject01_walk1.mot")).expect("motion");
    assert_eq!(mot.rows.len(), 151);
    let reference = d.join("../../shared/reference/opensim-4.6/gait2354_subject01/subject01_walk1_ik.mot");
    if let Ok(ik) = smocap::io::sto::read_sto(&reference) {
        assert_eq!(mot.columns, ik.columns);
    }
    let (subject, _) = smocap::io::osim::read_osim(&scaled).expect("scaled model re-imports");
    let set = smocap::io::osim::read_marker_set(std::path::Path::new(&path("gait2354_Scale_MarkerSet.xml")), &subject)
        .expect("marker set");
    let names = |m: &[smocap::model::Marker]| m.iter().map(|x| x.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(&subject.markers), names(&set));
    assert!(scaled.with_extension("scaleset.xml").exists());
}

#[test]
fn solve_writes_a_motion_per_trial_and_the_generated_subject_model() {
    let (trc, mots, scaled) = (tmp("export.trc"), tmp("export_mot"), tmp("export_subject.osim"));
    let truth = tmp("export.json");
    let args =
        ["synth", "--frames", "30", "--seed", "9", "--out", trc.to_str().unwrap(), "--truth", truth.to_str().unwrap()];
    let o = smocap(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = smocap(&[
        "solve",
        trc.to_str().unwrap(),
        "--mot-dir",
        mots.to_str().unwrap(),
        "--scaled-model",
        scaled.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mot = smocap::io::sto::read_sto(&mots.join("export.mot")).expect("motion");
    assert_eq!(mot.rows.len(), 30);
    assert_eq!(mot.in_degrees(), Some(true));
    let ctx = smocap::pipeline::Context::shipped().unwrap();
    assert_eq!(mot.columns.len(), 1 + ctx.model.nq());
    let (subject, _) = smocap::io::osim::read_osim(&scaled).expect("generated model re-imports");
    assert_eq!((subject.nb(), subject.markers.len()), (ctx.model.nb(), ctx.model.markers.len()));
}
