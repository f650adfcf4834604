//! The stage-wise baseline's scaling step, with OpenSim's Scale tool semantics: each measurement's
//! factor is the mean over its marker pairs of (distance between the pair's markers averaged over
//! the static trial's frames) / (distance on the unscaled model in its default pose), applied to
//! the body axes it names; manual factors follow (OpenSim's usual `measurements manualScale`
//! order). The factors are then frozen: every scale proxy is pinned (range and default) to the
//! mean factor of the body axes it drives, so calibration and trial solves move the pose only.

use crate::io::osim::Measurement;
use crate::io::MarkerTrial;
use crate::kinematics::cpu::{self, Workspace};
use crate::model::proxy::ProxyKind;
use crate::pipeline::input::trial::match_markers;
use crate::pipeline::Context;

/// Marker pairs of the shipped model (`models/fullbody.xml`) per scale group of its profile, as a
/// typical OpenSim scale setup chooses them: landmarks on the segment, or at the joints that bound
/// it (so most pairs span one segment and are nearly pose-independent in a standing pose).
/// One scale group of the shipped model: its name, its bodies, and the marker pairs measuring it.
type PairTable = (&'static str, &'static [&'static str], &'static [(&'static str, &'static str)]);

const SHIPPED: &[PairTable] = &[
    ("pelvis", &["pelvis"], &[("RASI", "LASI"), ("RPSI", "LPSI"), ("RASI", "RPSI"), ("LASI", "LPSI")]),
    ("lumbar", &["lumbar5", "lumbar4", "lumbar3", "lumbar2", "lumbar1"], &[("SACR", "L3"), ("L3", "T10")]),
    ("torso", &["torso"], &[("C7", "T10"), ("CLAV", "STRN"), ("LSHO", "RSHO")]),
    ("head", &["head"], &[("LFHD", "LBHD"), ("RFHD", "RBHD"), ("LFHD", "RFHD")]),
    ("humerus_r", &["humerus_r"], &[("RSHO", "RELB"), ("RELB", "RMEL")]),
    ("humerus_l", &["humerus_l"], &[("LSHO", "LELB"), ("LELB", "LMEL")]),
    ("forearm_r", &["ulna_r", "radius_r"], &[("RELB", "RWRA"), ("RMEL", "RWRB"), ("RWRA", "RWRB")]),
    ("forearm_l", &["ulna_l", "radius_l"], &[("LELB", "LWRA"), ("LMEL", "LWRB"), ("LWRA", "LWRB")]),
    ("hand_r", &["hand_r"], &[("RWRA", "RFIN"), ("RWRB", "RMH5")]),
    ("hand_l", &["hand_l"], &[("LWRA", "LFIN"), ("LWRB", "LMH5")]),
    ("femur_r", &["femur_r"], &[("RASI", "RKNE"), ("RKNE", "RKNM")]),
    ("femur_l", &["femur_l"], &[("LASI", "LKNE"), ("LKNE", "LKNM")]),
    ("tibia_r", &["tibia_r"], &[("RKNE", "RANK"), ("RKNM", "RMMA"), ("RANK", "RMMA")]),
    ("tibia_l", &["tibia_l"], &[("LKNE", "LANK"), ("LKNM", "LMMA"), ("LANK", "LMMA")]),
    ("foot_r", &["talus_r", "calcn_r", "toes_r"], &[("RHEE", "RTOE"), ("RHEE", "RMT5")]),
    ("foot_l", &["talus_l", "calcn_l", "toes_l"], &[("LHEE", "LTOE"), ("LHEE", "LMT5")]),
];

/// The measurements for the shipped model (uniform scaling of each profile scale group).
pub fn shipped_measurements() -> Vec<Measurement> {
    SHIPPED
        .iter()
        .map(|(name, bodies, pairs)| Measurement {
            name: (*name).into(),
            pairs: pairs.iter().map(|(a, b)| ((*a).into(), (*b).into())).collect(),
            bodies: bodies.iter().map(|b| ((*b).into(), [true; 3])).collect(),
        })
        .collect()
}

/// The factors found, per body and axis (`None`: not scaled), with notes on skipped pairs.
#[derive(Clone, Debug)]
pub struct StageScale {
    pub body_factors: Vec<[Option<f64>; 3]>,
    pub notes: Vec<String>,
}

/// Scales as OpenSim's Scale tool does from `static_trial` (in the model's frame and units).
pub fn measure(
    ctx: &Context,
    static_trial: &MarkerTrial,
    measurements: &[Measurement],
    manual: &[(String, [f64; 3])],
) -> StageScale {
    let model = &ctx.model;
    let mut notes = Vec::new();
    let mut ws = Workspace::new(model);
    cpu::forward(model, &model.default_state(), &mut ws);
    let map = match_markers(ctx, "static", static_trial).map(|m| m.columns).unwrap_or_default();
    // Each model marker's mean position over the static frames where it was seen.
    let mean = |m: usize| -> Option<[f64; 3]> {
        let c = (*map.get(m)?)?;
        let mut sum = [0.0; 3];
        let mut n = 0usize;
        for f in 0..static_trial.n_frames() {
            if let Some(p) = static_trial.position(f, c) {
                (0..3).for_each(|a| sum[a] += p[a]);
                n += 1;
            }
        }
        (n > 0).then(|| sum.map(|s| s / n as f64))
    };
    let dist =
        |a: [f64; 3], b: [f64; 3]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    let model_pos = |m: usize| [ws.markers[3 * m], ws.markers[3 * m + 1], ws.markers[3 * m + 2]];
    let mut body_factors = vec![[None; 3]; model.nb()];
    for meas in measurements {
        let mut ratios = Vec::new();
        for (a, b) in &meas.pairs {
            let (Some(ia), Some(ib)) = (model.marker_index(a), model.marker_index(b)) else {
                notes.push(format!("measurement {}: pair {a}–{b}: marker not in the model, skipped", meas.name));
                continue;
            };
            let (Some(pa), Some(pb)) = (mean(ia), mean(ib)) else {
                notes.push(format!("measurement {}: pair {a}–{b}: not seen in the static trial, skipped", meas.name));
                continue;
            };
            let d0 = dist(model_pos(ia), model_pos(ib));
            if d0 > 1e-9 {
                ratios.push(dist(pa, pb) / d0);
            }
        }
        if ratios.is_empty() {
            notes.push(format!("measurement {}: no usable pair, its bodies keep scale 1", meas.name));
            continue;
        }
        let factor = ratios.iter().sum::<f64>() / ratios.len() as f64;
        for (body, axes) in &meas.bodies {
            let Some(b) = model.body_index(body) else { continue };
            for a in 0..3 {
                if axes[a] {
                    body_factors[b][a] = Some(factor);
                }
            }
        }
    }
    for (body, f) in manual {
        if let Some(b) = model.body_index(body) {
            body_factors[b] = f.map(Some);
        }
    }
    StageScale { body_factors, notes }
}

/// The subject with every scale proxy pinned to the measured factors (the mean over the body axes
/// it drives that a measurement reached; 1 where none did).
pub fn pinned(ctx: &Context, scale: &StageScale) -> Context {
    let mut out = ctx.clone();
    let nq = ctx.model.nq();
    for (k, px) in out.proxy.proxies.iter_mut().enumerate() {
        if px.kind != ProxyKind::Scale {
            continue;
        }
        let f: Vec<f64> = ctx
            .proxy
            .terms
            .iter()
            .filter(|t| t.proxy == k && t.y_index >= nq)
            .filter_map(|t| scale.body_factors[(t.y_index - nq) / 3][(t.y_index - nq) % 3])
            .collect();
        let v = if f.is_empty() { 1.0 } else { f.iter().sum::<f64>() / f.len() as f64 };
        px.default = v;
        px.range = (v, v);
    }
    out
}
