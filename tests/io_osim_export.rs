//! OpenSim export: a scaled `.osim` rewritten from the model's own file or generated from any
//! model re-imports with the kinematics of the in-memory scaled model, and matches OpenSim's own
//! ScaleTool output.

mod common;

use common::{random_model, rng, scale_set, shared};
use nalgebra::Vector3;
use rand::RngExt;
use smocap::io::osim::{format_osim, parse_osim, read_marker_set, read_osim, scale_inertia, scale_osim, MassScaling};
use smocap::kinematics::cpu::{forward, Workspace};
use smocap::model::Model;
use std::collections::HashMap;

/// World positions (m) of every body origin, body axis tip (origin + 0.1 m along each axis) and
/// marker, by name, at state `y`.
fn points(model: &Model, y: &[f64]) -> HashMap<String, Vector3<f64>> {
    let mut ws = Workspace::new(model);
    forward(model, y, &mut ws);
    let mut v = HashMap::new();
    for (b, body) in model.bodies.iter().enumerate() {
        v.insert(format!("body:{}", body.name), ws.body_pos[b]);
        for k in 0..3 {
            v.insert(format!("axis{k}:{}", body.name), ws.body_pos[b] + ws.body_rot[b].column(k) * 0.1);
        }
    }
    for (m, mk) in model.markers.iter().enumerate() {
        v.insert(mk.name.clone(), ws.marker(m));
    }
    v
}

/// Random poses (coordinates within their ranges, clipped to ±1) of `a`, each as a state of `a`
/// at scales `s` and the same coordinates (by name) as a state of `b` at unit scale.
fn poses(a: &Model, s: &[Vector3<f64>], b: &Model, n: usize, seed: u64) -> Vec<(Vec<f64>, Vec<f64>)> {
    let mut r = rng(seed);
    (0..n)
        .map(|pose| {
            let mut q: Vec<f64> = a.coordinates.iter().map(|c| c.default).collect();
            if pose > 0 {
                for (i, c) in a.coordinates.iter().enumerate() {
                    let (lo, hi) = (c.range.0.max(-1.0), c.range.1.min(1.0));
                    q[i] = if lo < hi { r.random_range(lo..hi) } else { lo };
                }
                for k in &a.couplings {
                    q[k.dependent] = k.func.eval(q[k.independent]).0;
                }
            }
            let mut ya = a.default_state();
            ya[..a.nq()].copy_from_slice(&q);
            for (bi, f) in s.iter().enumerate() {
                for k in 0..3 {
                    ya[a.scale_index(bi, k)] = f[k];
                }
            }
            let mut yb = b.default_state();
            for (i, c) in b.coordinates.iter().enumerate() {
                yb[i] = q[a.coordinate_index(&c.name).unwrap_or_else(|| panic!("coordinate {} lost", c.name))];
            }
            (ya, yb)
        })
        .collect()
}

/// Largest distance (m) between same-named points of `a` (scaled) and `b` (unit scale) over
/// random poses, over the names `keep` accepts; also the number compared per pose.
fn fk_difference(a: &Model, s: &[Vector3<f64>], b: &Model, keep: impl Fn(&str) -> bool) -> (f64, usize) {
    let (mut worst, mut n) = (0.0f64, 0);
    for (ya, yb) in poses(a, s, b, 8, 11) {
        let (pa, pb) = (points(a, &ya), points(b, &yb));
        n = 0;
        for (name, p) in pb.iter().filter(|(k, _)| keep(k)) {
            let q = pa.get(name).unwrap_or_else(|| panic!("{name} missing from the in-memory model"));
            worst = worst.max((p - q).norm());
            n += 1;
        }
    }
    (worst, n)
}

/// Each body's first attached geometry's `scale_factors` in an `.osim` file.
fn mesh_factors(osim: &str) -> HashMap<String, Vector3<f64>> {
    let text = std::fs::read_to_string(shared(osim)).expect("scaled model");
    let doc = roxmltree::Document::parse(&text).expect("xml");
    let mut out = HashMap::new();
    for b in doc.descendants().filter(|n| n.has_tag_name("Body")) {
        let sf = b
            .children()
            .find(|c| c.has_tag_name("attached_geometry"))
            .and_then(|g| g.descendants().find(|c| c.has_tag_name("scale_factors")))
            .and_then(|c| c.text());
        if let (Some(name), Some(t)) = (b.attribute("name"), sf) {
            let v: Vec<f64> = t.split_whitespace().map(|x| x.parse().expect("number")).collect();
            out.insert(name.to_string(), Vector3::new(v[0], v[1], v[2]));
        }
    }
    out
}

