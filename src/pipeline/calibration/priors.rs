//! The subject-level terms of a calibration: the anthropometric prior (body dimensions against
//! the survey, conditioned on height, mass and sex), the stature-ratio and anisotropy terms, the
//! report of the calibrated scales against them, and the units check that refuses a marker cloud
//! a thousand times the model's size.

use crate::model::anthropometry::{resolve, stature_ratio, Survey};
use crate::pipeline::context::Context;
use crate::pipeline::input::trial::TrialError;
use crate::solve::prior::{measure, Anisotropy, Anthropometric, GlobalTerm, PriorReport, ScaleReport, ScaleToward};
use crate::solve::Calibration;
use nalgebra::{DVector, Vector3};

/// The subject-level terms of `ctx`'s calibration, and how to report against them.
pub(crate) struct Priors {
    pub(crate) terms: Vec<Box<dyn GlobalTerm>>,
    pub(crate) anthro: Option<Anthropometric>,
    /// Per scale unknown: prior mean and sd of the stature-ratio prior (used where no dimension
    /// governs the scale).
    pub(crate) ratio: f64,
    pub(crate) landmarks: Option<String>,
    pub(crate) stature_dim: Option<usize>,
    pub(crate) stature_ratio: f64,
}

impl Priors {
    /// Every term, the anthropometric one included, for the solver to sum.
    pub(crate) fn all(&self) -> Vec<&dyn GlobalTerm> {
        self.terms.iter().map(|t| t.as_ref()).chain(self.anthro.as_ref().map(|a| a as &dyn GlobalTerm)).collect()
    }
}

/// The priors with their weights for marker noise `noise_m` (m) and `frames` calibration frames.
pub(crate) fn priors(ctx: &Context, scale: &[usize], noise_m: f64, frames: usize) -> Result<Priors, TrialError> {
    let s = &ctx.settings;
    let ns = scale.len();
    let noise2 = noise_m.powi(2) * s.prior_fraction * frames as f64;
    let mut terms: Vec<Box<dyn GlobalTerm>> = Vec::new();
    let mut ratio = 1.0;
    let mut anthro = None;
    let (mut stature_dim, mut stat_ratio) = (None, 1.0);
    let landmarks = ctx.landmarks.as_ref().map(|(n, _)| n.clone());
    let p_neutral = ctx.proxy.default_proxies();
    if let Some((name, lm)) = ctx.landmarks.as_ref().filter(|_| s.anthropometric_weight > 0.0) {
        let survey = Survey::ansur2();
        let dims = resolve(lm, &ctx.model, &survey, name)?;
        let up = ctx.up.unwrap_or_else(Vector3::z);
        let rows: Vec<Vec<(usize, f64)>> = dims.iter().map(|d| d.survey.clone()).collect();
        // κ: survey value per model value at the generic subject the model represents.
        let (generic_mean, _) = survey.conditioned(&rows, &lm.generic);
        let at_one = measure(&ctx.model, &ctx.proxy, &dims, &up, &p_neutral);
        let kappa: Vec<f64> = generic_mean.iter().zip(&at_one).map(|(g, d)| g / d).collect();
        let (mean, mut cov) = survey.conditioned(&rows, &ctx.subject);
        // Model-to-survey mismatch of the landmarks: 10 mm on every dimension (also keeps the
        // covariance regular when a dimension is the known stature itself).
        for d in 0..dims.len() {
            cov[(d, d)] += 0.01f64.powi(2);
        }
        let sd: Vec<f64> = (0..dims.len()).map(|d| cov[(d, d)].sqrt()).collect();
        let cov_inv = cov
            .clone()
            .try_inverse()
            .unwrap_or_else(|| nalgebra::DMatrix::from_diagonal(&cov.map_diagonal(|v| 1.0 / v)));
        stature_dim = dims.iter().position(|d| d.name == lm.stature_from);
        if let Some(i) = stature_dim {
            stat_ratio = stature_ratio(&survey, &dims[i], ctx.subject.sex);
            // Stature ratio of the subject to the generic model, for the unmeasured scales.
            let subject_stature = mean[i] * stat_ratio;
            let generic_stature = lm.generic.height_m.unwrap_or(generic_mean[i] * stat_ratio);
            ratio = subject_stature / generic_stature;
        }
        anthro = Some(Anthropometric {
            model: ctx.model.clone(),
            proxy: ctx.proxy.clone(),
            dims,
            up,
            kappa,
            mean: DVector::from_iterator(mean.len(), mean.iter().copied()),
            cov_inv,
            sd,
            weight: s.anthropometric_weight * noise2,
        });
    }
    // Weak pull toward 1 on every scale, and the stature-ratio prior on scales no dimension
    // governs.
    let governed = anthro.as_ref().map(|a| governing(a, &p_neutral, scale)).unwrap_or_else(|| vec![None; ns]);
    let mut toward = ScaleToward { target: vec![1.0; ns], weight: vec![s.calibration_scale_prior; ns] };
    for i in 0..ns {
        if governed[i].is_none() && anthro.is_some() {
            toward.target[i] = ratio;
            toward.weight[i] = noise2 / s.scale_prior_sd.powi(2);
        }
    }
    terms.push(Box::new(toward));
    // Anisotropy: pairs of axes of one body's `xyz` scale group.
    let mut pairs = Vec::new();
    let names: Vec<&str> = scale.iter().map(|&k| ctx.proxy.proxies[k].name.as_str()).collect();
    for (i, n) in names.iter().enumerate() {
        if let Some(stem) = n.strip_suffix("_x") {
            for suffix in ["_y", "_z"] {
                if let Some(j) = names.iter().position(|m| *m == format!("{stem}{suffix}")) {
                    pairs.push((i, j));
                }
            }
        } else if let Some(stem) = n.strip_suffix("_y") {
            if let Some(j) = names.iter().position(|m| *m == format!("{stem}_z")) {
                pairs.push((i, j));
            }
        }
    }
    if !pairs.is_empty() && s.anisotropy_sd > 0.0 {
        terms.push(Box::new(Anisotropy { pairs, weight: noise2 / s.anisotropy_sd.powi(2) }));
    }
    Ok(Priors { terms, anthro, ratio, landmarks, stature_dim, stature_ratio: stat_ratio })
}

