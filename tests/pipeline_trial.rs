//! Whole-trial solving on real lab data: joint scale–pose calibration from the GENERIC OpenSim
//! models (their Scale setups' scale groups and marker placement, their IK setups' weights), then
//! every frame of the walking trial. The acceptance bar is OpenSim 4.6's own Scale + IK result
//! on the same data (`../shared/reference/opensim-4.6/*/*_summary.json`): our mean marker RMSE
//! over the trial must be no higher.

mod common;

use common::shared;
use smocap::io::osim::{read_ik_setup, read_scale_setup};
use smocap::io::read_markers;
use smocap::pipeline::calibration::calibrate::calibrate_subject_with;
use smocap::pipeline::{solve_trial, Context};
use smocap::solve::FrameStatus;

struct Dataset {
    dir: &'static str,
    model: &'static str,
    markerset: &'static str,
    scale_setup: &'static str,
    ik_setup: &'static str,
    static_trial: &'static str,
    trial: &'static str,
    summary: &'static str,
}

/// Mean marker RMSE (m) over the solved frames, and OpenSim's (m); `None` when data are absent.
fn joint_solve_rmse(d: &Dataset) -> Option<(f64, f64)> {
    let p = |f: &str| shared(&format!("datasets/{}/{f}", d.dir));
    if !p(d.model).exists() {
        println!("skipped: ../shared/datasets/{} is absent", d.dir);
        return None;
    }
    let ctx = Context::from_files_with_markers(&p(d.model), Some(&p(d.markerset)), None).expect("model");
    let setup = read_scale_setup(&p(d.scale_setup)).expect("scale setup");
    assert!(setup.place_markers, "both setups place markers");
    let mut ctx = ctx.with_scale_setup(&setup, d.scale_setup).expect("scale setup applies");
    ctx.apply_ik_setup(&read_ik_setup(&p(d.ik_setup)).expect("ik setup")).expect("ik setup applies");
    let static_trial = read_markers(&p(d.static_trial)).expect("static");
    let trial = read_markers(&p(d.trial)).expect("trial");
    // One morphology from the static trial and the motion together.
    let cal = calibrate_subject_with(&ctx, &[("static", &static_trial)], &[("walk", &trial)]).expect("calibration");
    let ctx = ctx.with_marker_offsets(cal.marker_offsets.as_ref().expect("placement ran")).expect("placed");
    let r = solve_trial(&ctx, d.trial, &trial, &cal, 2).expect("solve");
    let solved: Vec<f64> =
        r.stats.iter().filter(|s| s.status != FrameStatus::TooFewMarkers).map(|s| s.rmse_m).collect();
    assert_eq!(solved.len(), trial.n_frames(), "every frame has markers enough");
    let ours = solved.iter().sum::<f64>() / solved.len() as f64;
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(shared(d.summary)).expect("summary")).expect("json");
    let opensim = summary["rms_mean_m"].as_f64().expect("rms_mean_m");
    println!("{}: smocap mean RMSE {:.2} mm, OpenSim {:.2} mm", d.dir, ours * 1e3, opensim * 1e3);
    Some((ours, opensim))
}

#[test]
fn gait2354_walk_from_the_generic_model_fits_markers_at_least_as_well_as_opensim() {
    let d = Dataset {
        dir: "gait2354_subject01",
        model: "gait2354_simbody.osim",
        markerset: "gait2354_Scale_MarkerSet.xml",
        scale_setup: "subject01_Setup_Scale.xml",
        ik_setup: "subject01_Setup_IK.xml",
        static_trial: "subject01_static.trc",
        trial: "subject01_walk1.trc",
        summary: "reference/opensim-4.6/gait2354_subject01/subject01_walk1_summary.json",
    };
    if let Some((ours, opensim)) = joint_solve_rmse(&d) {
        assert!(ours <= opensim, "mean RMSE {:.2} mm > OpenSim's {:.2} mm", ours * 1e3, opensim * 1e3);
    }
}

#[test]
fn rajagopal_walk_from_the_generic_model_fits_markers_at_least_as_well_as_opensim() {
    let d = Dataset {
        dir: "rajagopal2016_walk",
        model: "Rajagopal2016.osim",
        markerset: "markerset_walk_preScale.xml",
        scale_setup: "scale_setup_walk_scaleOnly.xml",
        ik_setup: "ik_setup_walk.xml",
        static_trial: "static_walk_1.trc",
        trial: "motion_capture_walk.trc",
        summary: "reference/opensim-4.6/rajagopal2016_walk/motion_capture_walk_summary.json",
    };
    if let Some((ours, opensim)) = joint_solve_rmse(&d) {
        assert!(ours <= opensim, "mean RMSE {:.2} mm > OpenSim's {:.2} mm", ours * 1e3, opensim * 1e3);
    }
}
