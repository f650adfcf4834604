//! Where each method's error comes from: per driven rotational coordinate the RMS joint-angle
//! error over the motion frames, per scale group the factor error; per subject
//! ([`Detail`]) and pooled over the subjects ([`Breakdown`]).

use super::SubjectAudit;
use crate::model::proxy::ProxyKind;
use crate::model::CoordinateKind;
use crate::pipeline::Context;
use serde::{Deserialize, Serialize};

/// One method's errors on one subject, itemised.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Detail {
    /// Per driven rotational coordinate ([`Breakdown::coordinates`] order): RMS over the motion
    /// frames of the angle error (deg).
    pub coordinate_deg: Vec<f64>,
    /// Per driven rotational coordinate: the mean over the motion frames of the angle error
    /// (deg), the part of it that is a constant offset.
    #[serde(default)]
    pub coordinate_bias_deg: Vec<f64>,
    /// Per scale group ([`Breakdown::scales`] order): `ŝ − s` in %.
    pub scale_pct: Vec<f64>,
}

/// One row of the pooled breakdown: RMS over the subjects (and frames) of both methods' errors.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Row {
    pub name: String,
    pub joint: f64,
    pub stagewise: f64,
    /// Coordinates: the RMS over the subjects of each method's constant offset (deg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_bias: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stagewise_bias: Option<f64>,
}

/// Both methods' errors pooled over the audited subjects, per coordinate (deg) and per scale
/// group (%).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Breakdown {
    pub coordinates: Vec<Row>,
    pub scales: Vec<Row>,
}

/// The driven rotational coordinates the audit scores (model order).
pub fn driven_coordinates(ctx: &Context) -> Vec<usize> {
    let model = &ctx.model;
    (0..model.nq())
        .filter(|&c| model.coordinates[c].kind == CoordinateKind::Rotational && !ctx.proxy.y_terms[c].is_empty())
        .collect()
}

/// The scale proxies (proxy order).
pub fn scale_proxies(ctx: &Context) -> Vec<usize> {
    (0..ctx.proxy.np()).filter(|&k| ctx.proxy.proxies[k].kind == ProxyKind::Scale).collect()
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

/// Pools the subjects' details (RMS over subjects of each coordinate's per-subject RMS, which
/// is the RMS over all frames as every subject has the same number of frames).
pub fn pool(ctx: &Context, subjects: &[SubjectAudit]) -> Breakdown {
    let coords = driven_coordinates(ctx);
    let scales = scale_proxies(ctx);
    let row = |name: &str, i: usize, f: fn(&Detail) -> &Vec<f64>| Row {
        name: name.into(),
        joint: rms(subjects.iter().filter_map(|s| f(&s.joint_detail).get(i).copied())),
        stagewise: rms(subjects.iter().filter_map(|s| f(&s.stagewise_detail).get(i).copied())),
        joint_bias: None,
        stagewise_bias: None,
    };
    let bias = |d: &Detail, i: usize| d.coordinate_bias_deg.get(i).copied();
    Breakdown {
        coordinates: coords
            .iter()
            .enumerate()
            .map(|(i, &c)| Row {
                joint_bias: Some(rms(subjects.iter().filter_map(|s| bias(&s.joint_detail, i)))),
                stagewise_bias: Some(rms(subjects.iter().filter_map(|s| bias(&s.stagewise_detail, i)))),
                ..row(&ctx.model.coordinates[c].name, i, |d| &d.coordinate_deg)
            })
            .collect(),
        scales: scales.iter().enumerate().map(|(i, &k)| row(&ctx.proxy.proxies[k].name, i, |d| &d.scale_pct)).collect(),
    }
}

impl Breakdown {
    /// A table: per coordinate (deg) then per scale group (%), joint / stage-wise.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:<24} {:>9} {:>9} {:>11} {:>11}\n",
            "coordinate (deg RMS)", "joint", "stage", "joint bias", "stage bias"
        );
        for r in &self.coordinates {
            s += &format!(
                "{:<24} {:>9.2} {:>9.2} {:>11.2} {:>11.2}\n",
                r.name,
                r.joint,
                r.stagewise,
                r.joint_bias.unwrap_or(f64::NAN),
                r.stagewise_bias.unwrap_or(f64::NAN)
            );
        }
        s += &format!("{:<24} {:>9} {:>9}\n", "scale group (% RMS)", "joint", "stage");
        for r in &self.scales {
            s += &format!("{:<24} {:>9.2} {:>9.2}\n", r.name, r.joint, r.stagewise);
        }
        s
    }
}