/// For each scale unknown, the dimension it governs most (largest relative sensitivity
/// `∂log d/∂log s` above 0.2), if any.
pub(crate) fn governing(a: &Anthropometric, p: &[f64], scale: &[usize]) -> Vec<Option<usize>> {
    let base = a.measure(p);
    let mut q = p.to_vec();
    scale
        .iter()
        .map(|&k| {
            let v = q[k];
            q[k] = v * 1.01;
            let up = a.measure(&q);
            q[k] = v;
            let sens: Vec<f64> = up.iter().zip(&base).map(|(u, b)| ((u - b) / b).abs() / 0.01).collect();
            let (best, s) =
                sens.iter().copied().enumerate().fold((0, 0.0), |m, (i, s)| if s > m.1 { (i, s) } else { m });
            (s > 0.2).then_some(best)
        })
        .collect()
}

pub(crate) fn prior_report(ctx: &Context, pri: &Priors, scale: &[usize], cal: &Calibration) -> PriorReport {
    let p = &cal.proxies;
    let mut neutral = ctx.proxy.default_proxies();
    for &k in scale {
        neutral[k] = p[k];
    }
    let (values, governed) = match &pri.anthro {
        Some(a) => (a.survey_values(&neutral), governing(a, &ctx.proxy.default_proxies(), scale)),
        None => (Vec::new(), vec![None; scale.len()]),
    };
    let scales = scale
        .iter()
        .zip(&governed)
        .map(|(&k, gov)| {
            let px = &ctx.proxy.proxies[k];
            let v = p[k];
            let width = (px.range.1 - px.range.0).abs();
            let at_bound =
                (v - px.range.0).abs() < 1e-3 * width.max(1e-9) || (px.range.1 - v).abs() < 1e-3 * width.max(1e-9);
            let (z, dimension) = match (gov, &pri.anthro) {
                (Some(d), Some(a)) => ((values[*d] - a.mean[*d]) / a.sd[*d], Some(a.dims[*d].name.clone())),
                _ => ((v - pri.ratio) / ctx.settings.scale_prior_sd, None),
            };
            ScaleReport { name: px.name.clone(), value: v, range: px.range, at_bound, z, dimension }
        })
        .collect();
    let dimensions = pri
        .anthro
        .as_ref()
        .map(|a| a.dims.iter().enumerate().map(|(i, d)| (d.name.clone(), values[i], a.mean[i], a.sd[i])).collect())
        .unwrap_or_default();
    PriorReport {
        landmarks: pri.landmarks.clone(),
        subject: ctx.subject,
        stature_m: pri.stature_dim.map(|i| values[i] * pri.stature_ratio),
        scales,
        dimensions,
    }
}

/// Fails a trial whose marker cloud is far larger or smaller than the model's: the data's
/// units are then almost certainly not what was read (millimetres read as metres: ×1000).
pub(crate) fn units_check(
    ctx: &Context,
    name: &str,
    obs: &[f64],
    stride: usize,
    weights: &[f64],
    p0: &[f64],
) -> Result<(), TrialError> {
    let y = ctx.proxy.state(p0);
    let mut ws = crate::kinematics::cpu::Workspace::new(&ctx.model);
    crate::kinematics::cpu::forward(&ctx.model, &y, &mut ws);
    let spread = |pts: &[Vector3<f64>]| {
        let c = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
        (pts.iter().map(|p| (p - c).norm_squared()).sum::<f64>() / pts.len() as f64).sqrt()
    };
    let mut ratios = Vec::new();
    let n = obs.len() / stride.max(1);
    for f in (0..n).step_by((n / 20).max(1)) {
        let o = &obs[f * stride..(f + 1) * stride];
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for m in 0..stride / 3 {
            if weights[m] > 0.0 && o[3 * m..3 * m + 3].iter().all(|v| v.is_finite()) {
                a.push(Vector3::new(o[3 * m], o[3 * m + 1], o[3 * m + 2]));
                b.push(ws.marker(m));
            }
        }
        if a.len() >= 4 {
            let (sa, sb) = (spread(&a), spread(&b));
            if sb > 0.0 {
                ratios.push(sa / sb);
            }
        }
    }
    if ratios.is_empty() {
        return Ok(());
    }
    ratios.sort_by(f64::total_cmp);
    let r = ratios[ratios.len() / 2];
    if (0.2..=5.0).contains(&r) {
        return Ok(());
    }
    let hint = [
        (1000.0f64, "millimetres read as metres"),
        (100.0, "centimetres read as metres"),
        (10.0, "millimetres read as centimetres"),
        (0.1, "centimetres read as millimetres"),
        (0.01, "metres read as centimetres"),
        (0.001, "metres read as millimetres"),
    ]
    .iter()
    .min_by(|a, b| {
        (crate::model::math::ln(r) - crate::model::math::ln(a.0))
            .abs()
            .total_cmp(&(crate::model::math::ln(r) - crate::model::math::ln(b.0)).abs())
    })
    .map(|h| h.1)
    .unwrap_or("wrong units");
    Err(TrialError::Implausible {
        trial: name.into(),
        message: format!(
            "its markers spread {r:.3e} times as far as the model's: the data look like {hint}; give the right --units"
        ),
    })
}
