//! Stage 2 of a conversion, per subject: set up (model, the dataset's settings, what C3D files
//! say of the subject), screen and calibrate on its static and motion trials as `smocap solve`
//! does, and keep what the solve and write stages need ([`Calibrated`], and the motion trials
//! read whole for it: [`Held`]).

use super::ConvertOptions;
use crate::archive::config::Dataset;
use crate::archive::discover::SubjectGroup;
use crate::archive::trial_job::{open_for, Calibrated};
use crate::pipeline::calibration::subject::prepare_subject;
use crate::pipeline::input::convention::InputOptions;
use crate::pipeline::input::frames::TrialFrames;
use std::collections::BTreeMap;
use std::path::Path;

/// The subject's motion trials read, screened and held whole for calibration, by trial path
/// (`rel`): the solve takes them from here rather than reading and screening them again (the
/// same [`open_for`] with the same context, so the same frames and label events). Trials read a
/// window at a time are not kept (they are read again as they are solved).
pub(super) type Held = BTreeMap<String, Box<dyn TrialFrames>>;

/// Calibrates subject `g` of dataset `d`: its calibration and the dataset's input conventions,
/// or why it could not be (every trial of the subject then fails with it).
pub(super) fn calibrate(
    d: &Dataset,
    g: &SubjectGroup,
    opt: &ConvertOptions,
    log: &(dyn Fn(&str) + Sync),
) -> Result<(Calibrated, InputOptions, Held), String> {
    let mut files = d.subject_files(g.static_trial.clone());
    match d.subject_info(&g.subject) {
        Ok(info) => files.subject = info,
        Err(e) => return Err(format!("subject setup: {e}")),
    }
    let mut sub = match prepare_subject(&files) {
        Ok(s) => s,
        Err(e) => return Err(format!("subject setup: {e}")),
    };
    // What C3D files say of their subject (as `solve`): the prior's height and mass where the
    // dataset gives none, and whether the subject's trials (done ones too) are one person.
    let paths: Vec<&Path> = g.trials.iter().map(|t| t.path.as_path()).chain(sub.static_path.as_deref()).collect();
    let records = crate::pipeline::calibration::subject_check::subject_records(&paths);
    if let Some(n) = crate::pipeline::calibration::subject_check::fill_from_records(&mut sub.ctx.subject, &records) {
        log(&format!("note: {}/{}: {n}", d.name, g.subject));
    }
    let mut not_one_person = crate::pipeline::calibration::subject_check::inconsistencies(&records);
    if !d.settings.is_empty() {
        match sub.ctx.settings.with_overrides(&d.settings) {
            Ok(s) => sub.ctx.settings = s,
            Err(e) => return Err(format!("datasets.toml [settings]: {e}")),
        }
        sub.ctx.settings.qp = crate::solve::backend_for(sub.ctx.settings.qp, &sub.ctx.proxy);
    }
    if let Some(mode) = opt.label_qc {
        sub.ctx.settings.label_qc.mode = mode;
    }
    let input = d.input_options();
    // Calibrate as `solve` does: the static trial (when there is one) and the motion trials whose
    // markers match the model's, together (read for calibration; those held whole are kept for
    // the solve, the others are read again one at a time).
    let window = opt.window_frames;
    let statics: Vec<(String, Box<dyn TrialFrames>)> = match &sub.static_path {
        Some(p) => match open_for(d, &sub.ctx, p, &input, window) {
            Ok(t) => {
                // Its labels were screened as the trials' are: what was found goes to the log,
                // and a static trial the screen calls suspect makes the calibration suspect.
                if let Some(qc) = t.label_qc() {
                    for line in qc.lines(&p.display().to_string()) {
                        log(&format!("{}/{}: {line}", d.name, g.subject));
                    }
                    not_one_person.extend(qc.suspect.iter().map(|w| format!("static trial: {w}")));
                }
                vec![(p.display().to_string(), t)]
            }
            Err(e) => return Err(format!("static trial: {e}")),
        },
        None => Vec::new(),
    };
    let opened: Vec<(String, Box<dyn TrialFrames>)> = g
        .trials
        .iter()
        .filter_map(|t| open_for(d, &sub.ctx, &t.path, &input, window).ok().map(|m| (t.rel.clone(), m)))
        .collect();
    let motions: Vec<(&str, &dyn TrialFrames)> = opened
        .iter()
        .filter(|(rel, m)| {
            crate::pipeline::input::trial::match_markers(&sub.ctx, rel, m.header())
                .is_ok_and(|x| x.columns.iter().any(Option::is_some))
        })
        .map(|(n, t)| (n.as_str(), t.as_ref()))
        .collect();
    let cal = if statics.is_empty() && motions.is_empty() {
        Err("no trial to calibrate on".to_string())
    } else {
        let s: Vec<(&str, &dyn TrialFrames)> = statics.iter().map(|(n, t)| (n.as_str(), t.as_ref())).collect();
        crate::pipeline::calibration::subject::calibrate_placed_with(&sub.ctx, &s, &motions)
            .map_err(|e| format!("calibration failed: {e}"))
    };
    drop((statics, motions));
    let (calibration, placed) = cal?;
    let held: Held = opened.into_iter().filter(|(_, t)| t.window_frames() == usize::MAX).collect();
    let ctx = placed.as_ref().unwrap_or(&sub.ctx);
    let source = d.model.as_ref().filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("osim")));
    let text = source.and_then(|p| std::fs::read_to_string(p).ok());
    let name = source.map(|p| p.display().to_string()).unwrap_or_default();
    let scaled_model = crate::pipeline::results::export::scaled_osim(
        ctx,
        &calibration,
        text.as_deref().map(|t| (t, name.as_str())),
        crate::io::osim::MassScaling { subject_mass: ctx.subject.mass_kg, ..Default::default() },
    )
    .ok()
    .and_then(|(m, _)| crate::archive::trial_job::compress_model(&m));
    let settings_json = serde_json::to_string_pretty(&ctx.settings).unwrap_or_default();
    let mut suspect = calibration.suspect();
    suspect.extend(not_one_person);
    for w in &suspect {
        log(&format!("warning: {}/{}: suspect calibration: {w}", d.name, g.subject));
    }
    Ok((Calibrated { base: sub.ctx, placed, calibration, settings_json, scaled_model, suspect }, input, held))
}
