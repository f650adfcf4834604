//! OpenSim IK setup files: parsing, errors with lines, and their effect on a subject (marker
//! weights as OpenSim uses them, checked against OpenSim's own marker error output; coordinate
//! targets).

use smocap::io::osim::ik_setup::CoordinateValue;
use smocap::io::osim::{parse_ik_setup, read_ik_setup};
use smocap::io::sto::read_sto;
use smocap::pipeline::{calibrate_subject, solve_trial, Context};
use std::path::{Path, PathBuf};

fn shared(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared").join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipped: {} is absent", p.display());
        None
    }
}

const TINY: &str = r#"<?xml version="1.0"?>
<OpenSimDocument Version="40000">
  <InverseKinematicsTool name="t">
    <accuracy>1e-005</accuracy>
    <IKTaskSet>
      <objects>
        <IKMarkerTask name="A"><apply>true</apply><weight>2</weight></IKMarkerTask>
        <IKMarkerTask name="B"><apply>false</apply><weight>5</weight></IKMarkerTask>
        <IKMarkerTask name="C"/>
        <IKCoordinateTask name="q1"><weight>10</weight><value_type>manual_value</value_type><value>0.25</value></IKCoordinateTask>
        <IKCoordinateTask name="q2"><weight>3</weight></IKCoordinateTask>
      </objects>
    </IKTaskSet>
    <coordinate_file>Unassigned</coordinate_file>
    <time_range> 0.5 2</time_range>
  </InverseKinematicsTool>
</OpenSimDocument>
"#;

#[test]
fn tasks_and_settings_are_read_with_opensim_defaults() {
    let s = parse_ik_setup(TINY, "tiny.xml").expect("parses");
    assert_eq!(s.name.as_deref(), Some("t"));
    assert_eq!(s.accuracy, Some(1e-5));
    assert_eq!(s.time_range, Some((0.5, 2.0)));
    assert_eq!(s.coordinate_file, None);
    let m: Vec<(&str, bool, f64)> = s.marker_tasks.iter().map(|t| (t.name.as_str(), t.apply, t.weight)).collect();
    assert_eq!(m, [("A", true, 2.0), ("B", false, 5.0), ("C", true, 0.0)]);
    assert_eq!(s.marker_tasks[0].line, 7);
    assert_eq!(s.coordinate_tasks[0].value, CoordinateValue::Manual(0.25));
    assert_eq!(s.coordinate_tasks[1].value, CoordinateValue::Default);
    assert!(s.coordinate_tasks.iter().all(|t| t.apply));
}

#[test]
fn bad_setups_are_errors_with_file_and_line() {
    let cases = [
        (TINY.replace("<value_type>manual_value", "<value_type>from_mars"), "from_mars", 10),
        (TINY.replace("<weight>2</weight>", "<weight>-2</weight>"), "negative", 7),
        (TINY.replace("<weight>2</weight>", "<weight>two</weight>"), "expected numbers", 7),
        (TINY.replace("<apply>false</apply>", "<apply>maybe</apply>"), "true, false", 8),
        (TINY.replace("name=\"B\"", "name=\"A\""), "duplicate IKMarkerTask 'A'", 8),
        (TINY.replace("InverseKinematicsTool", "ScaleTool"), "missing <InverseKinematicsTool>", 2),
        (TINY.replace("</IKTaskSet>", ""), "malformed XML", 0),
    ];
    for (text, needle, line) in cases {
        let e = parse_ik_setup(&text, "setup.xml").expect_err(needle);
        let msg = e.to_string();
        assert!(msg.contains(needle) && msg.starts_with("setup.xml:"), "{msg}");
        if line > 0 {
            assert_eq!(e.line(), Some(line), "{msg}");
        }
    }
}

#[test]
fn both_dataset_setups_parse() {
    let (Some(g), Some(r)) = (
        shared("datasets/gait2354_subject01/subject01_Setup_IK.xml"),
        shared("datasets/rajagopal2016_walk/ik_setup_walk.xml"),
    ) else {
        return;
    };
    let g = read_ik_setup(&g).expect("gait2354");
    assert_eq!((g.marker_tasks.len(), g.coordinate_tasks.len()), (31, 4));
    assert_eq!(g.time_range, Some((0.4, 1.6)));
    assert_eq!(g.marker_file.as_deref(), Some("subject01_walk1.trc"));
    assert!(g.coordinate_tasks.iter().all(|t| t.weight == 1000.0 && t.value == CoordinateValue::Default));
    let r = read_ik_setup(&r).expect("rajagopal");
    assert_eq!(r.marker_tasks.len(), 49);
    assert_eq!(r.marker_tasks.iter().filter(|t| t.apply).count(), 39);
    assert_eq!(r.model_file.as_deref(), Some("../Scale/subject_scaled_walk.osim"));
    assert_eq!(r.coordinate_file, None);
}

/// Markers OpenSim used per frame: `total_squared_error / marker_error_RMS²`, the same on every row.
fn opensim_markers_used(sto: &Path) -> usize {
    let t = read_sto(sto).expect("marker errors");
    let (tot, rms) = (t.column("total_squared_error").expect("col"), t.column("marker_error_RMS").expect("col"));
    let n: Vec<usize> = t.rows.iter().map(|r| (r[tot] / (r[rms] * r[rms])).round() as usize).collect();
    assert!(n.iter().all(|&k| k == n[0]), "{n:?}");
    n[0]
}