/// Scale factors for every body of `model` (read from `generic`): OpenSim's exact ones where the
/// meshes give them (ratio of the scaled to the generic mesh factors), checked against the printed
/// scale set (6 digits), else the printed ones.
fn opensim_scales(model: &Model, generic: &str, scaled_osim: &str, set: &str) -> Vec<Vector3<f64>> {
    let (before, after) = (mesh_factors(generic), mesh_factors(scaled_osim));
    let exact: HashMap<&String, Vector3<f64>> =
        after.iter().filter_map(|(k, a)| before.get(k).map(|b| (k, a.component_div(b)))).collect();
    let printed: HashMap<String, [f64; 3]> = scale_set(&shared(set)).into_iter().collect();
    model
        .bodies
        .iter()
        .map(|b| {
            let p = Vector3::from(printed[&b.name]);
            match exact.get(&b.name) {
                Some(e) => {
                    assert!((e - p).abs().max() <= 1e-5 * p.abs().max(), "{}: {e} vs {p}", b.name);
                    *e
                }
                None => p,
            }
        })
        .collect()
}

/// Numbers of the scaled elements, keyed by their path of `tag[name]` from `<Model>`
/// (`GeometryPath` names dropped: OpenSim renames them), in document order per key.
fn scaled_values(text: &str) -> HashMap<String, Vec<Vec<f64>>> {
    const TAGS: [&str; 10] = [
        "translation",
        "location",
        "scale_factors",
        "mass",
        "mass_center",
        "inertia",
        "radius",
        "length",
        "scale",
        "dimensions",
    ];
    let doc = roxmltree::Document::parse(text).expect("xml");
    let mut out: HashMap<String, Vec<Vec<f64>>> = HashMap::new();
    for n in doc.descendants().filter(|n| n.is_element() && TAGS.contains(&n.tag_name().name())) {
        let mut key: Vec<String> = n
            .ancestors()
            .filter(|a| a.is_element())
            .take_while(|a| !a.has_tag_name("Model"))
            .map(|a| match a.attribute("name").filter(|_| !a.has_tag_name("GeometryPath")) {
                Some(name) => format!("{}[{name}]", a.tag_name().name()),
                None => a.tag_name().name().to_string(),
            })
            .collect();
        key.reverse();
        let v: Vec<f64> = n.text().unwrap_or("").split_whitespace().filter_map(|x| x.parse().ok()).collect();
        out.entry(key.join("/")).or_default().push(v);
    }
    out
}

