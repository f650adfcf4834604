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
    let gaps = &v["trials"][0]["gaps"];
    assert_eq!(gaps["frames_below_min_markers"], 1);
    let markers = gaps["markers"].as_array().unwrap();
    assert_eq!(gaps["missing_samples"].as_u64().unwrap() as usize, markers.len());
    assert!(markers.iter().all(|m| m["missing"] == 1 && m["longest_gap"] == 1 && m["missing_fraction"] == 1.0 / 40.0));
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
    assert_eq!(v["markers"][0]["longest_gap"], 1);
    assert_eq!(v["missing_samples"], 1);
    assert!((v["markers"][0]["missing_fraction"].as_f64().unwrap() - 1.0 / 3.0).abs() < 1e-12);
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

fn shared(rel: &str) -> Option<PathBuf> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared").join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipped: {} is absent", p.display());
        None
    }
}

#[test]
fn a_truncated_c3d_is_an_error_saying_so() {
    let Some(src) = shared("datasets/c3d_sample01/Eb015pi.c3d") else { return };
    let bytes = std::fs::read(src).unwrap();
    let cut = tmp("cut.c3d");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let o = smocap(&["solve", cut.to_str().unwrap()]);
    assert_clean_failure(&o, "truncated");
    assert!(stderr(&o).contains("cut.c3d"), "{}", stderr(&o));
    let o = smocap(&["markers", cut.to_str().unwrap()]);
    assert_clean_failure(&o, "truncated");
}

#[test]
fn a_trc_with_a_ragged_row_is_an_error_naming_the_line() {
    let p = one_marker_trc("ragged.trc", "A", &["1\t0.0\t1.0\t2.0\t3.0", "2\t0.01\t1.0\t2.0\t3.0\t4.0\t5.0"]);
    let o = smocap(&["solve", p.to_str().unwrap()]);
    assert_clean_failure(&o, "ragged.trc:7");
    assert!(stderr(&o).contains("coordinate cells"), "{}", stderr(&o));
}

/// The gait2354 model with `edit` applied, written to a temporary file.
fn edited_gait2354(name: &str, file: &str, edit: impl Fn(&str) -> String) -> Option<PathBuf> {
    let src = shared(&format!("datasets/gait2354_subject01/{file}"))?;
    let p = tmp(name);
    std::fs::write(&p, edit(&std::fs::read_to_string(src).unwrap())).unwrap();
    Some(p)
}

#[test]
fn an_osim_with_an_unsupported_joint_type_is_an_error_listing_the_supported_ones() {
    let Some(model) = edited_gait2354("planar.osim", "gait2354_simbody.osim", |t| {
        t.replacen("<CustomJoint name=", "<PlanarJoint name=", 1).replacen("</CustomJoint>", "</PlanarJoint>", 1)
    }) else {
        return;
    };
    let trc = one_marker_trc("any2.trc", "A", &["1\t0.0\t1.0\t2.0\t3.0"]);
    let o = smocap(&["solve", "--model", model.to_str().unwrap(), trc.to_str().unwrap()]);
    assert_clean_failure(&o, "PlanarJoint");
    assert!(stderr(&o).contains("planar.osim:") && stderr(&o).contains("CustomJoint, PinJoint"), "{}", stderr(&o));
}

#[test]
fn a_marker_set_on_a_body_the_model_lacks_is_an_error_naming_it() {
    let (Some(model), Some(set)) = (
        shared("datasets/gait2354_subject01/gait2354_simbody.osim"),
        edited_gait2354("badset.xml", "gait2354_Scale_MarkerSet.xml", |t| t.replacen("torso", "thorax_x", 1)),
    ) else {
        return;
    };
    let trc = one_marker_trc("any3.trc", "A", &["1\t0.0\t1.0\t2.0\t3.0"]);
    let o = smocap(&[
        "solve",
        "--model",
        model.to_str().unwrap(),
        "--markerset",
        set.to_str().unwrap(),
        trc.to_str().unwrap(),
    ]);
    assert_clean_failure(&o, "thorax_x");
    assert!(stderr(&o).contains("badset.xml:") && stderr(&o).contains("valid bodies"), "{}", stderr(&o));
}

