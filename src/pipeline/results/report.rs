//! The JSON report (`--report-json`) and its human-readable table.

use crate::kinematics::synth::Truth;
use crate::model::proxy::ProxyKind;
use crate::pipeline::context::Context;
use crate::pipeline::input::convention::InputConventions;
use crate::pipeline::running::trial::TrialResult;
use crate::pipeline::stats::{GapStats, MeanP50P90, P50P90};
use crate::solve::{FrameStatus, SolverSettings};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Pose error against a truth (degrees, rotational coordinates that the solver moves).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct PoseError {
    pub rmse: f64,
    pub p90: f64,
}

/// Scale error against a truth (percent, over the scale proxies).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct ScaleError {
    pub mean: f64,
    pub max: f64,
}

/// One trial in the report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrialReport {
    pub trial: String,
    /// "ok" or "failed".
    pub status: String,
    /// Why the trial failed (null when it did not).
    pub error: Option<String>,
    pub frames: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub marker_rmse_mm: Option<MeanP50P90>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ms_per_frame: Option<P50P90>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations: Option<P50P90>,
    pub solve_wall_s: f64,
    /// Per-body scale factors `[sx, sy, sz]`: the mean over the trial's frames.
    pub scale: BTreeMap<String, [f64; 3]>,
    /// Largest per-frame deviation of any scale proxy from the calibrated value.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale_drift_max: Option<f64>,
    /// Frames bridged for lack of markers.
    pub bridged_frames: Vec<usize>,
    /// Frames that hit the iteration cap.
    pub frames_at_iteration_cap: usize,
    pub unmatched_model_markers: Vec<String>,
    pub unmatched_trial_markers: Vec<String>,
    /// File labels matched to a model marker other than exactly (label → model marker).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub renamed_markers: BTreeMap<String, String>,
    /// Missing data of the matched markers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gaps: Option<GapStats>,
    /// Units and up axis of the file, and what was done to bring it into the model's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input: Option<InputConventions>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose_error_deg: Option<PoseError>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale_error_pct: Option<ScaleError>,
    /// Joint angles against what a person does: ranges, limits, jumps, left/right differences.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plausibility: Option<crate::pipeline::results::plausibility::PosePlausibility>,
    /// Label quality control: swaps, jumps and ghosts found, and what was done
    /// ([`crate::pipeline::input::label_qc`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub label_qc: Option<crate::pipeline::input::label_qc::LabelQc>,
    /// Per-marker RMSE and maximum (anatomical and tracking markers), and the worst frames
    /// ([`crate::pipeline::running::marker_errors`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub marker_errors: Option<crate::pipeline::running::marker_errors::MarkerErrorTable>,
    /// Runs of frames no pose fits (RMSE far above the trial's), their worst markers and whether
    /// the data or the model is to blame ([`crate::pipeline::running::unfittable`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unfittable: Vec<crate::pipeline::running::unfittable::Unfittable>,
    /// What the verdict says beyond the status, for a trial that did not fail: "the data is bad
    /// here: …" for runs of unfittable frames blamed on the data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// Totals over the run.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Totals {
    pub frames: usize,
    pub solve_wall_s: f64,
    pub frames_per_s: f64,
}

/// The whole report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Report {
    pub smocap_version: String,
    /// Evaluation backend: "cpu" or "wgpu".
    pub backend: String,
    /// What the backend ran on (for wgpu: adapter name, type, API and driver).
    #[serde(default)]
    pub device: String,
    /// Why `--backend auto` fell back to the CPU, when it did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backend_note: Option<String>,
    /// Lanes of the scheduler (frames in flight per batched evaluation, at most).
    #[serde(default)]
    pub lanes: usize,
    pub qp_backend: String,
    pub threads: usize,
    pub model: String,
    pub settings: SolverSettings,
    /// Units and up axis of the static trial, when one was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub static_input: Option<InputConventions>,
    /// The static trial's label quality control (its labels screened as every trial's are,
    /// before they inform the calibration), when one was given and screening is on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub static_label_qc: Option<crate::pipeline::input::label_qc::LabelQc>,
    /// The subject's calibration: morphology against its priors, registration, time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationReport>,
    pub trials: Vec<TrialReport>,
    pub totals: Totals,
}