#[test]
fn rajagopal_scaled_like_opensim_reimports_with_the_same_kinematics_and_values() {
    let dir = "reference/opensim-4.6/rajagopal2016_walk/";
    let generic_path = shared("datasets/rajagopal2016_walk/Rajagopal2016.osim");
    if !generic_path.exists() || !shared(dir).exists() {
        eprintln!("skipped: the Rajagopal dataset or its OpenSim reference is absent");
        return;
    }
    let (generic, _) = read_osim(&generic_path).expect("generic");
    let set = read_marker_set(&shared("datasets/rajagopal2016_walk/markerset_walk_preScale.xml"), &generic)
        .expect("marker set");
    let generic = generic.with_markers(set).expect("markers");
    let scaled_rel = format!("{dir}subject_scaled_walk_by_opensim.osim");
    let generic_rel = "datasets/rajagopal2016_walk/Rajagopal2016.osim";
    let s = opensim_scales(&generic, generic_rel, &scaled_rel, &format!("{dir}scaleSet_applied_walk.xml"));
    let text = std::fs::read_to_string(&generic_path).expect("text");
    // The reference setup: preserve the mass distribution, subject mass 85.0668 kg.
    let mass = MassScaling { scale_with_volume: false, subject_mass: Some(85.0668) };
    let (out, warnings) = scale_osim(&text, "Rajagopal2016.osim", &generic, &s, mass).expect("scaled");
    assert!(warnings.iter().any(|w| w.contains("tendon_slack_length")), "{warnings:?}");
    let (back, _) = parse_osim(&out, "exported.osim").expect("re-import");
    assert_eq!(back.markers.len(), generic.markers.len());
    let (e, n) = fk_difference(&generic, &s, &back, |_| true);
    println!("rajagopal export vs in-memory scaled model: {e:.3e} m over {n} points");
    assert!(e <= 1e-9, "{e} m");

    // Against OpenSim's own scaled model: every body frame and the markers its MarkerPlacer kept.
    let (theirs, _) = read_osim(&shared(&scaled_rel)).expect("OpenSim's scaled model");
    let set_text = std::fs::read_to_string(shared("datasets/rajagopal2016_walk/markerset_walk_preScale.xml")).unwrap();
    let fixed: Vec<String> = roxmltree::Document::parse(&set_text)
        .unwrap()
        .descendants()
        .filter(|n| n.has_tag_name("Marker"))
        .filter(|n| n.children().any(|c| c.has_tag_name("fixed") && c.text().is_some_and(|t| t.trim() == "true")))
        .filter_map(|n| n.attribute("name").map(str::to_string))
        .collect();
    let keep = |k: &str| k.contains(':') || fixed.iter().any(|f| f == k);
    let (e, n) = fk_difference(&generic, &s, &theirs, keep);
    println!("rajagopal export vs OpenSim's ScaleTool output: {e:.3e} m over {n} points");
    assert!(e <= 1e-6, "{e} m");

    // Value by value: offsets, path points, geometry, wrap objects, functions, inertial properties.
    let (ours, reference) =
        (scaled_values(&out), scaled_values(&std::fs::read_to_string(shared(&scaled_rel)).unwrap()));
    let (mut compared, mut worst) = (0, 0.0f64);
    for (key, theirs) in &reference {
        let marker = key.strip_prefix("MarkerSet[markerset]/objects/Marker[").and_then(|k| k.split(']').next());
        if marker.is_some_and(|m| !fixed.iter().any(|f| f == m)) {
            continue;
        }
        let mine = ours.get(key).unwrap_or_else(|| panic!("{key} missing from the export"));
        assert_eq!(mine.len(), theirs.len(), "{key}");
        for (a, b) in mine.iter().zip(theirs) {
            assert_eq!(a.len(), b.len(), "{key}");
            for (x, y) in a.iter().zip(b) {
                let rel = (x - y).abs() / (1e-3 + y.abs());
                assert!(rel <= 1e-9, "{key}: ours {a:?}, OpenSim {b:?}");
                worst = worst.max(rel);
                compared += 1;
            }
        }
    }
    println!("rajagopal export vs OpenSim's file: {compared} numbers, worst relative difference {worst:.2e}");
    assert!(compared > 1500, "{compared} numbers compared");
}

