//! Camera rigs and 2D ground truth (`smocap project`, [`smocap::render::rig`],
//! [`smocap::render::project`]): the default rig reproduces the thesis' geometry; a point
//! straight ahead of a camera lands at its principal point (in the projection, and in the COCO
//! file `project` writes for a marker of a converted trial); bad rig files are refused with the
//! reason; a converted shared trial gets its COCO JSON, CSV, cameras and metrics.

mod common;

use common::{convert_archive, converted_synthetic};
use nalgebra::Vector3;
use serde_json::Value;
use smocap::render::rig::{self, default_rig, parse_rig, SubjectFrame};
use smocap::render::Take;
use std::path::PathBuf;

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-project-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn smocap(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().unwrap()
}

fn walking_frame() -> SubjectFrame {
    // A root walking 3 m along world −y at 0.95 m: forward −y, left +x.
    let pos: Vec<Vector3<f64>> = (0..=30).map(|i| Vector3::new(0.4, 1.0 - 0.1 * i as f64, 0.95)).collect();
    SubjectFrame::from_root(&pos, &vec![-Vector3::y(); pos.len()])
}

#[test]
fn the_default_rig_is_a_frontal_and_a_sagittal_camera_at_hip_height_with_the_thesis_optics() {
    let frame = walking_frame();
    assert!((frame.forward - -Vector3::y()).norm() < 1e-12 && (frame.left - Vector3::x()).norm() < 1e-12);
    assert!((frame.half_path - 1.5).abs() < 1e-9 && (frame.root_height - 0.95).abs() < 1e-9);
    for seed in 0..20 {
        let cams = default_rig(&frame, seed);
        assert_eq!(cams.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(), ["frontal", "sagittal"]);
        for c in &cams {
            let centre = c.centre();
            assert!((1.0..=1.2).contains(&centre.z), "{} at {} m", c.name, centre.z);
            assert_eq!((c.focal_mm, c.sensor_width_mm, c.width_px, c.height_px), (33.0, 36.0, 1080, 720));
            // Horizontal fit: fx = 33/36 · 1080 px; square pixels; principal point at the centre.
            assert!((c.k[(0, 0)] - 990.0).abs() < 1e-9 && c.k[(1, 1)] == c.k[(0, 0)]);
            assert_eq!((c.k[(0, 2)], c.k[(1, 2)]), (539.5, 359.5));
            // Aimed at the root's mean position: it projects to the principal point.
            let p = c.project(&(frame.origin + Vector3::z() * frame.root_height));
            assert!((p.u - 539.5).abs() < 1e-9 && (p.v - 359.5).abs() < 1e-9 && p.in_image);
        }
        let axis = |c: &rig::Camera| c.r.row(2).transpose();
        // Frontal looks back along the walk (towards +y), sagittal at the subject's right side (towards +x).
        let (f, s) = (axis(&cams[0]), axis(&cams[1]));
        assert!(f.dot(&Vector3::y()) > 0.99, "frontal axis {f}");
        assert!(s.dot(&Vector3::x()) > 0.99, "sagittal axis {s}");
        // Nominal places ±0.1 m: 4 m beyond the path's front end; beside it at ≥ 4 m.
        let (fc, sc) = (cams[0].centre(), cams[1].centre());
        assert!((fc.y - (-0.5 - 5.5)).abs() <= 0.1 + 1e-12 && (fc.x - 0.4).abs() <= 0.1 + 1e-12, "{fc}");
        let side = 4.0f64.max(2.5 / (18.0 / 33.0));
        assert!((sc.x - (0.4 - side)).abs() <= 0.1 + 1e-12 && (sc.y - (-0.5)).abs() <= 0.1 + 1e-12, "{sc}");
        // The root's whole path is in the sagittal image.
        for y in [1.0, -2.0] {
            assert!(cams[1].project(&Vector3::new(0.4, y, 0.95)).in_image);
        }
    }
    assert_eq!(default_rig(&frame, 3), default_rig(&frame, 3), "a seed gives one rig");
    assert_ne!(default_rig(&frame, 3), default_rig(&frame, 4), "seeds perturb the positions");
}

