//! Units and up axis of marker data: detection, explicit overrides, and the rotation into the
//! model's convention (shipped model: Z up; OpenSim models: Y up).

use nalgebra::{Matrix3, Rotation3, Vector3};
use smocap::io::MarkerTrial;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::pipeline::input::convention::{conform_trial, rotate, rotation_between, InputOptions, Units, UpAxis};
use smocap::pipeline::Context;
use std::path::Path;

/// A synthetic trial; its subject leans up to 25° at times, 9° on average.
fn synthetic(ctx: &Context) -> MarkerTrial {
    synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 200, seed: 3, ..SynthOptions::default() }).trial
}

fn max_diff(a: &MarkerTrial, b: &MarkerTrial) -> f64 {
    a.positions.iter().zip(&b.positions).filter(|(x, _)| x.is_finite()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// Z-up → Y-up, as a lab would write it: `(x, y, z) → (x, z, −y)`.
fn z_to_y() -> Matrix3<f64> {
    Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0)
}

#[test]
fn data_in_the_models_convention_are_left_alone() {
    let ctx = Context::shipped().unwrap();
    let orig = synthetic(&ctx);
    let mut t = orig.clone();
    let c = conform_trial(&ctx, &mut t, &InputOptions::default());
    assert_eq!((c.up.as_deref(), c.up_source.as_str(), c.rotation), (Some("z"), "detected", None));
    assert_eq!((c.units.as_str(), c.units_source.as_str()), ("m", "file header"));
    assert!(c.notes.is_empty(), "{:?}", c.notes);
    assert_eq!(max_diff(&t, &orig), 0.0);
    assert!(c.summary().contains("not rotated"), "{}", c.summary());
}

#[test]
fn y_up_data_are_detected_and_rotated_into_a_z_up_model() {
    let ctx = Context::shipped().unwrap();
    let orig = synthetic(&ctx);
    let mut t = orig.clone();
    rotate(&mut t, &z_to_y());
    let c = conform_trial(&ctx, &mut t, &InputOptions::default());
    assert_eq!((c.up.as_deref(), c.up_source.as_str()), (Some("y"), "detected"));
    let r = c.rotation.expect("rotated");
    let r = Matrix3::from_fn(|i, j| r[i][j]);
    assert!((r.determinant() - 1.0).abs() < 1e-12 && (r * z_to_y() - Matrix3::identity()).abs().max() < 1e-12);
    assert!(max_diff(&t, &orig) < 1e-12, "back where it came from");
}

#[test]
fn every_signed_axis_is_detected_and_tilted_data_are_ambiguous() {
    let ctx = Context::shipped().unwrap();
    let orig = synthetic(&ctx);
    for (to, name) in
        [(Vector3::x(), "x"), (-Vector3::x(), "-x"), (Vector3::y(), "y"), (-Vector3::y(), "-y"), (-Vector3::z(), "-z")]
    {
        let mut t = orig.clone();
        rotate(&mut t, rotation_between(&Vector3::z(), &to).matrix());
        let c = conform_trial(&ctx, &mut t, &InputOptions::default());
        assert_eq!(c.up.as_deref(), Some(name));
        assert!(max_diff(&t, &orig) < 1e-12, "{name}");
    }
    // 45° between two axes: left as is, and said so.
    let mut t = orig.clone();
    rotate(&mut t, Rotation3::from_axis_angle(&Vector3::x_axis(), 45f64.to_radians()).matrix());
    let before = t.clone();
    let c = conform_trial(&ctx, &mut t, &InputOptions::default());
    assert_eq!((c.up.as_deref(), c.rotation), (None, None));
    assert!(c.up_source.starts_with("ambiguous"), "{}", c.up_source);
    assert!(c.summary().contains("left as is"), "{}", c.summary());
    assert_eq!(max_diff(&t, &before), 0.0);
}

#[test]
fn explicit_up_and_units_override_detection() {
    let ctx = Context::shipped().unwrap();
    let orig = synthetic(&ctx);
    let mut t = orig.clone();
    rotate(&mut t, &z_to_y());
    let opt = InputOptions { up: Some(UpAxis::Y), units: Some(Units::Mm) };
    let c = conform_trial(&ctx, &mut t, &opt);
    assert_eq!(
        (c.up_source.as_str(), c.units.as_str(), c.units_source.as_str()),
        ("command line", "mm", "command line")
    );
    // The file said m; read as mm every position shrinks 1000 times.
    let mut back = orig.clone();
    back.positions.iter_mut().for_each(|v| *v *= 1e-3);
    assert!(max_diff(&t, &back) < 1e-15);
}

#[test]
fn units_come_from_magnitudes_when_the_header_has_none_and_header_doubts_are_noted() {
    let ctx = Context::shipped().unwrap();
    let orig = synthetic(&ctx);
    // A C3D without POINT:UNITS holding metres: read as mm, everything is 1000 times too small.
    let mut t = orig.clone();
    t.positions.iter_mut().for_each(|v| *v *= 1e-3);
    t.source_units = "mm".into();
    t.warnings.push("no POINT:UNITS; assuming mm".into());
    let c = conform_trial(&ctx, &mut t, &InputOptions::default());
    assert_eq!((c.units.as_str(), c.units_source.as_str()), ("m", "marker spread"));
    assert!(max_diff(&t, &orig) < 1e-12);
    // The same numbers under a header saying mm: kept, with a note.
    t.positions.iter_mut().for_each(|v| *v *= 1e-3);
    t.warnings.clear();
    let c = conform_trial(&ctx, &mut t, &InputOptions::default());
    assert_eq!((c.units.as_str(), c.units_source.as_str()), ("mm", "file header"));
    assert!(c.notes.iter().any(|n| n.contains("m would fit")), "{:?}", c.notes);
}

#[test]
fn opensim_datasets_are_y_up_like_their_models() {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets");
    for (dir, model, set, trials) in [
        (
            "gait2354_subject01",
            "gait2354_simbody.osim",
            "gait2354_Scale_MarkerSet.xml",
            ["subject01_static.trc", "subject01_walk1.trc"],
        ),
        (
            "rajagopal2016_walk",
            "Rajagopal2016.osim",
            "markerset_walk_preScale.xml",
            ["static_walk_1.trc", "motion_capture_walk.trc"],
        ),
    ] {
        let d = d.join(dir);
        if !d.exists() {
            eprintln!("skipped: {} is absent", d.display());
            continue;
        }
        let ctx = Context::from_files_with_markers(&d.join(model), Some(&d.join(set)), None).unwrap();
        assert_eq!(ctx.up, Some(Vector3::y()));
        for f in trials {
            let mut t = smocap::io::read_markers(&d.join(f)).unwrap();
            let c = conform_trial(&ctx, &mut t, &InputOptions::default());
            assert_eq!((c.up.as_deref(), c.rotation, c.units.as_str()), (Some("y"), None, "mm"), "{f}");
            assert!(c.notes.is_empty(), "{f}: {:?}", c.notes);
        }
    }
}

#[test]
fn an_explicit_up_axis_that_contradicts_a_confident_detection_is_warned_about() {
    let ctx = Context::shipped().unwrap();
    let mut t = synthetic(&ctx);
    rotate(&mut t, &z_to_y());
    // The data are Y up; the user says Z.
    let c = conform_trial(&ctx, &mut t.clone(), &InputOptions { up: Some(UpAxis::Z), units: None });
    assert_eq!(c.up_source, "command line");
    assert!(c.notes.iter().any(|n| n.contains("--up z contradicts") && n.contains("(y)")), "{:?}", c.notes);
    // Saying what the data are draws no warning.
    let c = conform_trial(&ctx, &mut t, &InputOptions { up: Some(UpAxis::Y), units: None });
    assert!(c.notes.iter().all(|n| !n.contains("contradicts")), "{:?}", c.notes);
}