#[test]
fn an_ik_setup_sets_weights_warns_on_unknown_tasks_and_refuses_from_file() {
    let Some(d) = shared("datasets/gait2354_subject01") else { return };
    let path = |f: &str| d.join(f).to_str().unwrap().to_string();
    let setup = std::fs::read_to_string(d.join("subject01_Setup_IK.xml")).unwrap();
    let unknown = tmp("ik_unknown.xml");
    std::fs::write(&unknown, setup.replacen("\"Sternum\"", "\"NoSuchMarker\"", 1)).unwrap();
    let report = tmp("ik_report.json");
    let args = |ik: &PathBuf| {
        smocap(&[
            "solve",
            "--model",
            &path("gait2354_simbody.osim"),
            "--markerset",
            &path("gait2354_Scale_MarkerSet.xml"),
            "--static",
            &path("subject01_static.trc"),
            &path("subject01_walk1.trc"),
            "--ik-setup",
            ik.to_str().unwrap(),
            "--report-json",
            report.to_str().unwrap(),
        ])
    };
    let o = args(&unknown);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("warning:") && err.contains("'NoSuchMarker'") && err.contains("lacks"), "{err}");
    assert!(err.contains("30 markers weighted") && err.contains("4 coordinate targets"), "{err}");
    assert!(err.contains("up y (detected)"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(v["trials"][0]["input"]["up"], "y");
    assert_eq!(v["static_input"]["units"], "mm");
    let from_file = tmp("ik_from_file.xml");
    std::fs::write(&from_file, setup.replacen("<value_type>default_value", "<value_type>from_file", 1)).unwrap();
    let o = args(&from_file);
    assert_clean_failure(&o, "from_file is not supported");
}

/// Rewrites every position of a TRC file (mm) through `f`, and its labels through `label`.
fn rewrite_trc(
    src: &std::path::Path,
    dst: &std::path::Path,
    f: impl Fn([f64; 3]) -> [f64; 3],
    label: impl Fn(&str) -> String,
) {
    let mut t = smocap::io::trc::read_trc(src).unwrap();
    for p in t.positions.chunks_exact_mut(3) {
        if p[0].is_finite() {
            p.copy_from_slice(&f([p[0], p[1], p[2]]));
        }
    }
    t.labels = t.labels.iter().map(|l| label(l)).collect();
    smocap::io::trc::write_trc(dst, &t, "mm").unwrap();
}

#[test]
fn y_up_prefixed_data_solve_like_the_original_z_up_data() {
    let (trc, truth) = (tmp("zup.trc"), tmp("zup.json"));
    let o = smocap(&[
        "synth",
        "--frames",
        "60",
        "--seed",
        "9",
        "--out",
        trc.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // As a Vicon lab would write it: Y up, labels with the subject's name.
    let yup = tmp("yup.trc");
    rewrite_trc(&trc, &yup, |[x, y, z]| [x, z, -y], |l| format!("Derrick:{l}"));
    let mut rmse = Vec::new();
    for (file, up) in [(&trc, "z"), (&yup, "y")] {
        let report = tmp(&format!("updown_{up}.json"));
        let o = smocap(&["solve", file.to_str().unwrap(), "--threads", "1", "--report-json", report.to_str().unwrap()]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains(&format!("up {up} (detected)")), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let t = &v["trials"][0];
        assert_eq!(t["input"]["up"], up);
        assert_eq!(t["input"]["rotation"].is_null(), up == "z");
        assert_eq!(t["unmatched_trial_markers"], serde_json::json!([]));
        assert_eq!(t["renamed_markers"].is_null(), up == "z", "{}", t["renamed_markers"]);
        rmse.push(t["marker_rmse_mm"]["p50"].as_f64().unwrap());
    }
    assert!((rmse[0] - rmse[1]).abs() < 1e-3 * rmse[0], "{rmse:?}");
    // Told an axis and units, it does as told and says so.
    let o = smocap(&["solve", yup.to_str().unwrap(), "--up", "z", "--units", "m", "--threads", "1"]);
    assert!(
        stderr(&o).contains("up z (command line)") && stderr(&o).contains("units m (command line)"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_scale_setup_supplies_groups_marker_set_static_trial_and_placement() {
    let (Some(model), Some(setup), Some(ik), Some(walk)) = (
        shared("datasets/gait2354_subject01/gait2354_simbody.osim"),
        shared("datasets/gait2354_subject01/subject01_Setup_Scale.xml"),
        shared("datasets/gait2354_subject01/subject01_Setup_IK.xml"),
        shared("datasets/gait2354_subject01/subject01_walk1.trc"),
    ) else {
        return;
    };
    let report = tmp("scale-setup.json");
    // No --markerset, no --static: both come from the setup.
    let o = smocap(&[
        "solve",
        "--model",
        model.to_str().unwrap(),
        "--scale-setup",
        setup.to_str().unwrap(),
        "--ik-setup",
        ik.to_str().unwrap(),
        "--report-json",
        report.to_str().unwrap(),
        walk.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("patella_r"), "bodies the model lacks are named: {}", stderr(&o));
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["settings"]["marker_placement"], true);
    let t = &r["trials"][0];
    // The setup's groups: both femurs share one factor (measurement "thigh"), the torso its own.
    assert_eq!(t["scale"]["femur_r"], t["scale"]["femur_l"]);
    assert_ne!(t["scale"]["femur_r"], t["scale"]["torso"]);
    let mean = t["marker_rmse_mm"]["mean"].as_f64().unwrap();
    assert!(mean < 25.0, "mean marker RMSE {mean} mm");
}

#[test]
fn a_scale_setup_naming_a_missing_static_trial_asks_for_static() {
    let (Some(model), Some(setup), Some(walk)) = (
        shared("datasets/rajagopal2016_walk/Rajagopal2016.osim"),
        shared("datasets/rajagopal2016_walk/scale_setup_walk_scaleOnly.xml"),
        shared("datasets/rajagopal2016_walk/motion_capture_walk.trc"),
    ) else {
        return;
    };
    let o = smocap(&[
        "solve",
        "--model",
        model.to_str().unwrap(),
        "--scale-setup",
        setup.to_str().unwrap(),
        walk.to_str().unwrap(),
    ]);
    assert_clean_failure(&o, "--static");
    assert!(stderr(&o).contains("static_walk_1.trc"), "{}", stderr(&o));
}

/// `synth --motion fast-arm` swings the right shoulder at ≥ 1,500°/s (issue 32's scenario); on a
/// model without that shoulder it fails saying so.
#[test]
fn synth_fast_arm_swings_the_right_shoulder_and_refuses_a_model_without_one() {
    let dir = tmp("fast-arm");
    std::fs::create_dir_all(&dir).unwrap();
    let (trc, truth) = (dir.join("a.trc"), dir.join("a.json"));
    let o = smocap(&[
        "synth",
        "--motion",
        "fast-arm",
        "--frames",
        "60",
        "--out",
        trc.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let t: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    let names: Vec<&str> = t["coordinate_names"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    let k = names.iter().position(|n| *n == "arm_flex_r").expect("arm_flex_r in the truth");
    let q: Vec<f64> = t["coordinates"].as_array().unwrap().iter().map(|f| f[k].as_f64().unwrap()).collect();
    let peak = q.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max).to_degrees() * 100.0;
    assert!(peak >= 1500.0, "peak {peak}°/s");
    let o = smocap(&[
        "synth",
        "--model",
        "models/dog.xml",
        "--profile",
        "models/dog.toml",
        "--motion",
        "fast-arm",
        "--out",
        trc.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
    ]);
    assert_clean_failure(&o, "no right shoulder flexion proxy");
    let _ = std::fs::remove_dir_all(&dir);
}
