//! OpenSim import: forward kinematics against OpenSim's own marker locations, scale semantics
//! against OpenSim's ScaleTool output, and error handling.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use smocap::io::osim::{parse_marker_set, parse_osim, read_osim, simm_spline};
use smocap::io::sto::read_sto;
use smocap::kinematics::cpu::{forward, Workspace};
use smocap::model::{CoordinateKind, Function, Model};

mod common;
use common::{scale_set, shared};

/// Max marker error (m) of our FK at the IK coordinates against OpenSim's marker locations.
fn fk_oracle(model_rel: &str, mot_rel: &str, sto_rel: &str) -> f64 {
    let (model, warnings) = read_osim(&shared(model_rel)).expect("model");
    assert!(warnings.iter().any(|w| w.contains("ignored")), "{warnings:?}");
    let mot = read_sto(&shared(mot_rel)).expect("mot");
    let sto = read_sto(&shared(sto_rel)).expect("sto");
    assert_eq!(mot.rows.len(), sto.rows.len());
    let deg = mot.in_degrees().unwrap_or(false);
    let dependent: Vec<usize> = model.couplings.iter().map(|c| c.dependent).collect();
    let cols: Vec<Option<usize>> = model.coordinates.iter().map(|c| mot.column(&c.name)).collect();
    let mut markers = Vec::new();
    for (m, mk) in model.markers.iter().enumerate() {
        let c = ["_tx", "_ty", "_tz"].map(|s| sto.column(&format!("{}{s}", mk.name)));
        if let [Some(x), Some(y), Some(z)] = c {
            markers.push((m, [x, y, z]));
        }
    }
    assert_eq!(3 * markers.len() + 1, sto.columns.len(), "every oracle marker is in the model");
    let mut ws = Workspace::new(&model);
    let (mut worst, mut worst_coupled) = (0.0f64, 0.0f64);
    for (row, orow) in mot.rows.iter().zip(&sto.rows) {
        let mut y = model.default_state();
        for (i, c) in model.coordinates.iter().enumerate() {
            if c.locked || dependent.contains(&i) {
                continue;
            }
            let col = cols[i].unwrap_or_else(|| panic!("coordinate {} not in the .mot", c.name));
            let unit = if deg && c.kind == CoordinateKind::Rotational { std::f64::consts::PI / 180.0 } else { 1.0 };
            y[i] = row[col] * unit;
        }
        for k in &model.couplings {
            y[k.dependent] = k.func.eval(y[k.independent]).0;
            // OpenSim writes "coupled" coordinates (no pure axis) without degree conversion.
            if let Some(col) = cols[k.dependent] {
                worst_coupled = worst_coupled.max((row[col] - y[k.dependent]).abs());
            }
        }
        forward(&model, &y, &mut ws);
        for &(m, c) in &markers {
            let p = ws.marker(m);
            for a in 0..3 {
                worst = worst.max((p[a] - orow[c[a]]).abs());
            }
        }
    }
    assert!(worst_coupled < 1e-6, "coupled coordinates differ from the .mot by {worst_coupled}");
    worst
}

#[test]
fn gait2354_marker_positions_match_opensim_fk() {
    let e = fk_oracle(
        "reference/opensim-4.6/gait2354_subject01/subject01_scaled_by_opensim.osim",
        "reference/opensim-4.6/gait2354_subject01/subject01_walk1_ik.mot",
        "reference/opensim-4.6/gait2354_subject01/subject01_walk1_ik_model_marker_locations.sto",
    );
    println!("gait2354 max marker error: {:.3e} mm", e * 1e3);
    assert!(e <= 1e-5, "max marker error {} mm", e * 1e3);
}

#[test]
fn rajagopal_marker_positions_match_opensim_fk() {
    let e = fk_oracle(
        "reference/opensim-4.6/rajagopal2016_walk/subject_scaled_walk_by_opensim.osim",
        "reference/opensim-4.6/rajagopal2016_walk/motion_capture_walk_ik.mot",
        "reference/opensim-4.6/rajagopal2016_walk/motion_capture_walk_ik_model_marker_locations.sto",
    );
    println!("rajagopal max marker error: {:.3e} mm", e * 1e3);
    assert!(e <= 1e-5, "max marker error {} mm", e * 1e3);
}

