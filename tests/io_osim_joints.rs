//! Every OpenSim joint type against OpenSim itself: `tests/data/osim_joints.osim` (FreeJoint,
//! CustomJoint, PinJoint, UniversalJoint, SliderJoint, BallJoint, GimbalJoint, WeldJoint, with
//! translated and rotated offset frames, spline / linear / constant CustomJoint translations and
//! a CoordinateCouplerConstraint) and the world positions and orientations OpenSim 4.6 computed
//! for 20 random states, unscaled and after `Model::scale` with non-uniform factors on every
//! body (`tests/data/osim_joints_expected.json`). Regenerate with
//! `python scripts/gen_osim_joint_fixture.py` (OpenSim's Python package).

use nalgebra::{Matrix3, Vector3};
use serde_json::Value;
use smocap::io::osim::read_osim;
use smocap::kinematics::cpu::{forward, Workspace};
use smocap::model::{CoordinateKind, Model};
use std::path::{Path, PathBuf};

/// Tolerance on positions (m) and on rotation-matrix entries.
const TOL: f64 = 1e-9;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

fn expected() -> Value {
    let text = std::fs::read_to_string(data("osim_joints_expected.json")).expect("expected values");
    serde_json::from_str(&text).expect("json")
}

fn model(name: &str) -> Model {
    let (model, warnings) = read_osim(&data(name)).expect("fixture parses");
    assert!(warnings.is_empty(), "{warnings:?}");
    model
}

fn vec3(v: &Value) -> Vector3<f64> {
    let a: Vec<f64> = v.as_array().expect("array").iter().map(|x| x.as_f64().expect("number")).collect();
    Vector3::new(a[0], a[1], a[2])
}

fn mat3(v: &Value) -> Matrix3<f64> {
    let a: Vec<f64> = v.as_array().expect("array").iter().map(|x| x.as_f64().expect("number")).collect();
    Matrix3::from_row_slice(&a)
}

/// Sets every body's scale factors from the fixture's `scales`.
fn set_scales(model: &Model, scales: &Value, y: &mut [f64]) {
    for (name, s) in scales.as_object().expect("scales") {
        let b = model.body_index(name).unwrap_or_else(|| panic!("body {name}"));
        let s = vec3(s);
        for k in 0..3 {
            y[model.scale_index(b, k)] = s[k];
        }
    }
}

/// Worst (position, rotation) differences of our FK from OpenSim's over the fixture's states,
/// and the number of points compared. `scales`: the per-body factors to put in `y`, if any;
/// markers and origins of the bodies in `skip` are not compared.
fn compare(model: &Model, states: &Value, scales: Option<&Value>, skip: &[&str]) -> (f64, f64, usize) {
    let mut ws = Workspace::new(model);
    let (mut dp, mut dr, mut points) = (0.0f64, 0.0f64, 0);
    for st in states.as_array().expect("states") {
        let mut y = model.default_state();
        if let Some(s) = scales {
            set_scales(model, s, &mut y);
        }
        let q = st["coordinates"].as_object().expect("coordinates");
        assert_eq!(q.len(), model.nq(), "every coordinate is in the fixture");
        for (name, v) in q {
            let i = model.coordinate_index(name).unwrap_or_else(|| panic!("coordinate {name}"));
            y[i] = v.as_f64().expect("number");
        }
        // The coupled coordinate as OpenSim's constraint function gives it.
        for k in &model.couplings {
            let (f, _) = k.func.eval(y[k.independent]);
            assert!((f - y[k.dependent]).abs() < 1e-12, "coupling {f} vs {}", y[k.dependent]);
        }
        forward(model, &y, &mut ws);
        for (name, p) in st["markers"].as_object().expect("markers") {
            let m = model.marker_index(name).unwrap_or_else(|| panic!("marker {name}"));
            if skip.contains(&model.bodies[model.markers[m].body].name.as_str()) {
                continue;
            }
            dp = dp.max((ws.marker(m) - vec3(p)).amax());
            points += 1;
        }
        for (name, p) in st["body_origins"].as_object().expect("origins") {
            let b = model.body_index(name).unwrap_or_else(|| panic!("body {name}"));
            if skip.contains(&name.as_str()) {
                continue;
            }
            dp = dp.max((ws.body_pos[b] - vec3(p)).amax());
            dr = dr.max((ws.body_rot[b] - mat3(&st["body_rotations"][name])).amax());
            points += 1;
        }
    }
    (dp, dr, points)
}

