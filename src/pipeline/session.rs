//! A subject calibrated once, then solving its trials, as `smocap solve` does it: shared by the
//! command line and the Python binding (`python/`), so that both give the same numbers and
//! verdicts. Trials are brought into the model's conventions with implausible samples masked
//! ([`conform_input`]), the subject calibrated with its report ([`calibrate`]), and each trial
//! solved and judged ([`solve_judged`]): a non-finite result or no solvable frame fails it, most
//! frames at the iteration cap or a suspect calibration make it `suspect`.

use crate::io::{MarkerFileError, MarkerTrial};
use crate::kinematics::backend::BatchBackend;
use crate::kinematics::synth::Truth;
use crate::pipeline::calibration::subject::{calibrate_placed_with, SetupError};
use crate::pipeline::context::Context;
use crate::pipeline::input::convention::{conform_trial, InputConventions, InputOptions};
use crate::pipeline::input::label_qc::LabelQc;
use crate::pipeline::input::trial::mask_implausible;
use crate::pipeline::results::report::{trial_report, CalibrationReport, TrialReport};
use crate::pipeline::results::verdict::{Judge, Verdict};
use crate::pipeline::running::stream::solve_trial_with;
use crate::pipeline::running::trial::TrialResult;
use crate::solve::Calibration;
use std::path::Path;

/// Brings `trial` (as read, or built in memory) into the model's units and up axis, then masks
/// samples no capture volume holds ([`mask_implausible`], with a warning in the trial's).
pub fn conform_input(ctx: &Context, trial: &mut MarkerTrial, opt: &InputOptions) -> InputConventions {
    let conv = conform_trial(ctx, trial, opt);
    if let Some(w) = mask_implausible(trial) {
        trial.warnings.push(w);
    }
    conv
}

/// Reads a marker file and brings it into the model's conventions ([`conform_input`]).
pub fn read_input(
    ctx: &Context,
    path: &Path,
    opt: &InputOptions,
) -> Result<(MarkerTrial, InputConventions), MarkerFileError> {
    let mut t = crate::io::read_markers(path)?;
    let conv = conform_input(ctx, &mut t, opt);
    Ok((t, conv))
}

/// Overrides solver settings with `table` (a profile's `[solver]` keys and TOML values, as
/// `--set KEY=VALUE`), keeping the QP backend one that solves the profile's constraints.
pub fn apply_overrides(ctx: &mut Context, table: &toml::Table) -> Result<(), String> {
    if table.is_empty() {
        return Ok(());
    }
    ctx.settings = ctx.settings.with_overrides(table)?;
    ctx.settings.qp = crate::solve::backend_for(ctx.settings.qp, &ctx.proxy);
    Ok(())
}

/// A calibrated subject: the context its trials are solved with, its calibration and the
/// report's `calibration` section.
#[derive(Clone)]
pub struct Calibrated {
    /// The subject's context, with its markers placed where marker placement moved them.
    pub ctx: Context,
    pub calibration: Calibration,
    pub report: CalibrationReport,
    /// Why the trials calibrated together are not one person
    /// ([`crate::pipeline::calibration::subject_check::inconsistencies`]); empty when nothing says so.
    pub subject_suspect: Vec<String>,
}

impl Calibrated {
    /// Why the calibration cannot be trusted (empty when it can): every trial is then `suspect`.
    pub fn suspect(&self) -> Vec<String> {
        let mut out = self.calibration.suspect();
        out.extend(self.subject_suspect.iter().cloned());
        out
    }

    /// Marks the calibration `suspect` because its trials are not one person (`why`), in its
    /// report too.
    pub fn mark_subject_suspect(&mut self, why: Vec<String>) {
        if why.is_empty() {
            return;
        }
        self.report.status = "suspect".into();
        self.report.warnings.extend(why.iter().cloned());
        self.subject_suspect = why;
    }
}

/// Calibrates the subject of `ctx` once from its static trials and frames of its motion trials
/// (both brought into the model's conventions), with the report (against `ctx`'s generic markers).
pub fn calibrate(
    ctx: &Context,
    statics: &[(&str, &MarkerTrial)],
    motions: &[(&str, &MarkerTrial)],
) -> Result<Calibrated, SetupError> {
    let (calibration, placed) = calibrate_placed_with(ctx, statics, motions)?;
    let report = CalibrationReport::new(ctx, &calibration);
    let ctx = placed.unwrap_or_else(|| ctx.clone());
    Ok(Calibrated { ctx, calibration, report, subject_suspect: Vec::new() })
}