fn world_points(model: &Model, y: &[f64]) -> Vec<(String, nalgebra::Vector3<f64>)> {
    let mut ws = Workspace::new(model);
    forward(model, y, &mut ws);
    let mut v: Vec<_> = model.markers.iter().enumerate().map(|(m, mk)| (mk.name.clone(), ws.marker(m))).collect();
    v.extend(model.bodies.iter().enumerate().map(|(b, body)| (format!("body:{}", body.name), ws.body_pos[b])));
    v
}

#[test]
fn scaled_generic_rajagopal_equals_opensim_scaled_model() {
    let dir = "reference/opensim-4.6/rajagopal2016_walk/";
    let (generic, _) = read_osim(&shared("datasets/rajagopal2016_walk/Rajagopal2016.osim")).expect("generic");
    let (scaled, _) = read_osim(&shared(&format!("{dir}subject_scaled_walk_by_opensim.osim"))).expect("scaled");
    // The ScaleTool replaced the model's markers by the setup's marker set: attach it too.
    let set =
        smocap::io::osim::read_marker_set(&shared("datasets/rajagopal2016_walk/markerset_walk_preScale.xml"), &generic)
            .expect("marker set");
    let generic = generic.with_markers(set).expect("markers");
    let set_text =
        std::fs::read_to_string(shared("datasets/rajagopal2016_walk/markerset_walk_preScale.xml")).expect("marker set");
    let set_doc = roxmltree::Document::parse(&set_text).expect("xml");
    let fixed: Vec<String> = set_doc
        .descendants()
        .filter(|n| n.has_tag_name("Marker"))
        .filter(|n| n.children().any(|c| c.has_tag_name("fixed") && c.text().is_some_and(|t| t.trim() == "true")))
        .filter_map(|n| n.attribute("name").map(str::to_string))
        .collect();
    assert!(fixed.len() > 30);
    assert_eq!(generic.nq(), scaled.nq());
    let mut s = generic.default_state();
    for (seg, f) in scale_set(&shared(&format!("{dir}scaleSet_applied_walk.xml"))) {
        if let Some(b) = generic.body_index(&seg) {
            for (k, v) in f.iter().enumerate() {
                s[generic.scale_index(b, k)] = *v;
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (mut worst, mut compared) = (0.0f64, 0);
    for pose in 0..6 {
        let mut q: Vec<f64> = generic.coordinates.iter().map(|c| c.default).collect();
        if pose > 0 {
            for (i, c) in generic.coordinates.iter().enumerate() {
                let (lo, hi) = (c.range.0.max(-1.0), c.range.1.min(1.0));
                q[i] = if lo < hi { rng.random_range(lo..hi) } else { lo };
            }
            for k in &generic.couplings {
                q[k.dependent] = k.func.eval(q[k.independent]).0;
            }
        }
        s[..generic.nq()].copy_from_slice(&q);
        let mut unit = scaled.default_state();
        for (i, c) in scaled.coordinates.iter().enumerate() {
            unit[i] = q[generic.coordinate_index(&c.name).expect("same coordinates")];
        }
        let a = world_points(&generic, &s);
        let b = world_points(&scaled, &unit);
        // Every body origin, and every marker the MarkerPlacer kept fixed (`<fixed>true`; the
        // setup applies it, so the free markers were moved to the static trial).
        for (name, p2) in b.iter().filter(|(n, _)| n.starts_with("body:") || fixed.contains(n)) {
            let (_, p) = a.iter().find(|(n, _)| n == name).unwrap_or_else(|| panic!("{name} missing"));
            worst = worst.max((p - p2).norm());
        }
        compared = b.iter().filter(|(n, _)| n.starts_with("body:") || fixed.contains(n)).count();
    }
    println!("scale semantics: max difference {worst:.3e} m over {compared} points");
    // The applied factors are printed with 6 significant digits (pelvis 1.24463 where the scaled
    // model holds 1.2446319…), a relative rounding up to ~2e-6: 1e-6 m over ~0.5 m levers.
    assert!(worst <= 2e-6, "max difference {worst} m");
}

const SMALL: &str = r#"<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
  <Model name="tiny">
    <BodySet name="bodyset"><objects>
      <Body name="pelvis"><mass>1</mass></Body>
      <Body name="femur"><mass>1</mass></Body>
    </objects></BodySet>
    <JointSet name="jointset"><objects>
      <FreeJoint name="ground_pelvis">
        <socket_parent_frame>/ground</socket_parent_frame>
        <socket_child_frame>/bodyset/pelvis</socket_child_frame>
      </FreeJoint>
      <CustomJoint name="hip">
        <socket_parent_frame>pelvis_offset</socket_parent_frame>
        <socket_child_frame>femur_offset</socket_child_frame>
        <coordinates>
          <Coordinate name="hip_flexion"><default_value>0.1</default_value><range>-1 2</range>
            <clamped>true</clamped><locked>false</locked></Coordinate>
        </coordinates>
        <frames>
          <PhysicalOffsetFrame name="pelvis_offset"><socket_parent>/bodyset/pelvis</socket_parent>
            <translation>0.1 -0.2 0.05</translation><orientation>0.1 0.2 0.3</orientation></PhysicalOffsetFrame>
          <PhysicalOffsetFrame name="femur_offset"><socket_parent>/bodyset/femur</socket_parent>
            <translation>0 0.4 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
        </frames>
        <SpatialTransform>
          <TransformAxis name="rotation1"><coordinates>hip_flexion</coordinates><axis>1 0 0</axis>
            <LinearFunction name="function"><coefficients>1 0</coefficients></LinearFunction></TransformAxis>
          <TransformAxis name="translation1"><coordinates>hip_flexion</coordinates><axis>1 0 0</axis>
            <SimmSpline name="function"><x>0 0.5 1 1.5 2</x><y>0 0.01 0.015 0.02 0.01</y></SimmSpline></TransformAxis>
        </SpatialTransform>
      </CustomJoint>
    </objects></JointSet>
    <MarkerSet name="markerset"><objects>
      <Marker name="KNEE"><socket_parent_frame>/bodyset/femur</socket_parent_frame><location>0 -0.4 0.05</location></Marker>
    </objects></MarkerSet>
    <ForceSet name="forceset"><objects><Thelen2003Muscle name="m1"/><Thelen2003Muscle name="m2"/></objects></ForceSet>
  </Model>
</OpenSimDocument>
"#;

#[test]
fn small_model_parses_with_expected_structure() {
    let (m, w) = parse_osim(SMALL, "tiny.osim").expect("parses");
    assert_eq!(m.nb(), 2);
    assert_eq!(m.nq(), 7);
    assert_eq!(m.markers.len(), 1);
    assert_eq!(w, vec!["tiny.osim: ignored 2 Thelen2003Muscle".to_string()]);
    let hip = m.coordinate_index("hip_flexion").expect("hip");
    assert_eq!(m.coordinates[hip].default, 0.1);
    assert!(m.coordinates[hip].clamped);
    // Translation first (scaled with the parent), then the rotation.
    let r = m.bodies[1].joint.motions.clone();
    assert_eq!(r.len(), 2);
    assert!(m.motions[r.start].parent_scale_weights.is_some());
}

#[test]
fn simm_spline_interpolates_knots_and_extrapolates_linearly() {
    let x = [0.0, 0.3, 0.7, 1.0, 1.6, 2.0];
    let y = [0.0, 0.2, -0.1, 0.4, 0.5, 0.1];
    let f = simm_spline(&x, &y);
    for (xi, yi) in x.iter().zip(&y) {
        assert!((f.eval(*xi).0 - yi).abs() < 1e-12);
    }
    let Function::Spline(s) = &f else { panic!("spline expected") };
    let (v, d) = f.eval(-1.0);
    assert!((v - (y[0] - s.b[0])).abs() < 1e-12 && (d - s.b[0]).abs() < 1e-12);
    // SIMM's end condition differs from a natural spline's zero end curvature.
    assert!(s.c[0].abs() > 1e-6);
}

#[test]
fn unsupported_joint_type_names_line_and_supported_types() {
    let text = SMALL
        .replace("<FreeJoint name=\"ground_pelvis\">", "<PlanarJoint name=\"ground_pelvis\">")
        .replace("</FreeJoint>", "</PlanarJoint>");
    let e = parse_osim(&text, "tiny.osim").expect_err("must fail");
    let line = 1 + text[..text.find("<PlanarJoint").expect("tag")].matches('\n').count() as u32;
    assert_eq!(e.line(), Some(line));
    let msg = e.to_string();
    assert!(msg.contains("PlanarJoint") && msg.contains("CustomJoint, PinJoint"), "{msg}");
}

#[test]
fn marker_set_with_unknown_body_names_it_and_valid_bodies() {
    let (m, _) = parse_osim(SMALL, "tiny.osim").expect("parses");
    let set = r#"<OpenSimDocument Version="40000"><MarkerSet name="s"><objects>
        <Marker name="A"><socket_parent_frame>/bodyset/femur</socket_parent_frame><location>0 0 0</location></Marker>
        <Marker name="B"><body>tibia</body><location>0 0 0</location></Marker>
        </objects></MarkerSet></OpenSimDocument>"#;
    let msg = parse_marker_set(set, "set.xml", &m).expect_err("unknown body").to_string();
    assert!(msg.contains("'tibia'") && msg.contains("pelvis, femur"), "{msg}");
    let ok = parse_marker_set(&set.replace("tibia", "pelvis"), "set.xml", &m).expect("valid");
    assert_eq!(ok.len(), 2);
    assert_eq!(ok[1].body, m.body_index("pelvis").expect("pelvis"));
}

#[test]
fn marker_set_files_of_both_datasets_attach() {
    let (m, _) = read_osim(&shared("datasets/gait2354_subject01/gait2354_simbody.osim")).expect("gait");
    let path = shared("datasets/gait2354_subject01/gait2354_Scale_MarkerSet.xml");
    let markers = smocap::io::osim::read_marker_set(&path, &m).expect("marker set");
    assert!(markers.len() > 10);
    m.with_markers(markers).expect("attach");
}

#[test]
fn mutated_files_never_panic() {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let bytes = SMALL.as_bytes();
    let alphabet = b"<>/\"= 0123456789.-eE\nabcxyzNa";
    let mut parsed = 0;
    for _ in 0..500 {
        let mut b = bytes.to_vec();
        for _ in 0..rng.random_range(1..6) {
            let i = rng.random_range(0..b.len());
            match rng.random_range(0..3) {
                0 => b[i] = alphabet[rng.random_range(0..alphabet.len())],
                1 => {
                    b.remove(i);
                }
                _ => b.insert(i, alphabet[rng.random_range(0..alphabet.len())]),
            }
        }
        let text = String::from_utf8_lossy(&b);
        if let Ok((m, _)) = parse_osim(&text, "fuzz.osim") {
            parsed += 1;
            let mut ws = Workspace::new(&m);
            forward(&m, &m.default_state(), &mut ws);
        }
    }
    assert!(parsed > 0);
}

#[test]
fn scale_setup_groups_follow_measurements_and_equal_manual_factors() {
    let path = shared("datasets/rajagopal2016_walk/scale_setup_walk_scaleOnly.xml");
    if !path.exists() {
        return;
    }
    let s = smocap::io::osim::read_scale_setup(&path).expect("setup");
    assert!(s.place_markers);
    assert_eq!(s.mass_kg.map(|m| (m * 100.0).round()), Some(8507.0));
    let group = |body: &str| s.scale_groups.iter().find(|g| g.bodies.iter().any(|b| b == body)).expect(body);
    use smocap::model::profile::ScaleAxes;
    // PelvisX/Y/Z measure one axis each: one group, per-axis factors.
    assert_eq!(group("pelvis").bodies, ["pelvis"]);
    assert_eq!(group("pelvis").axes, ScaleAxes::Xyz);
    // footX/Y/Z cover six bodies on both sides.
    assert_eq!(group("calcn_r").bodies.len(), 6);
    assert_eq!(group("calcn_r").axes, ScaleAxes::Xyz);
    // Manual factors: equal uniform factors share a group (femurs and patellae at 0.958) …
    let thigh = group("femur_r");
    assert!(["femur_l", "patella_r", "patella_l"].iter().all(|b| thigh.bodies.iter().any(|x| x == b)));
    assert_eq!(thigh.axes, ScaleAxes::Uniform);
    // … and unequal per-axis ones give the body its own per-axis group.
    assert_eq!(group("torso").bodies, ["torso"]);
    assert_eq!(group("torso").axes, ScaleAxes::Xyz);
    // Bodies named nowhere (the hands) keep scale 1: no group.
    assert!(s.scale_groups.iter().all(|g| !g.bodies.iter().any(|b| b == "hand_r")));
}

#[test]
fn a_scale_setup_that_is_not_one_is_an_error_saying_so() {
    let err = smocap::io::osim::parse_scale_setup(
        "<OpenSimDocument><IKTool/></OpenSimDocument>",
        "x.xml",
        std::path::Path::new(""),
    )
    .expect_err("not a scale setup")
    .to_string();
    assert!(err.contains("x.xml") && err.contains("ScaleTool"), "{err}");
}
