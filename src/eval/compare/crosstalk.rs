//! Knee cross-talk: a knee "adduction" (varus/valgus) that follows the knee's flexion, the mark
//! of a flexion axis turned about the thigh's long axis (a thigh wand or knee marker set by eye;
//! Baker's analysis). For a thigh turned by θ, the angles measured about the turned axes are the
//! true ones rotated by θ in the flexion–adduction plane:
//!
//! `flexion' = cos θ · flexion − sin θ · adduction`, `adduction' = sin θ · flexion + cos θ · adduction`
//!
//! (for small adduction, `adduction' ≈ adduction + sin θ · flexion`, `flexion' ≈ cos θ · flexion`).
//! The axis error is the θ whose inverse rotation leaves the corrected adduction uncorrelated with
//! the corrected flexion over the trial: in closed form, `θ = ½ atan2(2 S_fa, S_ff − S_aa)` of the
//! (co)variances `S`, the principal axis of the flexion–adduction cloud.
//!
//! Which coordinates are a knee's flexion and adduction comes from the angle map: the entries
//! reading components 0 and 1 of the same knee point ([`knee_pairs`]).

use super::load::AngleMap;
use super::{Comparison, Motion};
use serde::{Deserialize, Serialize};

/// A knee's flexion and adduction coordinates.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KneePair {
    /// The side, from the flexion coordinate's suffix (`r` of `knee_angle_r`).
    pub side: String,
    pub flexion: String,
    pub adduction: String,
}

/// The knee pairs of `map`: an entry reading component 0 (flexion) of a point whose name holds
/// `Knee`, with the entry reading component 1 (adduction) of the same points.
pub fn knee_pairs(map: &AngleMap) -> Vec<KneePair> {
    map.angle
        .iter()
        .filter(|e| e.component == 0 && e.points.iter().any(|p| p.to_ascii_lowercase().contains("knee")))
        .filter_map(|f| {
            let a = map.angle.iter().find(|a| a.component == 1 && a.points == f.points)?;
            let side = f.coordinate.rsplit_once('_').map_or(f.coordinate.as_str(), |(_, s)| s).to_string();
            Some(KneePair { side, flexion: f.coordinate.clone(), adduction: a.coordinate.clone() })
        })
        .collect()
}

/// How much a knee's adduction follows its flexion over a trial.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    /// Frames where both angles are known.
    pub frames: usize,
    /// Pearson correlation of adduction with flexion (NaN when either is constant).
    pub r: f64,
    /// Least-squares slope of adduction on flexion (°/°).
    pub slope: f64,
    /// The estimated turn of the flexion axis about the thigh (degrees; + where adduction rises
    /// with flexion).
    pub axis_error_deg: f64,
}

/// The cross-talk fit of `adduction` on `flexion` (degrees, frame by frame; frames where either
/// is NaN are left out); `None` with fewer than three frames or a constant flexion.
pub fn fit(flexion: &[f64], adduction: &[f64]) -> Option<Fit> {
    let pairs: Vec<(f64, f64)> =
        flexion.iter().zip(adduction).map(|(f, a)| (*f, *a)).filter(|(f, a)| f.is_finite() && a.is_finite()).collect();
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let mf = pairs.iter().map(|p| p.0).sum::<f64>() / n;
    let ma = pairs.iter().map(|p| p.1).sum::<f64>() / n;
    let (mut sff, mut saa, mut sfa) = (0.0, 0.0, 0.0);
    for (f, a) in &pairs {
        sff += (f - mf) * (f - mf);
        saa += (a - ma) * (a - ma);
        sfa += (f - mf) * (a - ma);
    }
    if sff <= 0.0 {
        return None;
    }
    let r = if saa > 0.0 { sfa / (sff * saa).sqrt() } else { f64::NAN };
    let axis_error_deg = 0.5 * (2.0 * sfa).atan2(sff - saa).to_degrees();
    Some(Fit { frames: pairs.len(), r, slope: sfa / sff, axis_error_deg })
}

/// `(flexion, adduction)` turned back by `axis_error_deg`: the angles about the axis the fit
/// says was meant.
pub fn turned_back(flexion: f64, adduction: f64, axis_error_deg: f64) -> (f64, f64) {
    let (s, c) = axis_error_deg.to_radians().sin_cos();
    (c * flexion + s * adduction, -s * flexion + c * adduction)
}

/// One knee's cross-talk in one motion.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CrossTalk {
    pub side: String,
    pub flexion: String,
    pub adduction: String,
    #[serde(flatten)]
    pub fit: Fit,
    /// The correlation left once the angles are turned back by the axis error (≈ 0).
    pub r_corrected: f64,
}