/// What calibration found, for the report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CalibrationReport {
    /// "ok", or "suspect" (then `warnings` says why, and no trial counts as ok).
    pub status: String,
    pub warnings: Vec<String>,
    pub frames: usize,
    pub iterations: u32,
    /// Wall time (s).
    pub seconds: f64,
    /// Mean marker RMSE over the calibration frames (mm).
    pub rmse_mm: f64,
    /// Markers whose offsets were registered.
    pub registered_markers: usize,
    /// How far registration or placement moved each marker from the model's position (mm, at
    /// the subject's scale), largest first.
    pub marker_moves_mm: Vec<(String, f64)>,
    /// Scales with their z-scores, dimensions against the prior, stature.
    pub prior: crate::solve::prior::PriorReport,
    /// Each registered marker's move with its class and why it has it; landmarks moved too far.
    #[serde(default)]
    pub registration: crate::solve::prior::RegistrationReport,
    /// The root's joints (the hips) from the motion against the calibrated model's.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub functional_centres: Vec<crate::solve::prior::FunctionalCentre>,
    /// The static trial's posture (mean angles of its calibration frames), when there was one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub static_posture: Option<crate::solve::prior::StaticPostureReport>,
    /// Height and mass the anthropometric prior took from the files (C3D `PROCESSING`), when
    /// the user gave none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub subject_from_files: Option<String>,
    /// What each stage cost (frames, accepted and rejected steps, wall time).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<crate::solve::calibration::StageCost>,
}

impl CalibrationReport {
    /// One line for stderr.
    pub fn summary(&self) -> String {
        let stature = self.prior.stature_m.map_or(String::new(), |h| format!(", stature {h:.3} m"));
        let worst = self.prior.scales.iter().map(|s| s.z.abs()).fold(0.0, f64::max);
        format!(
            "calibration: {} frames, {} iterations, {:.2} s, RMSE {:.2} mm, {} markers registered{stature}, largest |z| of a scale {worst:.2}: {}",
            self.frames, self.iterations, self.seconds, self.rmse_mm, self.registered_markers, self.status
        ) + &if self.stages.is_empty() {
            String::new()
        } else {
            format!("\n  calibration stages: {}", crate::solve::calibration::StageCost::summary(&self.stages))
        }
    }

    /// The report of `cal` for the subject `ctx` (its generic markers).
    pub fn new(ctx: &Context, cal: &crate::solve::Calibration) -> CalibrationReport {
        let warnings = cal.warnings();
        let y = ctx.proxy.state(&cal.proxies);
        let mut moves: Vec<(String, f64)> = match &cal.marker_offsets {
            Some(o) => ctx
                .model
                .markers
                .iter()
                .zip(o)
                .map(|(m, o)| {
                    let s = nalgebra::Vector3::new(
                        y[ctx.model.scale_index(m.body, 0)],
                        y[ctx.model.scale_index(m.body, 1)],
                        y[ctx.model.scale_index(m.body, 2)],
                    );
                    (m.name.clone(), (o - m.offset).component_mul(&s).norm() * 1e3)
                })
                .collect(),
            None => Vec::new(),
        };
        moves.sort_by(|a, b| b.1.total_cmp(&a.1));
        CalibrationReport {
            status: if cal.suspect().is_empty() { "ok" } else { "suspect" }.into(),
            warnings,
            frames: cal.frames,
            iterations: cal.iterations,
            seconds: cal.seconds,
            rmse_mm: cal.rmse_m * 1e3,
            registered_markers: cal.registered,
            marker_moves_mm: moves,
            prior: cal.prior.clone(),
            registration: cal.registration_report.clone(),
            functional_centres: cal.functional_centres.clone(),
            static_posture: (cal.static_frames > 0).then(|| cal.posture.clone()),
            subject_from_files: None,
            stages: cal.stages.clone(),
        }
    }
}

impl Report {
    pub fn new(ctx: &Context, threads: usize) -> Report {
        Report {
            smocap_version: env!("CARGO_PKG_VERSION").into(),
            backend: "cpu".into(),
            device: "cpu, f64".into(),
            backend_note: None,
            lanes: threads,
            qp_backend: format!("{:?}", ctx.settings.qp).to_lowercase(),
            threads,
            model: ctx.model_source.clone(),
            settings: ctx.settings.clone(),
            static_input: None,
            static_label_qc: None,
            calibration: None,
            trials: Vec::new(),
            totals: Totals::default(),
        }
    }