#[test]
fn a_point_straight_ahead_of_a_camera_lands_at_the_principal_point() {
    let text = "[[cameras]]\nname = \"a\"\nposition = [1.0, 2.0, 1.5]\nlook_at = [-3.0, 0.5, 0.2]\nfocal_mm = 50\nsensor_width_mm = 24\nwidth_px = 1921\nheight_px = 1081\n\n[[cameras]]\nname = \"b\"\nposition = [0.0, -4.0, 1.0]\nrotation = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]\nfocal_mm = 33\nsensor_width_mm = 36\nwidth_px = 1080\nheight_px = 720\n";
    let cams = parse_rig(text, "rig.toml", &SubjectFrame::world()).unwrap();
    for c in &cams {
        let ahead = c.centre() + c.r.row(2).transpose() * 2.7;
        let p = c.project(&ahead);
        assert!((p.u - c.k[(0, 2)]).abs() < 1e-9 && (p.v - c.k[(1, 2)]).abs() < 1e-9, "{}: {p:?}", c.name);
        assert!((p.depth - 2.7).abs() < 1e-12 && p.in_image);
    }
    // Camera b looks along +y with image down = −z: a point above the axis is above the centre.
    let p = cams[1].project(&Vector3::new(0.0, 0.0, 1.5));
    assert!(p.v < 359.5 && (p.u - 539.5).abs() < 1e-9);
}