/// A solved trial that is a result (`ok` or `suspect`): its report entry, its frames, and lines
/// worth saying (bridged frames, pre-solved outliers, why it is suspect).
pub struct JudgedTrial {
    pub report: TrialReport,
    pub result: TrialResult,
    pub notes: Vec<String>,
}

/// Solves `trial` (in the model's conventions, as `input` says) for the subject `cal` with
/// `threads` threads and `lanes` lanes on `backend` (the CPU backend when `None`), and judges it.
/// `Err` is why it is not a result (the report's `error` of a failed trial).
#[allow(clippy::too_many_arguments)]
pub fn solve_judged(
    cal: &Calibrated,
    name: &str,
    trial: &MarkerTrial,
    input: &InputConventions,
    threads: usize,
    lanes: usize,
    backend: Option<&mut (dyn BatchBackend + '_)>,
    truth: Option<&Truth>,
) -> Result<JudgedTrial, String> {
    let ctx = &cal.ctx;
    let r = solve_trial_with(ctx, name, trial, &cal.calibration, threads, lanes, backend).map_err(|e| e.to_string())?;
    let verdict = judge(&r);
    if let Verdict::Failed(why) = &verdict {
        return Err(format!("{name}: {why}"));
    }
    let mut notes: Vec<String> = r
        .bridged
        .iter()
        .map(|&f| {
            format!(
                "{name}: frame {f} (file frame {}, t = {:.3} s) has fewer than {} observed markers; bridged from its neighbours",
                trial.frame_numbers.get(f).copied().unwrap_or(f as i64 + 1),
                trial.times.get(f).copied().unwrap_or(f64::NAN),
                ctx.settings.min_markers
            )
        })
        .collect();
    if !r.presolved.is_empty() {
        notes.push(format!("{name}: {} outlier frames improved by pre-solve", r.presolved.len()));
    }
    notes.extend(r.marker_errors.lines(name));
    notes.extend(r.marker_errors.unfittable.iter().map(|u| format!("warning: {name}: {}", u.why)));
    let mut report = trial_report(ctx, &r, truth);
    report.input = Some(input.clone());
    // Suspect: the trial's frames (mostly at the iteration cap) or its subject's calibration.
    let mut why: Vec<String> = verdict.reason().into_iter().collect();
    why.extend(report.plausibility.iter().flat_map(|p| p.suspect.iter().cloned()));
    let suspect = cal.suspect();
    if !suspect.is_empty() {
        why.push(format!("suspect calibration: {}", suspect.join("; ")));
    }
    if !why.is_empty() {
        let why = why.join("; ");
        notes.push(format!("warning: {name}: suspect: {why}"));
        report.status = "suspect".into();
        report.error = Some(why);
    }
    Ok(JudgedTrial { report, result: r, notes })
}

/// Screens the labels of `trial` (held whole, in the model's conventions) as
/// `ctx.settings.label_qc` says, repairing and masking in place ([`crate::pipeline::input::label_qc`]); `None`
/// when its markers do not match the model's (solving it then says why) or screening is off.
pub fn screen_labels(ctx: &Context, name: &str, trial: &mut MarkerTrial) -> Option<LabelQc> {
    if ctx.settings.label_qc.mode == crate::pipeline::input::label_qc::QcMode::Off {
        return None;
    }
    let matched = crate::pipeline::input::trial::match_markers(ctx, name, trial).ok()?;
    crate::pipeline::input::label_qc::screen_in_place(ctx, trial, &matched.columns).ok()
}

/// Puts a trial's label QC into its report entry: its events as notes, and the trial `suspect`
/// when the QC says so.
pub fn attach_label_qc(j: &mut JudgedTrial, qc: Option<LabelQc>) {
    let Some(qc) = qc else { return };
    let name = j.report.trial.clone();
    j.notes.extend(qc.lines(&name));
    if let Some(why) = &qc.suspect {
        j.notes.push(format!("warning: {name}: suspect: {why}"));
        j.report.status = "suspect".into();
        j.report.error = Some(match j.report.error.take() {
            Some(e) => format!("{e}; {why}"),
            None => why.clone(),
        });
    }
    j.report.label_qc = Some(qc);
}

/// The verdict on a solved trial ([`crate::pipeline::results::verdict`]).
pub fn judge(r: &TrialResult) -> Verdict {
    let mut j = Judge::default();
    for (f, (p, st)) in r.proxies.iter().zip(&r.stats).enumerate() {
        j.frame(f, p, st, r.bridged.binary_search(&f).is_ok());
    }
    j.verdict()
}