/// Applies the dataset's IK setup, solves its walk, and checks the markers used per frame
/// against OpenSim's and that coordinate targets hold.
fn solve_with_setup(dir: &str, model: &str, set: &str, stat: &str, walk: &str, setup: &str, reference: &str) {
    let (Some(d), Some(r)) = (shared(dir), shared(reference)) else { return };
    let mut ctx = Context::from_files_with_markers(&d.join(model), Some(&d.join(set)), None).expect("context");
    let applied = ctx.apply_ik_setup(&read_ik_setup(&d.join(setup)).expect("setup")).expect("applies");
    assert!(applied.warnings.is_empty(), "{:?}", applied.warnings);
    let walk_t = smocap::io::read_markers(&d.join(walk)).expect("walk");
    let static_t = smocap::io::read_markers(&d.join(stat)).expect("static");
    let expected = opensim_markers_used(&r);
    let map = smocap::pipeline::input::trial::match_markers(&ctx, walk, &walk_t).expect("match").columns;
    let used = map.iter().zip(&ctx.marker_weights).filter(|(c, &w)| c.is_some() && w > 0.0).count();
    assert_eq!(used, expected, "markers weighted and in the file, as OpenSim counts them");
    let cal = calibrate_subject(&ctx, &[(stat, &static_t)]).expect("calibrates");
    let res = solve_trial(&ctx, walk, &walk_t, &cal, 1).expect("solves");
    assert!(res.stats.iter().all(|s| s.markers_used == expected));
    // Coordinate targets (gait2354: subtalar and mtp held at their default 0 with weight 1000):
    // the largest distance from target over the coordinates with one, with and without them.
    let targeted: Vec<usize> = (0..ctx.model.nq()).filter(|&j| ctx.coordinate_weights[j] > 0.0).collect();
    if targeted.is_empty() {
        return;
    }
    let worst = |ctx: &Context, proxies: &[Vec<f64>]| {
        proxies
            .iter()
            .flat_map(|p| {
                let y = ctx.proxy.state(p);
                targeted.iter().map(move |&j| (y[j] - ctx.coordinate_targets[j]).abs())
            })
            .fold(0.0f64, f64::max)
    };
    let with = worst(&ctx, &res.proxies);
    ctx.coordinate_weights.iter_mut().for_each(|w| *w = 0.0);
    let cal = calibrate_subject(&ctx, &[(stat, &static_t)]).expect("calibrates");
    let without = worst(&ctx, &solve_trial(&ctx, walk, &walk_t, &cal, 1).expect("solves").proxies);
    eprintln!(
        "{dir}: worst distance from coordinate targets {:.3} deg with them, {:.3} without",
        with.to_degrees(),
        without.to_degrees()
    );
    assert!(with < 1f64.to_radians() && with < 0.2 * without, "{with} vs {without}");
}

#[test]
fn gait2354_setup_uses_the_markers_opensim_used_and_holds_its_coordinates() {
    solve_with_setup(
        "datasets/gait2354_subject01",
        "gait2354_simbody.osim",
        "gait2354_Scale_MarkerSet.xml",
        "subject01_static.trc",
        "subject01_walk1.trc",
        "subject01_Setup_IK.xml",
        "reference/opensim-4.6/gait2354_subject01/subject01_walk1_ik_marker_errors.sto",
    );
}

#[test]
fn rajagopal_setup_uses_the_39_markers_opensim_used() {
    solve_with_setup(
        "datasets/rajagopal2016_walk",
        "Rajagopal2016.osim",
        "markerset_walk_preScale.xml",
        "static_walk_1.trc",
        "motion_capture_walk.trc",
        "ik_setup_walk.xml",
        "reference/opensim-4.6/rajagopal2016_walk/motion_capture_walk_ik_marker_errors.sto",
    );
}

#[test]
fn applying_a_setup_replaces_weights_and_sets_targets() {
    let mut ctx = Context::shipped().expect("shipped");
    let names: Vec<String> = ctx.model.markers.iter().take(2).map(|m| m.name.clone()).collect();
    let coord = ctx
        .model
        .coordinates
        .iter()
        .position(|c| !c.locked && !ctx.proxy.y_terms[ctx.model.coordinate_index(&c.name).unwrap()].is_empty())
        .expect("a free coordinate");
    let cname = ctx.model.coordinates[coord].name.clone();
    let text = TINY.replace("\"A\"", &format!("\"{}\"", names[0])).replace("\"B\"", &format!("\"{}\"", names[1]));
    let text = text.replace("\"q1\"", &format!("\"{cname}\""));
    let setup = parse_ik_setup(&text, "s.xml").expect("parses");
    let done = ctx.apply_ik_setup(&setup).expect("applies");
    assert_eq!(ctx.marker_weights[0], 2.0);
    assert_eq!(ctx.marker_weights[1], 0.0, "apply = false");
    assert!(ctx.marker_weights[2..].iter().all(|&w| w == 0.0), "no task: unused, as in OpenSim");
    assert_eq!(done.markers_weighted, 1);
    assert_eq!((ctx.coordinate_weights[coord], ctx.coordinate_targets[coord]), (10.0, 0.25));
    let w = done.warnings.join("\n");
    assert!(w.contains("'C'") && w.contains("marker the model lacks"), "{w}");
    assert!(w.contains("'q2'") && w.contains("coordinate the model lacks"), "{w}");
    // from_file is refused when applied, ignored when not.
    let from_file = text.replace("manual_value", "from_file");
    let msg = ctx.apply_ik_setup(&parse_ik_setup(&from_file, "s.xml").unwrap()).expect_err("from_file").to_string();
    assert!(msg.contains("from_file is not supported") && msg.contains("s.xml:10"), "{msg}");
    let off = from_file.replace("<weight>10</weight>", "<apply>false</apply><weight>10</weight>");
    ctx.apply_ik_setup(&parse_ik_setup(&off, "s.xml").unwrap()).expect("an unapplied from_file task is ignored");
    assert_eq!(ctx.coordinate_weights[coord], 0.0);
}
