//! The leakage audit on real datasets: marker RMSE of the joint solve and of the stage-wise
//! baseline (scaled with the dataset's own OpenSim Scale setup measurements, markers then placed
//! when its MarkerPlacer applies), beside OpenSim 4.6's Scale + IK (reference `*_summary.json`).

use super::stagewise;
use crate::archive::config::Dataset;
use crate::archive::discover::discover;
use crate::pipeline::calibration::subject::{calibrate_placed, calibrate_placed_with, prepare_subject, read_trial};
use crate::pipeline::stats::MeanP50P90;
use crate::pipeline::{solve_trial, TrialResult};
use crate::solve::FrameStatus;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One real trial.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RealAudit {
    pub dataset: String,
    pub trial: String,
    pub frames: usize,
    /// Per-frame marker RMSE (mm) of each method; OpenSim's from its reference summary.
    pub joint_rmse_mm: MeanP50P90,
    pub stagewise_rmse_mm: MeanP50P90,
    pub opensim_rmse_mm: Option<MeanP50P90>,
    /// Baseline scale factors per scale proxy (name, factor), as measured.
    pub stagewise_scales: Vec<(String, f64)>,
    pub joint_scales: Vec<(String, f64)>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl RealAudit {
    pub fn line(&self) -> String {
        let f = |m: &MeanP50P90| format!("{:.2} ({:.2}/{:.2})", m.mean, m.p50, m.p90);
        format!(
            "{}/{}: marker RMSE mm mean (p50/p90): joint {}, stage-wise {}, OpenSim {}\n",
            self.dataset,
            self.trial,
            f(&self.joint_rmse_mm),
            f(&self.stagewise_rmse_mm),
            self.opensim_rmse_mm.as_ref().map_or("-".into(), f)
        )
    }
}

#[derive(Deserialize)]
struct Summary {
    tag: String,
    rms_mean_m: f64,
    rms_p50_m: f64,
    rms_p90_m: f64,
}

fn rmse(r: &TrialResult) -> MeanP50P90 {
    let v: Vec<f64> = r
        .stats
        .iter()
        .filter(|s| s.status != FrameStatus::TooFewMarkers && s.rmse_m.is_finite())
        .map(|s| s.rmse_m * 1e3)
        .collect();
    MeanP50P90::of(&v)
}

/// OpenSim's marker RMSE for trial `stem` of `dataset` under `reference`, when recorded.
fn opensim(reference: &Path, dataset: &str, stem: &str) -> Option<MeanP50P90> {
    let dir = reference.join(dataset);
    std::fs::read_dir(dir).ok()?.filter_map(|e| e.ok()).find_map(|e| {
        let s: Summary = serde_json::from_str(&std::fs::read_to_string(e.path()).ok()?).ok()?;
        (s.tag == stem).then_some(MeanP50P90 {
            mean: s.rms_mean_m * 1e3,
            p50: s.rms_p50_m * 1e3,
            p90: s.rms_p90_m * 1e3,
        })
    })
}

/// Audits every trial of the datasets that have a Scale setup and a static trial (others are
/// skipped with a note through `log`).
pub fn audit_real(datasets: &[Dataset], reference: &Path, log: &dyn Fn(&str)) -> Vec<RealAudit> {
    let mut out = Vec::new();
    for (i, d) in datasets.iter().enumerate() {
        let (Some(setup_path), Some(root)) = (&d.scale_setup, &d.root) else { continue };
        if d.synthetic.is_some() || !root.is_dir() {
            log(&format!("note: audit: dataset '{}' skipped (root absent)", d.name));
            continue;
        }
        match audit_dataset(i, d, root, setup_path, reference) {
            Ok(mut v) => out.append(&mut v),
            Err(e) => log(&format!("note: audit: dataset '{}' failed: {e:#}", d.name)),
        }
    }
    out
}

fn audit_dataset(
    i: usize,
    d: &Dataset,
    root: &Path,
    setup_path: &Path,
    reference: &Path,
) -> anyhow::Result<Vec<RealAudit>> {
    let setup = crate::io::osim::read_scale_setup(setup_path)?;
    let mut out = Vec::new();
    for g in discover(i, d, root)? {
        let sub = prepare_subject(&d.subject_files(g.static_trial.clone()))?;
        let Some(static_path) = &sub.static_path else {
            anyhow::bail!("subject {} has no static trial", g.subject);
        };
        let input = d.input_options();
        let (st, _) = read_trial(&sub.ctx, static_path, &input)?;
        let statics = [("static", &st)];
        // The joint method calibrates as `solve` does: the static trial and the motion trials
        // together; the stage-wise baseline scales from the static trial alone (OpenSim's way).
        let trials: Vec<(String, crate::io::MarkerTrial)> = g
            .trials
            .iter()
            .map(|t| read_trial(&sub.ctx, &t.path, &input).map(|(m, _)| (t.rel.clone(), m)))
            .collect::<Result<_, _>>()?;
        let motions: Vec<(&str, &crate::io::MarkerTrial)> = trials.iter().map(|(n, m)| (n.as_str(), m)).collect();
        let (cal_j, placed_j) = calibrate_placed_with(&sub.ctx, &statics, &motions)?;
        let ctx_j = placed_j.unwrap_or_else(|| sub.ctx.clone());
        let scale = stagewise::measure(&sub.ctx, &st, &setup.measurements, &setup.manual_scales);
        let pinned = stagewise::pinned(&sub.ctx, &scale);
        let (cal_s, placed_s) = calibrate_placed(&pinned, &statics)?;
        // Placing markers rebuilds the proxy map from the profile: pin the factors again.
        let ctx_s = placed_s.map_or_else(|| pinned.clone(), |c| stagewise::pinned(&c, &scale));
        let names = |cal: &[f64]| -> Vec<(String, f64)> {
            sub.ctx
                .proxy
                .proxies
                .iter()
                .enumerate()
                .filter(|(_, p)| p.kind == crate::model::proxy::ProxyKind::Scale)
                .map(|(k, p)| (p.name.clone(), cal[k]))
                .collect()
        };
        for (t, (_, m)) in g.trials.iter().zip(&trials) {
            let rj = solve_trial(&ctx_j, &t.rel, m, &cal_j, 1)?;
            let rs = solve_trial(&ctx_s, &t.rel, m, &cal_s, 1)?;
            let stem = Path::new(&t.rel).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            out.push(RealAudit {
                dataset: d.name.clone(),
                trial: t.rel.clone(),
                frames: m.n_frames(),
                joint_rmse_mm: rmse(&rj),
                stagewise_rmse_mm: rmse(&rs),
                opensim_rmse_mm: opensim(reference, &d.name, &stem),
                stagewise_scales: names(&cal_s.proxies),
                joint_scales: names(&cal_j.proxies),
                notes: scale.notes.clone(),
            });
        }
    }
    Ok(out)
}
