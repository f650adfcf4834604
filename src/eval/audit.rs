//! Leakage audit (METHOD.md): the joint solve (scale and pose calibrated together on the static
//! trial, then every frame solved) against a stage-wise baseline (each segment scaled from
//! marker-pair distances in the static trial as OpenSim's Scale tool does, [`stagewise`], then
//! pose-only IK with that scale frozen, by the same trust-region solver), on the same trials.
//!
//! On synthetic subjects with known truth ([`subjects`]) each method gets, per subject:
//! - `pose_deg`: RMS over the motion frames and the driven rotational coordinates of the
//!   joint-angle error (deg); `knee_deg` the same over the knee angles alone;
//! - `scale_mm`: RMS over the scale proxies of `|ŝ − s| · L`, `L` the proxy's segment length at
//!   unit scale (the sum over its bodies of each body's largest extent from its origin to a child
//!   joint or a marker), in mm: an anthropometric error; `scale_pct` the RMS of `ŝ − s` in %;
//!   `ŝ` is the subject's calibrated morphology (frozen factors for the baseline);
//! - `marker_rmse_mm`: mean over the motion frames of the per-frame marker RMSE (mm).
//!
//! A method "wins" a subject on a metric when its error is the lower. On real datasets (those of
//! a `datasets.toml` with an OpenSim Scale setup and a static trial), marker RMSE of both methods
//! is reported beside OpenSim's (reference `*_summary.json`), the baseline scaling with the
//! setup's own measurements and then placing markers when its MarkerPlacer applies.

pub mod breakdown;
mod real;
pub mod stagewise;
pub mod subjects;

pub use real::{audit_real, RealAudit};

use crate::model::math::wrap_angle;
use crate::pipeline::{calibrate_subject, solve_trial, Context, TrialError, TrialResult};
use crate::solve::FrameStatus;
use breakdown::{driven_coordinates, scale_proxies, Breakdown, Detail};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use subjects::{subject, SubjectSpec, SyntheticSubject};

/// Errors of one method on one subject (units in the field names).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct MethodErrors {
    pub pose_deg: f64,
    pub knee_deg: f64,
    pub scale_mm: f64,
    pub scale_pct: f64,
    pub marker_rmse_mm: f64,
}

/// Both methods on one synthetic subject.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SubjectAudit {
    pub subject: usize,
    pub joint: MethodErrors,
    pub stagewise: MethodErrors,
    /// The joint solve's errors per coordinate and scale group.
    #[serde(default)]
    pub joint_detail: Detail,
    /// The baseline's errors per coordinate and scale group.
    #[serde(default)]
    pub stagewise_detail: Detail,
    /// Notes of the baseline's scaling (skipped pairs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// Subjects won per metric.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct Wins {
    pub pose: usize,
    pub scale: usize,
    pub marker: usize,
}

/// Mean over the subjects of each method's errors.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct MeanErrors {
    pub joint: MethodErrors,
    pub stagewise: MethodErrors,
}

/// The audit's result.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AuditReport {
    pub smocap_version: String,
    /// Synthetic subjects audited (each: one static and one motion trial).
    pub trials: usize,
    pub seed: u64,
    /// Subjects where the joint solve has the lower error.
    pub wins: Wins,
    /// Subjects where the stage-wise baseline has the lower error.
    pub stagewise_wins: Wins,
    pub mean: Option<MeanErrors>,
    pub spec: SubjectSpec,
    pub subjects: Vec<SubjectAudit>,
    /// Both methods' errors per coordinate and scale group, pooled over the subjects.
    #[serde(default)]
    pub breakdown: Breakdown,
    /// `subject N: reason` for subjects that could not be audited.
    pub failed: Vec<String>,
    pub real: Vec<RealAudit>,
}

