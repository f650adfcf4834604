//! The body mesh on solved motion (issue 33): its height against the subject's stature, the joint
//! centres inside the skin, edge lengths and enclosed volume against the rest pose, on a synthetic
//! trial of the shipped model and on the shared Rajagopal walking trial (OpenSim's own inverse
//! kinematics of it, at OpenSim's scales). The measured numbers are printed (`--nocapture`).

mod common;

use common::{converted_synthetic, scale_set, shared};
use nalgebra::UnitQuaternion;
use smocap::body::bind::targets;
use smocap::body::metrics::{edge_ratios, edges, volume, winding_number};
use smocap::body::{BodyAsset, Dressed, Phenotype, PoseWorkspace};
use smocap::model::Model;

struct Measured {
    /// Height at the bind pose and the subject's scales minus the target stature (m).
    stature_error: f64,
    inside: (usize, usize),
    edge_in_range: f64,
    edge_min: f64,
    edge_max: f64,
    volume_min: f64,
    volume_max: f64,
}

fn measure(
    name: &str,
    model: &Model,
    world_from_model: &UnitQuaternion<f64>,
    scales: &[f64],
    stature: Option<f64>,
    frames: &[Vec<f64>],
) -> Measured {
    let asset = BodyAsset::shipped().unwrap();
    let t = std::time::Instant::now();
    let body = Dressed::new(model, world_from_model, &asset, scales, stature, Phenotype::default()).unwrap();
    let dress_s = t.elapsed().as_secs_f64();
    measure_body(name, model, world_from_model, &body, dress_s, scales, frames)
}

/// [`measure`] on a given body.
fn measure_body(
    name: &str,
    model: &Model,
    world_from_model: &UnitQuaternion<f64>,
    body: &Dressed,
    dress_s: f64,
    scales: &[f64],
    frames: &[Vec<f64>],
) -> Measured {
    let asset = BodyAsset::shipped().unwrap();
    let mut ws = PoseWorkspace::new(model, body);
    body.pose(model, &body.bind_state(model, scales), &mut ws);
    let rest = ws.vertices.clone();
    let height = body.height(&rest);
    let rest_volume = volume(&rest, &body.triangles);
    let e = edges(&body.triangles);
    let joints: Vec<usize> = targets(model, &body.binding.map, &asset).iter().map(|t| t.0).collect();
    let r0 = world_from_model.to_rotation_matrix().into_inner();
    let (mut inside, mut total, mut in_range, mut n_edges) = (0, 0, 0usize, 0usize);
    let (mut emin, mut emax, mut vmin, mut vmax) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    let mut ratios = Vec::new();
    let mut outside = std::collections::BTreeMap::<String, usize>::new();
    let mut bad_edges = std::collections::BTreeMap::<String, usize>::new();
    for q in frames {
        let mut y = q.clone();
        y.extend_from_slice(scales);
        body.pose(model, &y, &mut ws);
        for &b in &joints {
            let p = r0 * ws.kin.body_pos[b];
            total += 1;
            if winding_number(&ws.vertices, &body.triangles, [p.x, p.y, p.z]) > 0.5 {
                inside += 1;
            } else {
                *outside.entry(model.bodies[b].name.clone()).or_default() += 1;
            }
        }
        edge_ratios(&rest, &ws.vertices, &e, &mut ratios);
        for (k, &r) in ratios.iter().enumerate() {
            emin = emin.min(r);
            emax = emax.max(r);
            in_range += (0.5..=2.0).contains(&r) as usize;
            if !(0.5..=2.0).contains(&r) {
                let v = e[k].0 as usize;
                let sk = asset.skin[v];
                let names: Vec<&str> = sk
                    .segments
                    .iter()
                    .zip(&sk.weights)
                    .filter(|x| *x.1 > 0.0)
                    .map(|x| asset.segments[*x.0 as usize].as_str())
                    .collect();
                *bad_edges.entry(names.join("+")).or_default() += 1;
            }
        }
        n_edges += ratios.len();
        let v = volume(&ws.vertices, &body.triangles) / rest_volume;
        vmin = vmin.min(v);
        vmax = vmax.max(v);
    }
    // posing alone, every frame (this build's optimisation level; not asserted)
    let t = std::time::Instant::now();
    let reps = (2000 / frames.len().max(1)).max(1);
    let mut y = vec![0.0; model.ny()];
    for _ in 0..reps {
        for q in frames {
            y[..q.len()].copy_from_slice(q);
            y[q.len()..].copy_from_slice(scales);
            body.pose(model, &y, &mut ws);
        }
    }
    let fps = (reps * frames.len()) as f64 / t.elapsed().as_secs_f64();
    eprintln!("{name}: edges out of range by segments: {bad_edges:?}");
    let target = body.target_stature;
    let m = Measured {
        stature_error: height - target,
        inside: (inside, total),
        edge_in_range: in_range as f64 / n_edges as f64,
        edge_min: emin,
        edge_max: emax,
        volume_min: vmin,
        volume_max: vmax,
    };
    eprintln!(
        "{name}: {} frames; dressed in {dress_s:.3} s (height {:.3}); target stature {target:.4} m, body {height:.4} m \
         (error {:+.1} mm); joint centres inside {inside}/{total} ({:.3} %), outside by body {outside:?}; \
         edges in 0.5–2× rest {:.4} % (ratios {emin:.3}..{emax:.3}); volume / rest {vmin:.4}..{vmax:.4}; \
         posing {fps:.0} frames/s (one core)",
        frames.len(),
        body.phenotype.height,
        1e3 * m.stature_error,
        100.0 * inside as f64 / total as f64,
        100.0 * m.edge_in_range,
    );
    m
}