    /// Records the evaluation backend that solved the trials.
    pub fn set_backend(&mut self, chosen: &crate::pipeline::running::device::Chosen, lanes: usize) {
        self.backend = chosen.name().into();
        self.device = chosen.device();
        self.backend_note = chosen.note().map(str::to_string);
        self.lanes = lanes;
    }

    /// Adds a trial (and updates the totals).
    pub fn push(&mut self, t: TrialReport) {
        self.totals.frames += t.frames;
        self.totals.solve_wall_s += t.solve_wall_s;
        self.totals.frames_per_s =
            if self.totals.solve_wall_s > 0.0 { self.totals.frames as f64 / self.totals.solve_wall_s } else { 0.0 };
        self.trials.push(t);
    }

    /// A failed trial.
    pub fn failed(name: &str, error: String) -> TrialReport {
        TrialReport {
            trial: name.into(),
            status: "failed".into(),
            error: Some(error),
            frames: 0,
            marker_rmse_mm: None,
            ms_per_frame: None,
            iterations: None,
            solve_wall_s: 0.0,
            scale: BTreeMap::new(),
            scale_drift_max: None,
            bridged_frames: Vec::new(),
            frames_at_iteration_cap: 0,
            unmatched_model_markers: Vec::new(),
            unmatched_trial_markers: Vec::new(),
            renamed_markers: BTreeMap::new(),
            gaps: None,
            input: None,
            pose_error_deg: None,
            scale_error_pct: None,
            plausibility: None,
            label_qc: None,
            marker_errors: None,
            unfittable: Vec::new(),
            reason: None,
        }
    }

    /// Fixed-width table, one line per trial (METHOD.md's columns).
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:<28} {:>7} {:>9} {:>8} {:>8} {:>6} {:>6} {:>8} {:>8}\n",
            "trial", "frames", "FPS", "ms p50", "ms p90", "it p50", "it p90", "RMSE p50", "RMSE p90"
        );
        for t in &self.trials {
            match (&t.ms_per_frame, &t.iterations, &t.marker_rmse_mm) {
                (Some(ms), Some(it), Some(r)) => {
                    s += &format!(
                        "{:<28} {:>7} {:>9.0} {:>8.3} {:>8.3} {:>6.0} {:>6.0} {:>8.2} {:>8.2}\n",
                        t.trial,
                        t.frames,
                        t.frames as f64 / t.solve_wall_s.max(1e-12),
                        ms.p50,
                        ms.p90,
                        it.p50,
                        it.p90,
                        r.p50,
                        r.p90
                    )
                }
                _ => s += &format!("{:<28} failed: {}\n", t.trial, t.error.clone().unwrap_or_default()),
            }
        }
        s
    }
}