/// Runs the synthetic part on `n` subjects of the shipped model, in parallel over subjects.
pub fn audit_synthetic(ctx: &Context, n: usize, seed: u64, spec: &SubjectSpec) -> AuditReport {
    let results: Vec<Result<SubjectAudit, String>> = (0..n)
        .into_par_iter()
        .map(|i| audit_subject(ctx, spec, seed, i).map_err(|e| format!("subject {i}: {e}")))
        .collect();
    let (mut subjects, mut failed) = (Vec::new(), Vec::new());
    for r in results {
        match r {
            Ok(s) => subjects.push(s),
            Err(e) => failed.push(e),
        }
    }
    let count = |f: fn(&MethodErrors) -> f64, joint_better: bool| {
        subjects
            .iter()
            .filter(|s| if joint_better { f(&s.joint) < f(&s.stagewise) } else { f(&s.stagewise) < f(&s.joint) })
            .count()
    };
    let wins_of = |j: bool| Wins {
        pose: count(|e| e.pose_deg, j),
        scale: count(|e| e.scale_mm, j),
        marker: count(|e| e.marker_rmse_mm, j),
    };
    let mean = (!subjects.is_empty()).then(|| {
        let avg = |g: fn(&SubjectAudit) -> MethodErrors| {
            let m =
                |f: fn(&MethodErrors) -> f64| subjects.iter().map(|s| f(&g(s))).sum::<f64>() / subjects.len() as f64;
            MethodErrors {
                pose_deg: m(|e| e.pose_deg),
                knee_deg: m(|e| e.knee_deg),
                scale_mm: m(|e| e.scale_mm),
                scale_pct: m(|e| e.scale_pct),
                marker_rmse_mm: m(|e| e.marker_rmse_mm),
            }
        };
        MeanErrors { joint: avg(|s| s.joint), stagewise: avg(|s| s.stagewise) }
    });
    AuditReport {
        smocap_version: env!("CARGO_PKG_VERSION").into(),
        trials: subjects.len(),
        seed,
        wins: wins_of(true),
        stagewise_wins: wins_of(false),
        mean,
        spec: spec.clone(),
        breakdown: breakdown::pool(ctx, &subjects),
        subjects,
        failed,
        real: Vec::new(),
    }
}

/// Both methods on synthetic subject `i`.
pub fn audit_subject(ctx: &Context, spec: &SubjectSpec, seed: u64, i: usize) -> Result<SubjectAudit, TrialError> {
    let s = subject(ctx, spec, seed, i);
    let statics = [("static", &s.static_trial)];
    let cal = calibrate_subject(ctx, &statics)?;
    let joint = solve_trial(ctx, "motion", &s.motion, &cal, 1)?;
    let scale = stagewise::measure(ctx, &s.static_trial, &stagewise::shipped_measurements(), &[]);
    let pinned = stagewise::pinned(ctx, &scale);
    let cal_s = calibrate_subject(&pinned, &statics)?;
    let stage = solve_trial(&pinned, "motion", &s.motion, &cal_s, 1)?;
    let (joint, joint_detail) = errors(ctx, &s, &cal.proxies, &joint);
    let (stagewise, stagewise_detail) = errors(ctx, &s, &cal_s.proxies, &stage);
    Ok(SubjectAudit { subject: i, joint, stagewise, joint_detail, stagewise_detail, notes: scale.notes })
}

/// Each scale proxy's segment length at unit scale (m): the sum over the bodies it drives of
/// each body's largest extent from its origin to a child joint or one of its markers.
pub fn segment_lengths(ctx: &Context) -> Vec<f64> {
    let model = &ctx.model;
    let nq = model.nq();
    let extent = |b: usize| {
        let joints = model
            .bodies
            .iter()
            .filter(|c| c.parent == Some(b))
            .map(|c| c.joint.parent_offset.translation.vector.norm());
        let markers = model.markers.iter().filter(|m| m.body == b).map(|m| m.offset.norm());
        joints.chain(markers).fold(0.0, f64::max)
    };
    (0..ctx.proxy.np())
        .map(|k| {
            let mut bodies: Vec<usize> = ctx
                .proxy
                .terms
                .iter()
                .filter(|t| t.proxy == k && t.y_index >= nq)
                .map(|t| (t.y_index - nq) / 3)
                .collect();
            bodies.dedup();
            bodies.into_iter().map(extent).sum()
        })
        .collect()
}