/// The cross-talk of each knee of `pairs` that `m` has both angles of.
pub fn knee_cross_talk(m: &Motion, pairs: &[KneePair]) -> Vec<CrossTalk> {
    pairs
        .iter()
        .filter_map(|p| {
            let (f, a) = (&m.get(&p.flexion)?.values, &m.get(&p.adduction)?.values);
            let fit = fit(f, a)?;
            let (cf, ca): (Vec<f64>, Vec<f64>) =
                f.iter().zip(a).map(|(f, a)| turned_back(*f, *a, fit.axis_error_deg)).unzip();
            let r_corrected = self::fit(&cf, &ca).map_or(f64::NAN, |x| x.r);
            Some(CrossTalk {
                side: p.side.clone(),
                flexion: p.flexion.clone(),
                adduction: p.adduction.clone(),
                fit,
                r_corrected,
            })
        })
        .collect()
}

/// `m` with the knees of `found` turned back by their axis errors (flexion and adduction both;
/// a frame missing either angle is missing both).
pub fn corrected(m: &Motion, found: &[CrossTalk]) -> Motion {
    let mut out = m.clone();
    for ct in found {
        let (Some(f), Some(a)) = (m.get(&ct.flexion), m.get(&ct.adduction)) else { continue };
        let (cf, ca): (Vec<f64>, Vec<f64>) = f
            .values
            .iter()
            .zip(&a.values)
            .map(|(f, a)| match f.is_finite() && a.is_finite() {
                true => turned_back(*f, *a, ct.fit.axis_error_deg),
                false => (f64::NAN, f64::NAN),
            })
            .unzip();
        for s in &mut out.series {
            if s.name == ct.flexion {
                s.values = cf.clone();
            } else if s.name == ct.adduction {
                s.values = ca.clone();
            }
        }
    }
    out.source = format!("{} (knee axes turned back)", m.source);
    out
}

/// Both sides' knee cross-talk.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct CrossTalkReport {
    pub reference: Vec<CrossTalk>,
    pub ours: Vec<CrossTalk>,
    /// The knee pairs looked for (`flexion/adduction`), for a report that finds none on a side.
    pub looked_for: Vec<String>,
}

impl CrossTalkReport {
    /// Both sides analysed with the knee pairs of `map`.
    pub fn of(ours: &Motion, reference: &Motion, map: &AngleMap) -> CrossTalkReport {
        let pairs = knee_pairs(map);
        CrossTalkReport {
            reference: knee_cross_talk(reference, &pairs),
            ours: knee_cross_talk(ours, &pairs),
            looked_for: pairs.iter().map(|p| format!("{}/{}", p.flexion, p.adduction)).collect(),
        }
    }

    /// Whether neither side has a knee with both angles.
    pub fn is_empty(&self) -> bool {
        self.reference.is_empty() && self.ours.is_empty()
    }
}

/// A comparison with its knee cross-talk and, on request, the comparison against the reference
/// with its knee axes turned back (the JSON of `smocap compare`: the comparison's fields, then
/// `cross_talk` and `corrected` when there are any).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Diagnosed {
    #[serde(flatten)]
    pub comparison: Comparison,
    #[serde(default, skip_serializing_if = "CrossTalkReport::is_empty")]
    pub cross_talk: CrossTalkReport,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corrected: Option<Comparison>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turned_axis_is_found_and_turned_back() {
        let n = 400;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / n as f64 * std::f64::consts::TAU).collect();
        let flex: Vec<f64> = t.iter().map(|t| 30.0 - 30.0 * t.cos()).collect();
        let add: Vec<f64> = t.iter().map(|t| 2.0 * (3.0 * t).sin()).collect();
        let (s, c) = 12.0f64.to_radians().sin_cos();
        let f2: Vec<f64> = flex.iter().zip(&add).map(|(f, a)| c * f - s * a).collect();
        let a2: Vec<f64> = flex.iter().zip(&add).map(|(f, a)| s * f + c * a).collect();
        let x = fit(&f2, &a2).unwrap();
        assert!((x.axis_error_deg - 12.0).abs() < 1e-6, "{x:?}");
        assert!(x.r > 0.9 && (x.slope - 12.0f64.to_radians().tan()).abs() < 0.01, "{x:?}");
        let (bf, ba) = turned_back(f2[7], a2[7], x.axis_error_deg);
        assert!((bf - flex[7]).abs() < 1e-6 && (ba - add[7]).abs() < 1e-6);
    }
}