#[test]
fn body_follows_a_synthetic_trial_of_the_shipped_model() {
    let dir = std::env::temp_dir().join(format!("smocap-body-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mcap = converted_synthetic(&dir, 60);
    let rec = smocap::archive::export::read_trial_record(&mcap).unwrap();
    let take = smocap::render::Take::from_record(&rec, &mcap).unwrap();
    let m = measure("synthetic", &take.model, &take.world_from_model, &take.scales, None, &take.q);
    // the converted file carries the calibrated stature; the body is shaped to it
    let stature = rec.subject_stature_m.expect("smocap.run carries subject_stature_m");
    let sub = smocap::body::SubjectBody { stature_m: Some(stature), info: rec.subject_info };
    let asset = BodyAsset::shipped().unwrap();
    let (body, line) = take.dress(&asset, &sub, &smocap::body::FitSettings::default()).unwrap();
    eprintln!("synthetic: {line}");
    assert_eq!(body.target_stature, stature);
    assert!((body.bind_pose_height(&take.model, &take.scales) - stature).abs() < 0.01, "{line}");
    // `export --mesh`: posed OBJ files, closed, as many vertices as the asset
    let out = dir.join("mesh");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"))
        .args(["export", mcap.to_str().unwrap(), "--mesh", out.to_str().unwrap(), "--frames", "0,50"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [0, 50] {
        let text = std::fs::read_to_string(out.join(format!("walk01_{f}.obj"))).unwrap();
        assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 13_380);
        assert_eq!(text.lines().filter(|l| l.starts_with("f ")).count(), 26_756);
    }
    assert!(m.stature_error.abs() < 0.01, "{}", m.stature_error);
    assert!(m.inside.0 as f64 >= 0.999 * m.inside.1 as f64, "{:?}", m.inside);
    assert!(m.edge_in_range >= 0.999, "{}", m.edge_in_range);
    assert!(m.volume_min > 0.9 && m.volume_max < 1.1, "{} {}", m.volume_min, m.volume_max);
    let _ = (m.edge_min, m.edge_max);
}

#[test]
fn body_follows_the_rajagopal_walk() {
    let model_path = shared("datasets/rajagopal2016_walk/Rajagopal2016.osim");
    let mot = shared("reference/opensim-4.6/rajagopal2016_walk/motion_capture_walk_ik.mot");
    let scale_path = shared("reference/opensim-4.6/rajagopal2016_walk/scaleSet_applied_walk.xml");
    if !model_path.exists() || !mot.exists() || !scale_path.exists() {
        eprintln!("skipped: the shared Rajagopal files are absent");
        return;
    }
    let text = std::fs::read_to_string(&model_path).unwrap();
    let (model, _) = smocap::io::osim::parse_osim(&text, "Rajagopal2016.osim").unwrap();
    let mut scales = vec![1.0; 3 * model.nb()];
    for (seg, s) in scale_set(&scale_path) {
        if let Some(b) = model.body_index(&seg) {
            scales[3 * b..3 * b + 3].copy_from_slice(&s);
        }
    }
    let table = smocap::io::sto::read_sto(&mot).unwrap();
    let deg = table.in_degrees().unwrap_or(true);
    let cols: Vec<Option<usize>> = model.coordinates.iter().map(|c| table.column(&c.name)).collect();
    let default = model.default_state();
    let frames: Vec<Vec<f64>> = table
        .rows
        .iter()
        .map(|row| {
            model
                .coordinates
                .iter()
                .zip(&cols)
                .enumerate()
                .map(|(i, (c, col))| match col {
                    Some(k) if deg && c.kind != smocap::model::CoordinateKind::Translational => row[*k].to_radians(),
                    Some(k) => row[*k],
                    None => default[i],
                })
                .collect()
        })
        .collect();
    // OpenSim models are Y up
    let y_up = smocap::model::math::quaternion(&nalgebra::Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
    let m = measure("rajagopal walk", &model, &y_up, &scales, None, &frames);
    assert!(m.stature_error.abs() < 0.01, "{}", m.stature_error);
    assert!(m.inside.0 as f64 >= 0.999 * m.inside.1 as f64, "{:?}", m.inside);
    assert!(m.edge_in_range >= 0.999, "{}", m.edge_in_range);
    assert!(m.volume_min > 0.9 && m.volume_max < 1.1, "{} {}", m.volume_min, m.volume_max);
}

/// `export --skin-report` on `mcap`: prints each marker's signed distance to the skin and the
/// pooled |distance − 7 mm| of landmarks and others; returns the report.
fn skin_report(name: &str, mcap: &std::path::Path, out: &std::path::Path) -> serde_json::Value {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"))
        .args(["export", mcap.to_str().unwrap(), "--skin-report", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap();
    let frames = r["frames"].as_u64().unwrap();
    for m in r["markers"].as_array().unwrap() {
        eprintln!(
            "{name}: {:<20} {:<10} {:<9} signed median {:>6} mm, |d − 7 mm| median {:>5} p90 {:>5} mm",
            m["marker"].as_str().unwrap(),
            m["body"].as_str().unwrap(),
            if m["computed"] == true {
                "computed"
            } else if m["landmark"] == true {
                "landmark"
            } else {
                "other"
            },
            m["median_signed_mm"],
            m["median_off_skin_mm"],
            m["p90_off_skin_mm"]
        );
        // sanity: every marker measured at every frame, a finite distance within half a metre
        assert_eq!(m["frames"].as_u64().unwrap(), frames, "{m}");
        assert!(m["median_signed_mm"].as_f64().is_some_and(|d| d.abs() < 500.0), "{m}");
    }
    for g in ["landmarks", "others", "computed_points"] {
        eprintln!("{name}: {g}: {}", r[g]);
    }
    assert!(r["landmarks"]["markers"].as_u64().unwrap() > 0);
    r
}

#[test]
fn markers_against_the_skin() {
    let dir = std::env::temp_dir().join(format!("smocap-body-skin-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mcap = converted_synthetic(&dir, 60);
    skin_report("synthetic", &mcap, &dir.join("skin-synthetic.json"));
    if !shared("datasets/rajagopal2016_walk/Rajagopal2016.osim").exists() {
        eprintln!("skipped Rajagopal: the shared files are absent");
        return;
    }
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["convert", "datasets.toml", "--dataset", "rajagopal2016_walk", "--quiet", "--out"])
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mcap = dir.join("out/rajagopal2016_walk/motion_capture_walk.mcap");
    skin_report("rajagopal walk", &mcap, &dir.join("skin-rajagopal.json"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The shared trials, converted: the gait2354 and Rajagopal datasets of `datasets.toml`, one
/// OpenCap trial and the Vicon Plug-in Gait trial (`None` where `../shared` is absent).
fn converted_shared(dir: &std::path::Path) -> Option<Vec<std::path::PathBuf>> {
    let s = shared("datasets");
    if !s.join("rajagopal2016_walk").exists() {
        return None;
    }
    let extra = dir.join("more.toml");
    let text = format!(
        "[[dataset]]\nname = \"opencap\"\nroot = \"{o}\"\ntrials = [\"MarkerData/walking2.trc\"]\nmodel = \"{o}/unscaled_generic.osim\"\n\n\
         [[dataset]]\nname = \"vicon\"\nroot = \"{v}\"\ntrials = [\"PiG_Motion3_FF.c3d\"]\nstatic = \"PiG_Calibration3_FF.c3d\"\n",
        o = s.join("opencap_addbiomechanics").display(),
        v = s.join("vicon_plugingait_flatfoot").display()
    );
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(&extra, text).unwrap();
    let out = dir.join("out");
    let runs = [
        ("datasets.toml", Some("gait2354_subject01")),
        ("datasets.toml", Some("rajagopal2016_walk")),
        (extra.to_str().unwrap(), None),
    ];
    for (file, set) in runs {
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"));
        cmd.current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["convert", file, "--quiet", "--allow-empty", "--out"])
            .arg(&out);
        if let Some(d) = set {
            cmd.args(["--dataset", d]);
        }
        let o = cmd.output().unwrap();
        assert!(o.status.success() || o.status.code() == Some(3), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let mut files: Vec<std::path::PathBuf> = [
        "gait2354_subject01/subject01_walk1",
        "rajagopal2016_walk/motion_capture_walk",
        "opencap/MarkerData/walking2",
        "vicon/PiG_Motion3_FF",
    ]
    .iter()
    .map(|t| out.join(format!("{t}.mcap")))
    .collect();
    files.retain(|f| f.exists());
    Some(files)
}

#[test]
fn shaped_bodies_are_the_subjects_stature_with_the_markers_on_the_skin() {
    let dir = std::env::temp_dir().join(format!("smocap-body-shared-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut files = vec![converted_synthetic(&dir.join("synthetic"), 60)];
    match converted_shared(&dir) {
        Some(f) => {
            assert_eq!(f.len(), 4, "{f:?}");
            files.extend(f);
        }
        None => eprintln!("skipped the shared trials: ../shared is absent"),
    }
    let asset = BodyAsset::shipped().unwrap();
    for mcap in &files {
        let rec = smocap::archive::export::read_trial_record(mcap).unwrap();
        let take = smocap::render::Take::from_record(&rec, mcap).unwrap();
        let sub = smocap::body::SubjectBody { stature_m: rec.subject_stature_m, info: rec.subject_info };
        let t = std::time::Instant::now();
        let (body, line) = take.dress(&asset, &sub, &smocap::body::FitSettings::default()).unwrap();
        let name = take.name.clone();
        eprintln!("{name}: {line}");
        let m = measure_body(
            &name,
            &take.model,
            &take.world_from_model,
            &body,
            t.elapsed().as_secs_f64(),
            &take.scales,
            &take.q,
        );
        assert!(m.stature_error.abs() < 0.01, "{name}: {}", m.stature_error);
        assert!(m.inside.0 as f64 >= 0.999 * m.inside.1 as f64, "{name}: {:?}", m.inside);
        // the edges out of range are linear blend skinning's, where bodies turn far from the
        // A-pose the mesh is bound in (groin, armpits, knees; printed above): the OpenCap walk
        // measures 99.91 %, Rajagopal's 99.93 %, the others 99.96 % and more
        assert!(m.edge_in_range >= 0.999, "{name}: {}", m.edge_in_range);
        assert!(m.volume_min > 0.95 && m.volume_max < 1.05, "{name}: {} {}", m.volume_min, m.volume_max);
        let r = skin_report(&name, mcap, &dir.join(format!("{name}.skin.json")));
        let (med, p90) = (
            r["landmarks"]["median_off_skin_mm"].as_f64().unwrap(),
            r["landmarks"]["p90_off_skin_mm"].as_f64().unwrap(),
        );
        assert!(med <= 8.0 && p90 <= 20.0, "{name}: landmarks off the skin median {med} mm, p90 {p90} mm");
        // the thesis' metrics (its figures: 13.8 mm, 2.32 px at 1080 × 720, a running trial)
        let out = dir.join(format!("{name}.project"));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"))
            .args(["project", mcap.to_str().unwrap(), "--out", out.to_str().unwrap(), "--stride", "5"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        eprintln!("{}", String::from_utf8_lossy(&o.stdout));
        let metrics: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
        let mm = metrics["virtual_marker_error_mm"].as_f64().unwrap();
        assert!(mm <= 10.0, "{name}: virtual markers {mm} mm from the model's");
        for c in metrics["cameras"].as_array().unwrap() {
            let px = c["virtual_marker_error_px"].as_f64().unwrap();
            assert!(px <= 1.5, "{name}: virtual markers {px} px from the model's ({})", c["camera"]);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn convert_with_body_measures_every_trial_beside_its_file_and_resumes() {
    let dir = std::env::temp_dir().join(format!("smocap-body-convert-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let run = |extra: &[&str]| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["convert", "datasets.toml", "--dataset", "synthetic", "--quiet", "--body", "--out"])
            .arg(dir.join("out"))
            .arg("--report-json")
            .arg(dir.join("summary.json"))
            .args(extra)
            .output()
            .unwrap();
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
        (o, summary)
    };
    let (o, first) = run(&[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    for t in first["trials"].as_array().unwrap() {
        let b = &t["body"];
        let output = std::path::PathBuf::from(t["output"].as_str().unwrap());
        assert!(output.with_extension("body.json").exists(), "{output:?}");
        // the second subject's left leg is 9 cm longer than its right (`smocap synth` draws
        // each side's scales on their own): its height is read down to the right sole, as its
        // stature is
        assert_eq!(b["status"], "ok", "{b}");
        assert!(b["height_minus_stature_mm"].as_f64().unwrap().abs() <= 10.0, "{b}");
        assert!(b["landmark_median_off_skin_mm"].as_f64().unwrap() <= 8.0, "{b}");
        assert!(b["landmark_p90_off_skin_mm"].as_f64().unwrap() <= 20.0, "{b}");
        assert!(b["virtual_marker_error_mm"].as_f64().unwrap() <= 10.0, "{b}");
    }
    // resumed: the reports are read back, the figures the same
    let (_, again) = run(&["--resume"]);
    for (a, b) in first["trials"].as_array().unwrap().iter().zip(again["trials"].as_array().unwrap()) {
        assert_eq!(a["body"]["height_minus_stature_mm"], b["body"]["height_minus_stature_mm"]);
        assert_eq!(a["body"]["virtual_marker_error_mm"], b["body"]["virtual_marker_error_mm"]);
        assert_eq!(b["body"]["status"], "skipped");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Helper joints ([`smocap::body::helpers`]): with the right hip flexed 90°, the skin blended
/// about half and half between the pelvis and the thigh (≥ 80 % of its weight on the two, the
/// thigh's share 35–65 %) stays near its distance from the hip centre (measured 0.95 of it),
/// where linear blending of the bodies alone pulls it toward the chord (0.81; cos 45° ≈ 0.71 for
/// an even split of the two alone); at the bind pose the helpers change nothing.
#[test]
fn helper_joints_keep_a_flexed_hip_round_where_linear_blending_collapses_it() {
    let model = smocap::pipeline::Context::shipped().unwrap().model;
    let asset = BodyAsset::shipped().unwrap();
    let ones = vec![1.0; 3 * model.nb()];
    let body = Dressed::new(&model, &UnitQuaternion::identity(), &asset, &ones, None, Phenotype::default()).unwrap();
    let (pelvis, femur) = (model.body_index("pelvis").unwrap(), model.body_index("femur_r").unwrap());
    let mut ws = PoseWorkspace::new(&model, &body);
    let bind = body.binding.y.clone();
    body.pose(&model, &bind, &mut ws);
    let rest = ws.vertices.clone();
    // at the bind pose every joint (helpers too) is where its body is: plain blending
    let plain = |y: &[f64], ws: &mut PoseWorkspace| -> Vec<[f64; 3]> {
        smocap::kinematics::cpu::forward(&model, y, &mut ws.kin);
        body.binding
            .influences
            .iter()
            .map(|inf| {
                let mut v = nalgebra::Vector3::zeros();
                for x in inf.iter().filter(|x| x.weight > 0.0) {
                    let b = x.body as usize;
                    let i = model.scale_index(b, 0);
                    let u = nalgebra::Vector3::new(
                        x.local[0] as f64 * y[i],
                        x.local[1] as f64 * y[i + 1],
                        x.local[2] as f64 * y[i + 2],
                    );
                    v += (ws.kin.body_rot[b] * u + ws.kin.body_pos[b]) * x.weight as f64;
                }
                [v.x, v.y, v.z]
            })
            .collect()
    };
    let at_bind = plain(&bind, &mut ws);
    let worst = rest
        .iter()
        .zip(&at_bind)
        .map(|(a, b)| (0..3).map(|k| (a[k] as f64 - b[k]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "at the bind pose the helpers moved a vertex by {worst} m");
    let mut flexed = bind.clone();
    flexed[model.coordinate_index("hip_flexion_r").unwrap()] += 90f64.to_radians();
    body.pose(&model, &flexed, &mut ws);
    let posed = ws.vertices.clone();
    let lbs = plain(&flexed, &mut ws);
    smocap::kinematics::cpu::forward(&model, &bind, &mut ws.kin);
    let hip0 = ws.kin.body_pos[femur];
    smocap::kinematics::cpu::forward(&model, &flexed, &mut ws.kin);
    let hip1 = ws.kin.body_pos[femur];
    let (mut with, mut without, mut n) = (0.0, 0.0, 0usize);
    for (v, inf) in body.binding.influences.iter().enumerate() {
        let w = |b: usize| inf.iter().filter(|x| x.body as usize == b).map(|x| x.weight as f64).sum::<f64>();
        let (wp, wf) = (w(pelvis), w(femur));
        if wp + wf < 0.8 || !(0.35..=0.65).contains(&(wf / (wp + wf))) {
            continue;
        }
        let r0 = (nalgebra::Vector3::from(rest[v].map(|x| x as f64)) - hip0).norm();
        with += (nalgebra::Vector3::from(posed[v].map(|x| x as f64)) - hip1).norm() / r0;
        without += (nalgebra::Vector3::from(lbs[v]) - hip1).norm() / r0;
        n += 1;
    }
    let (with, without) = (with / n as f64, without / n as f64);
    eprintln!("{n} vertices half pelvis, half thigh: distance to the hip over rest {with:.3} with helpers, {without:.3} blending the two bodies");
    assert!(n > 20, "{n}");
    assert!(with > 0.93 && without < 0.85, "with helpers {with:.3}, without {without:.3}");
}