/// One method's errors on subject `s`, its morphology `cal` (proxies) and its motion solve `r`:
/// the summary and the itemised detail.
fn errors(ctx: &Context, s: &SyntheticSubject, cal: &[f64], r: &TrialResult) -> (MethodErrors, Detail) {
    let model = &ctx.model;
    let driven = driven_coordinates(ctx);
    let is_knee: Vec<bool> = driven.iter().map(|&c| model.coordinates[c].name.contains("knee")).collect();
    let (mut sq, mut sum) = (vec![0.0; driven.len()], vec![0.0; driven.len()]);
    for (p, q) in r.proxies.iter().zip(&s.truth_q) {
        let y = ctx.proxy.state(p);
        for (i, &c) in driven.iter().enumerate() {
            let e = wrap_angle(y[c] - q[c]);
            sq[i] += e * e;
            sum[i] += e;
        }
    }
    let frames = r.proxies.len().min(s.truth_q.len());
    let rms_of = |pick: &dyn Fn(usize) -> bool| {
        let (sum, n) = (0..driven.len()).filter(|&i| pick(i)).fold((0.0, 0usize), |(a, n), i| (a + sq[i], n + 1));
        if n == 0 || frames == 0 {
            f64::NAN
        } else {
            (sum / (n * frames) as f64).sqrt().to_degrees()
        }
    };
    let lengths = segment_lengths(ctx);
    let truth = &s.truth_proxies[0];
    let scales = scale_proxies(ctx);
    let rms = |v: &mut dyn Iterator<Item = f64>| {
        let v: Vec<f64> = v.collect();
        (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    let rmse: Vec<f64> = r
        .stats
        .iter()
        .filter(|st| st.status != FrameStatus::TooFewMarkers && st.rmse_m.is_finite())
        .map(|st| st.rmse_m * 1e3)
        .collect();
    let summary = MethodErrors {
        pose_deg: rms_of(&|_| true),
        knee_deg: rms_of(&|i| is_knee[i]),
        scale_mm: rms(&mut scales.iter().map(|&k| (cal[k] - truth[k]) * lengths[k] * 1e3)),
        scale_pct: rms(&mut scales.iter().map(|&k| (cal[k] - truth[k]) * 100.0)),
        marker_rmse_mm: rmse.iter().sum::<f64>() / rmse.len().max(1) as f64,
    };
    let detail = Detail {
        coordinate_deg: sq
            .iter()
            .map(|&e| if frames == 0 { f64::NAN } else { (e / frames as f64).sqrt().to_degrees() })
            .collect(),
        coordinate_bias_deg: sum
            .iter()
            .map(|&e| if frames == 0 { f64::NAN } else { (e / frames as f64).to_degrees() })
            .collect(),
        scale_pct: scales.iter().map(|&k| (cal[k] - truth[k]) * 100.0).collect(),
    };
    (summary, detail)
}

impl AuditReport {
    /// A human-readable summary: per subject, then means, wins and the real datasets.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:>7}  {:>21} {:>21} {:>21} {:>21}\n",
            "subject", "pose deg joint/stage", "knee deg joint/stage", "scale mm joint/stage", "RMSE mm joint/stage"
        );
        let row = |name: String, j: &MethodErrors, g: &MethodErrors| {
            format!(
                "{:>7}  {:>10.2}/{:<10.2} {:>10.2}/{:<10.2} {:>10.2}/{:<10.2} {:>10.2}/{:<10.2}\n",
                name,
                j.pose_deg,
                g.pose_deg,
                j.knee_deg,
                g.knee_deg,
                j.scale_mm,
                g.scale_mm,
                j.marker_rmse_mm,
                g.marker_rmse_mm
            )
        };
        for a in &self.subjects {
            s += &row(a.subject.to_string(), &a.joint, &a.stagewise);
        }
        if let Some(m) = &self.mean {
            s += &row("mean".into(), &m.joint, &m.stagewise);
        }
        s += &format!(
            "joint solve wins ({} subjects): pose {}/{n}, scale {}/{n}, marker {}/{n}\n",
            self.trials,
            self.wins.pose,
            self.wins.scale,
            self.wins.marker,
            n = self.trials
        );
        for f in &self.failed {
            s += &format!("failed: {f}\n");
        }
        for r in &self.real {
            s += &r.line();
        }
        s
    }
}