#[test]
fn gait2354_with_a_separate_marker_set_exports_its_markers_and_kinematics() {
    let d = "datasets/gait2354_subject01/";
    let model_path = shared(&format!("{d}gait2354_simbody.osim"));
    if !model_path.exists() {
        eprintln!("skipped: {} is absent", model_path.display());
        return;
    }
    let (model, _) = read_osim(&model_path).expect("model");
    let file_markers: Vec<String> = model.markers.iter().map(|m| m.name.clone()).collect();
    let set = read_marker_set(&shared(&format!("{d}gait2354_Scale_MarkerSet.xml")), &model).expect("set");
    let model = model.with_markers(set).expect("markers");
    let mut r = rng(3);
    let s: Vec<Vector3<f64>> = (0..model.nb()).map(|_| Vector3::from_fn(|_, _| r.random_range(0.8..1.25))).collect();
    let text = std::fs::read_to_string(&model_path).expect("text");
    let (out, warnings) =
        scale_osim(&text, "gait2354_simbody.osim", &model, &s, MassScaling::default()).expect("scaled");
    let (back, _) = parse_osim(&out, "exported.osim").expect("re-import");
    let names = |m: &Model| m.markers.iter().map(|x| x.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(&back), names(&model), "the written MarkerSet is the attached marker set");
    let dropped = file_markers.iter().filter(|n| model.marker_index(n).is_none()).count();
    assert_eq!(dropped > 0, warnings.iter().any(|w| w.contains("left out")), "{warnings:?}");
    let (e, n) = fk_difference(&model, &s, &back, |_| true);
    println!("gait2354 export vs in-memory scaled model: {e:.3e} m over {n} points");
    assert!(e <= 1e-9, "{e} m");
    // Masses are kept by default; a uniformly scaled body's inertia scales by s².
    let mass_of = |t: &str, body: &str| -> Vec<f64> {
        let doc = roxmltree::Document::parse(t).unwrap();
        let b = doc.descendants().find(|n| n.has_tag_name("Body") && n.attribute("name") == Some(body)).unwrap();
        ["mass", "inertia"]
            .iter()
            .flat_map(|tag| {
                b.children().find(|c| c.has_tag_name(*tag)).and_then(|c| c.text()).unwrap().split_whitespace()
            })
            .map(|x| x.parse().unwrap())
            .collect()
    };
    assert_eq!(mass_of(&out, "femur_r")[0], mass_of(&text, "femur_r")[0]);

    // Against OpenSim's ScaleTool output (its MarkerPlacer moved the markers: body frames only).
    let rd = "reference/opensim-4.6/gait2354_subject01/";
    if shared(rd).exists() {
        let scaled_rel = format!("{rd}subject01_scaled_by_opensim.osim");
        let generic_rel = format!("{d}gait2354_simbody.osim");
        let s = opensim_scales(&model, &generic_rel, &scaled_rel, &format!("{rd}subject01_scaleSet_applied.xml"));
        let (out, _) = scale_osim(&text, "gait2354_simbody.osim", &model, &s, MassScaling::default()).expect("scaled");
        let (back, _) = parse_osim(&out, "exported.osim").expect("re-import");
        let (theirs, _) = read_osim(&shared(&scaled_rel)).expect("OpenSim's scaled model");
        let (e, n) = fk_difference(&back, &vec![Vector3::new(1.0, 1.0, 1.0); back.nb()], &theirs, |k| k.contains(':'));
        println!("gait2354 export vs OpenSim's ScaleTool output: {e:.3e} m over {n} body points");
        assert!(e <= 1e-6, "{e} m");
    }
}

#[test]
fn models_generated_as_osim_reimport_with_the_same_kinematics() {
    let mut models = vec![smocap::pipeline::Context::shipped().expect("shipped").model];
    let rajagopal = shared("datasets/rajagopal2016_walk/Rajagopal2016.osim");
    if rajagopal.exists() {
        // An OpenSim model through the generic writer: SimmSplines, couplings, Pin/Universal joints.
        models.push(read_osim(&rajagopal).expect("rajagopal").0);
    }
    for (i, model) in models.iter().enumerate() {
        let mut r = rng(21 + i as u64);
        let s: Vec<Vector3<f64>> =
            (0..model.nb()).map(|_| Vector3::from_fn(|_, _| r.random_range(0.8..1.25))).collect();
        let (text, warnings) = format_osim(model, &s).expect("export");
        assert!(warnings.is_empty(), "{warnings:?}");
        let (back, _) = parse_osim(&text, "generated.osim").expect("re-import");
        assert_eq!((back.nb(), back.nq(), back.markers.len()), (model.nb(), model.nq(), model.markers.len()));
        assert_eq!(back.couplings.len(), model.couplings.len());
        for c in &model.coordinates {
            let b = &back.coordinates[back.coordinate_index(&c.name).expect("coordinate")];
            assert_eq!((b.default, b.locked, b.clamped), (c.default, c.locked, c.clamped), "{}", c.name);
            if c.range.0.is_finite() && c.range.1.is_finite() {
                assert_eq!(b.range, c.range, "{}", c.name);
            }
        }
        let (e, n) = fk_difference(model, &s, &back, |_| true);
        println!("{} generated: {e:.3e} m over {n} points", model.name);
        assert!(e <= 1e-9, "{}: {e} m", model.name);
    }
}