/// Summarises a solved trial, with errors against `truth` when given.
pub fn trial_report(ctx: &Context, r: &TrialResult, truth: Option<&Truth>) -> TrialReport {
    let n = r.proxies.len();
    let solved: Vec<usize> = (0..n).filter(|&f| r.stats[f].status != FrameStatus::TooFewMarkers).collect();
    let rmse_mm: Vec<f64> = solved.iter().map(|&f| r.stats[f].rmse_m * 1e3).collect();
    let ms: Vec<f64> = solved.iter().map(|&f| r.frame_seconds[f] * 1e3).collect();
    let its: Vec<f64> = solved.iter().map(|&f| r.stats[f].iterations as f64).collect();
    let scale_k: Vec<usize> = (0..ctx.proxy.np()).filter(|&k| ctx.proxy.proxies[k].kind == ProxyKind::Scale).collect();
    // Per-trial morphology: the mean over solved frames (the calibration when none was solved).
    let mean_p: Vec<f64> = if solved.is_empty() {
        r.calibration.proxies.clone()
    } else {
        (0..ctx.proxy.np())
            .map(|k| solved.iter().map(|&f| r.proxies[f][k]).sum::<f64>() / solved.len() as f64)
            .collect()
    };
    let y_mean = ctx.proxy.state(&mean_p);
    let scale = ctx
        .model
        .bodies
        .iter()
        .enumerate()
        .map(|(b, body)| (body.name.clone(), [0, 1, 2].map(|a| y_mean[ctx.model.scale_index(b, a)])))
        .collect();
    let drift = scale_k
        .iter()
        .flat_map(|&k| solved.iter().map(move |&f| (r.proxies[f][k] - r.calibration.proxies[k]).abs()))
        .fold(0.0f64, f64::max);
    let (pose_error_deg, scale_error_pct) = match truth {
        Some(t) => errors_against(ctx, r, &mean_p, &scale_k, t),
        None => (None, None),
    };
    TrialReport {
        trial: r.name.clone(),
        status: "ok".into(),
        error: None,
        frames: n,
        marker_rmse_mm: Some(MeanP50P90::of(&rmse_mm)),
        ms_per_frame: Some(P50P90::of(&ms)),
        iterations: Some(P50P90::of(&its)),
        solve_wall_s: r.wall_seconds,
        scale,
        scale_drift_max: (!scale_k.is_empty()).then_some(drift),
        bridged_frames: r.bridged.clone(),
        frames_at_iteration_cap: r.stats.iter().filter(|s| s.status == FrameStatus::MaxIterations).count(),
        unmatched_model_markers: r.unmatched_model.clone(),
        unmatched_trial_markers: r.unmatched_trial.clone(),
        renamed_markers: r.renamed.iter().cloned().collect(),
        gaps: Some(r.gaps.clone()),
        input: None,
        pose_error_deg,
        scale_error_pct,
        plausibility: Some(pose_plausibility(ctx, r)),
        label_qc: None,
        marker_errors: Some(r.marker_errors.clone()),
        unfittable: r.marker_errors.unfittable.clone(),
        reason: crate::pipeline::running::unfittable::reason(&r.marker_errors.unfittable),
    }
}

/// The pose check ([`crate::pipeline::results::plausibility`]) of a solved trial.
pub fn pose_plausibility(ctx: &Context, r: &TrialResult) -> crate::pipeline::results::plausibility::PosePlausibility {
    let mut check = crate::pipeline::results::plausibility::PoseCheck::new(ctx);
    for (f, (p, st)) in r.proxies.iter().zip(&r.stats).enumerate() {
        check.frame(f, p, st.status != FrameStatus::TooFewMarkers);
    }
    check.finish()
}

fn errors_against(
    ctx: &Context,
    r: &TrialResult,
    mean_p: &[f64],
    scale_k: &[usize],
    t: &Truth,
) -> (Option<PoseError>, Option<ScaleError>) {
    use crate::model::CoordinateKind;
    // Rotational coordinates the solver moves, present in the truth.
    let moved: Vec<(usize, usize)> = ctx
        .model
        .coordinates
        .iter()
        .enumerate()
        .filter(|(j, c)| c.kind == CoordinateKind::Rotational && !ctx.proxy.y_terms[*j].is_empty())
        .filter_map(|(j, c)| t.coordinate_names.iter().position(|n| n == &c.name).map(|tj| (j, tj)))
        .collect();
    let mut errs = Vec::new();
    // Over solved frames, like every other statistic of the report (bridged frames are interpolated).
    for f in (0..r.proxies.len().min(t.coordinates.len())).filter(|&f| r.stats[f].status != FrameStatus::TooFewMarkers)
    {
        let y = ctx.proxy.state(&r.proxies[f]);
        for &(j, tj) in &moved {
            // A rotation off by whole turns is the same pose.
            errs.push(crate::model::math::wrap_angle(y[j] - t.coordinates[f][tj]).to_degrees().abs());
        }
    }
    let pose = (!errs.is_empty()).then(|| PoseError {
        rmse: (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt(),
        p90: crate::pipeline::stats::percentile(&errs, 0.9),
    });
    let serr: Vec<f64> = scale_k
        .iter()
        .filter_map(|&k| t.scales.get(&ctx.proxy.proxies[k].name).map(|&truth| (mean_p[k] / truth - 1.0).abs() * 100.0))
        .collect();
    let scale = (!serr.is_empty()).then(|| ScaleError {
        mean: serr.iter().sum::<f64>() / serr.len() as f64,
        max: serr.iter().copied().fold(0.0, f64::max),
    });
    (pose, scale)
}