#[test]
fn project_puts_a_marker_straight_ahead_of_a_camera_at_its_principal_point_in_the_coco_file() {
    let dir = tmp("ahead");
    let file = converted_synthetic(&dir, 20);
    let rec = smocap::archive::export::read_trial_record(&file).unwrap();
    let take = Take::from_record(&rec, &file).unwrap();
    let mut ws = smocap::kinematics::Workspace::new(&take.model);
    let m = take.model.markers.len() / 2;
    let target = take.pose(0, &mut ws).markers[m];
    let rig = dir.join("rig.toml");
    std::fs::write(
        &rig,
        format!(
            "[[cameras]]\nname = \"ahead\"\nposition = [{}, {}, {}]\nlook_at = [{}, {}, {}]\nfocal_mm = 33\nsensor_width_mm = 36\nwidth_px = 1080\nheight_px = 720\n",
            target.x + 3.0, target.y + 0.5, target.z + 0.2, target.x, target.y, target.z
        ),
    )
    .unwrap();
    let out = dir.join("gt");
    let o = smocap(&[
        "project",
        file.to_str().unwrap(),
        "--cameras",
        rig.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let coco: Value = serde_json::from_slice(&std::fs::read(out.join("ahead.coco.json")).unwrap()).unwrap();
    let cat = &coco["categories"][0];
    assert_eq!(cat["keypoints"][m], take.model.markers[m].name.as_str());
    assert_eq!(cat["keypoints"].as_array().unwrap().len(), take.model.markers.len() + take.model.nb());
    assert_eq!(coco["images"].as_array().unwrap().len(), 20);
    let ann =
        coco["annotations"].as_array().unwrap().iter().find(|a| a["image_id"] == 1 && a["category_id"] == 1).unwrap();
    let kp = ann["keypoints"].as_array().unwrap();
    let (u, v, vis) = (kp[3 * m].as_f64().unwrap(), kp[3 * m + 1].as_f64().unwrap(), kp[3 * m + 2].as_f64().unwrap());
    assert!((u - 539.5).abs() < 1e-6 && (v - 359.5).abs() < 1e-6 && vis == 2.0, "({u}, {v}, {vis})");
    let k = &coco["camera"]["K"];
    assert_eq!((k[0][2].as_f64(), k[1][2].as_f64()), (Some(539.5), Some(359.5)));
    let csv = std::fs::read_to_string(out.join("keypoints.csv")).unwrap();
    assert!(csv.starts_with("camera,frame,time_s,kind,name,x_m,y_m,z_m,u_px,v_px,depth_m,in_image\n"));
    let row =
        csv.lines().find(|l| l.starts_with(&format!("ahead,0,0,marker,{},", take.model.markers[m].name))).unwrap();
    let f: Vec<&str> = row.split(',').collect();
    assert!((f[8].parse::<f64>().unwrap() - 539.5).abs() < 1e-6 && (f[9].parse::<f64>().unwrap() - 359.5).abs() < 1e-6);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_rig_files_are_refused_with_the_reason() {
    let cam = |extra: &str| {
        format!("[[cameras]]\nname = \"c\"\nposition = [0, 0, 1]\n{extra}width_px = 10\nheight_px = 10\n")
    };
    let optics = "focal_mm = 33\nsensor_width_mm = 36\n";
    for (text, want) in [
        (cam(&format!("look_at = [1, 0, 1]\n{optics}colour = 1\n")), "unknown field `colour`"),
        (cam(optics), "give look_at = [x, y, z] or rotation"),
        (cam(&format!("look_at = [1, 0, 1]\nrotation = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n{optics}")), "not both"),
        (cam("look_at = [1, 0, 1]\nfocal_mm = 0\nsensor_width_mm = 36\n"), "focal_mm = 0: expected a positive length"),
        (cam("look_at = [1, 0, 1]\nfocal_mm = 33\nsensor_width_mm = -1\n"), "sensor_width_mm = -1"),
        (cam(&format!("rotation = [[1, 0, 0], [0, 1, 0], [0, 1, 1]]\n{optics}")), "not a rotation matrix"),
        (cam(&format!("look_at = [0, 0, 1]\n{optics}")), "look_at is the position itself"),
        (cam(&format!("look_at = [1, 0, 1]\n{optics}")).replace("name = \"c\"\n", ""), "missing field `name`"),
        ("frame = \"lab\"\n".to_string() + &cam(&format!("look_at = [1, 0, 1]\n{optics}")), "unknown variant `lab`"),
        ("cameras = []\n".into(), "no [[cameras]]"),
    ] {
        let e = parse_rig(&text, "bad.toml", &SubjectFrame::world()).expect_err(want).to_string();
        assert!(e.contains(want) && e.contains("bad.toml"), "{e} (wanted {want})");
    }
    // The camera's line is named.
    let two = cam(&format!("look_at = [1, 0, 1]\n{optics}"))
        + "\n"
        + &cam("look_at = [1, 0, 1]\nfocal_mm = -2\nsensor_width_mm = 3\n").replace("\"c\"", "\"d\"");
    let e = parse_rig(&two, "bad.toml", &SubjectFrame::world()).unwrap_err().to_string();
    assert!(e.contains("line 10: camera 'd'"), "{e}");
}

#[test]
fn project_writes_coco_json_csv_cameras_and_metrics_for_a_converted_shared_trial() {
    let root = common::shared("datasets/gait2354_subject01");
    if !root.exists() {
        eprintln!("skipped: {} is absent", root.display());
        return;
    }
    let dir = tmp("gait");
    let d = |f: &str| root.join(f).display().to_string();
    let toml = format!(
        "[[dataset]]\nname = \"g\"\nroot = \"{}\"\ntrials = [\"subject01_walk1.trc\"]\nstatic = \"subject01_static.trc\"\nmodel = \"{}\"\nmarkerset = \"{}\"\nscale_setup = \"{}\"\nik_setup = \"{}\"\n",
        root.display(),
        d("gait2354_simbody.osim"),
        d("gait2354_Scale_MarkerSet.xml"),
        d("subject01_Setup_Scale.xml"),
        d("subject01_Setup_IK.xml")
    );
    let file = convert_archive(&dir, &toml, "g/subject01_walk1.mcap");
    let out = dir.join("gt");
    let o = smocap(&["project", file.to_str().unwrap(), "--out", out.to_str().unwrap(), "--stride", "10"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table = String::from_utf8_lossy(&o.stdout);
    eprintln!("{table}");
    assert!(table.contains("| subject01_walk1 | 16 |"), "{table}");
    for cam in ["frontal", "sagittal"] {
        let coco: Value =
            serde_json::from_slice(&std::fs::read(out.join(format!("{cam}.coco.json"))).unwrap()).unwrap();
        assert_eq!(coco["images"].as_array().unwrap().len(), 16, "151 frames, every 10th");
        assert_eq!(coco["annotations"].as_array().unwrap().len(), 48, "model, observed and body per image");
        let visible = coco["annotations"][0]["num_keypoints"].as_u64().unwrap();
        assert!(visible > 30, "{cam}: {visible} keypoints visible");
        // the body's surface keypoints: COCO-17 and the feet, every one in the image
        let body = &coco["categories"][2];
        assert_eq!(body["name"], "body");
        assert_eq!(body["keypoints"].as_array().unwrap().len(), 23);
        let a = coco["annotations"].as_array().unwrap().iter().find(|a| a["category_id"] == 3).unwrap();
        assert_eq!(a["num_keypoints"].as_u64().unwrap(), 23, "{cam}");
    }
    let metrics: Value = serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
    let mm = metrics["marker_error_mm"].as_f64().unwrap();
    assert!(mm > 1.0 && mm < 40.0, "{mm} mm");
    for c in metrics["cameras"].as_array().unwrap() {
        let px = c["marker_error_px"].as_f64().unwrap();
        assert!(px > 0.1 && px < 20.0, "{px} px");
        let vpx = c["virtual_marker_error_px"].as_f64().unwrap();
        assert!(vpx > 0.0 && vpx < 1.5, "virtual markers {vpx} px");
    }
    let vmm = metrics["virtual_marker_error_mm"].as_f64().unwrap();
    assert!(vmm > 0.0 && vmm < 10.0, "virtual markers {vmm} mm");
    let cams: Value = serde_json::from_slice(&std::fs::read(out.join("cameras.json")).unwrap()).unwrap();
    assert_eq!(cams["cameras"].as_array().unwrap().len(), 2);
    assert!(std::fs::metadata(out.join("keypoints.csv")).unwrap().len() > 1000);
    let _ = std::fs::remove_dir_all(&dir);
}