#[test]
fn random_models_with_every_function_kind_round_trip_or_name_the_joint() {
    let (mut exported, mut refused) = (0, 0);
    for seed in 0..60 {
        let model = random_model(seed, 3);
        let mut r = rng(seed + 100);
        let s: Vec<Vector3<f64>> = (0..model.nb()).map(|_| Vector3::from_fn(|_, _| r.random_range(0.7..1.3))).collect();
        match format_osim(&model, &s) {
            Ok((text, _)) => {
                let (back, _) = parse_osim(&text, "random.osim").expect("re-import");
                let (e, _) = fk_difference(&model, &s, &back, |_| true);
                assert!(e <= 1e-9, "seed {seed}: {e} m");
                exported += 1;
            }
            Err(e) => {
                let msg = e.to_string();
                assert!(msg.starts_with("joint 'j"), "seed {seed}: {msg}");
                assert!(msg.contains("after a rotation") || msg.contains("collinear"), "{msg}");
                refused += 1;
            }
        }
    }
    println!("{exported} random models exported, {refused} refused");
    assert!(exported >= 10 && refused >= 1, "{exported} exported, {refused} refused");
}

#[test]
fn unequal_scale_factors_scale_inertia_as_a_cylinder() {
    // A cylinder along y (radius r, length l, mass m) scaled by (a, b, a) is the cylinder of radius
    // r·a, length l·b: OpenSim's approximation is exact for it.
    let (m, rad, len) = (2.0, 0.05, 0.4);
    let i = |r: f64, l: f64| {
        [m * (l * l / 12.0 + r * r / 4.0), 0.5 * m * r * r, m * (l * l / 12.0 + r * r / 4.0), 0.0, 0.0, 0.0]
    };
    let got = scale_inertia(&i(rad, len), m, m, &Vector3::new(1.2, 0.9, 1.2), false);
    let want = i(rad * 1.2, len * 0.9);
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() <= 1e-15, "{got:?} vs {want:?}");
    }
    // Equal factors: s² (and the volume ratio when the mass scales with it).
    let got = scale_inertia(&i(rad, len), m, m * 8.0, &Vector3::new(2.0, 2.0, 2.0), true);
    assert!((got[0] - i(rad, len)[0] * 32.0).abs() <= 1e-12);
}

#[test]
fn hips_moved_by_calibration_are_written_where_the_subjects_model_has_them() {
    let path = shared("datasets/gait2354_subject01/gait2354_simbody.osim");
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let (generic, _) = read_osim(&path).expect("model");
    // The functional hips move the hip joints in the pelvis (`functional_hips = "apply"`).
    let moves: Vec<smocap::solve::prior::JointMove> = ["femur_r", "femur_l"]
        .iter()
        .map(|b| {
            let joint = &generic.bodies[generic.body_index(b).expect("femur")].joint;
            let t = joint.parent_offset.translation.vector + Vector3::new(0.012, -0.005, 0.008);
            smocap::solve::prior::JointMove {
                body: b.to_string(),
                joint: joint.name.clone(),
                location_m: t.into(),
                moved_mm: [12.0, -5.0, 8.0],
                residual_mm: None,
            }
        })
        .collect();
    let moved = smocap::pipeline::context::with_joint_moves(&generic, &moves);
    let mut r = rng(5);
    let s: Vec<Vector3<f64>> = (0..moved.nb()).map(|_| Vector3::from_fn(|_, _| r.random_range(0.8..1.25))).collect();
    let text = std::fs::read_to_string(&path).expect("text");
    let (out, _) = scale_osim(&text, "gait2354_simbody.osim", &moved, &s, MassScaling::default()).expect("scaled");
    let (back, _) = parse_osim(&out, "exported.osim").expect("re-import");
    let (e, n) = fk_difference(&moved, &s, &back, |_| true);
    println!("gait2354 with moved hips, export vs in-memory: {e:.3e} m over {n} points");
    assert!(e <= 1e-9, "{e} m");
    // The generic model's own joints are written as before.
    let (plain, _) = scale_osim(&text, "gait2354_simbody.osim", &generic, &s, MassScaling::default()).expect("scaled");
    let (back, _) = parse_osim(&plain, "exported.osim").expect("re-import");
    assert!(fk_difference(&generic, &s, &back, |_| true).0 <= 1e-9);
    assert_ne!(plain, out, "the moved hips change the file");
}