#[test]
fn every_joint_type_matches_opensim_fk() {
    let model = model("osim_joints.osim");
    let e = expected();
    let (dp, dr, n) = compare(&model, &e["unscaled"], None, &[]);
    println!("unscaled: {n} points, max position error {dp:.3e} m, max rotation error {dr:.3e}");
    assert_eq!(n, 20 * (model.markers.len() + model.nb()));
    assert!(dp < TOL && dr < TOL, "position {dp:e} m, rotation {dr:e}");
}

#[test]
fn non_uniform_body_scales_match_opensim_model_scale() {
    let model = model("osim_joints.osim");
    let e = expected();
    // Everything but the bodies below the elbow's oblique translation axis matches as imported.
    let below_elbow = ["forearm", "hand"];
    let (dp, dr, n) = compare(&model, &e["scaled"], Some(&e["scales"]), &below_elbow);
    println!("scaled state: {n} points, max position error {dp:.3e} m, max rotation error {dr:.3e}");
    assert!(n > 0);
    assert!(dp < TOL && dr < TOL, "position {dp:e} m, rotation {dr:e}");
    // OpenSim multiplies a scaled translation function by `|axis|·s_parent`, which is not 1 at
    // unit scale for an oblique axis (Σ|axisᵢ| = 1.4 for the elbow's (0.6, −0.8, 0)). We keep
    // the unscaled model exact and weight by `|axis|/Σ|axisᵢ|`; with OpenSim's own weights
    // `|axis|` substituted, the oblique axis matches too.
    let (dp_below, _, _) = compare(&model, &e["scaled"], Some(&e["scales"]), &[]);
    println!("scaled state, all bodies as imported: max position error {dp_below:.3e} m (the oblique axis)");
    let mut opensim_weights = model.clone();
    let mut oblique = 0;
    for mo in &mut opensim_weights.motions {
        if let Some(w) = &mut mo.parent_scale_weights {
            let a = mo.axis.abs();
            assert!((*w - a / a.sum()).amax() < 1e-15, "weights {w:?} for axis {:?}", mo.axis);
            oblique += usize::from(a.sum() > 1.0 + 1e-12);
            *w = a;
        }
    }
    assert_eq!(oblique, 1);
    let (dp, dr, n) = compare(&opensim_weights, &e["scaled"], Some(&e["scales"]), &[]);
    println!("scaled state, OpenSim's weights: {n} points, max position error {dp:.3e} m, rotation {dr:.3e}");
    assert!(dp < TOL && dr < TOL, "position {dp:e} m, rotation {dr:e}");
}

#[test]
fn opensim_scaled_model_file_matches_its_own_fk() {
    // OpenSim's scaled model (offsets, markers scaled; CustomJoint translations wrapped in
    // MultiplierFunction) read back at unit scale.
    let model = model("osim_joints_scaled.osim");
    let (dp, dr, n) = compare(&model, &expected()["scaled"], None, &[]);
    println!("scaled file: {n} points, max position error {dp:.3e} m, max rotation error {dr:.3e}");
    assert!(dp < TOL && dr < TOL, "position {dp:e} m, rotation {dr:e}");
}

#[test]
fn coordinate_kinds_follow_opensim_motion_types() {
    let model = model("osim_joints.osim");
    let kind = |n: &str| model.coordinates[model.coordinate_index(n).expect("coordinate")].kind;
    use CoordinateKind::{Rotational as R, Translational as T};
    // OpenSim 4.6 `Coordinate::getMotionType` of the fixture (Coupled → ours by its axes).
    for (name, k) in [
        ("pelvis_rx", R),
        ("pelvis_tz", T),
        ("hip_flex", R),
        ("knee_coord_0", R),
        ("ankle_coord_1", R),
        ("mtp_coord_0", T),
        ("back_coord_2", R),
        ("neck_coord_0", R),
        // Pure about rotation1, pure (slope −1) along translation2: the last pure axis wins.
        ("elbow_flex", T),
        ("elbow_beta", R),
        ("wrist_flex", R),
    ] {
        assert_eq!(kind(name), k, "{name}");
    }
}
