//! The subject-level terms of calibration (mink style: each a small type that adds its part of
//! the objective, gradient and Gauss–Newton Hessian; the calibration solver only sums them).
//!
//! They act on the calibration's global unknowns `z = [s; o]`: the scale proxies `s` (in the
//! order of [`Globals::scale`]) and the registered markers' unit-scale body-frame offsets `o`
//! (m, three per registered marker). Energies are in the marker objective's units (m², the
//! objective being `½ Σ w‖r‖²`): a prior in standard deviations is multiplied by `σ_n²`, the
//! marker noise ([`crate::solve::SolverSettings::prior_noise_sd_m`]), so that one standard
//! deviation costs what one marker missed by `σ_n` in one frame costs. Derivations:
//! `docs/CALIBRATION.md`.

use crate::kinematics::cpu::{forward, Workspace};
use crate::model::anthropometry::{Along, Dimension};
use crate::model::proxy::ProxyMap;
use crate::model::Model;
use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};

/// The current values of the global unknowns.
pub struct Globals<'a> {
    /// Full proxy vector whose scale entries are the current scales (pose entries: default).
    pub p: &'a [f64],
    /// Proxy index of each scale unknown.
    pub scale: &'a [usize],
    /// Current offset of every model marker (unit-scale body frame, m).
    pub offsets: &'a [Vector3<f64>],
    /// Column of each model marker's offset block in `z` (`None`: not registered).
    pub offset_col: &'a [Option<usize>],
}

/// A term of the subject-level objective.
pub trait GlobalTerm: Send + Sync {
    /// Short name for reports.
    fn name(&self) -> &'static str;
    /// Returns the term's energy at `x`; when `hg` is given, adds its gradient to `g` and its
    /// Gauss–Newton Hessian to `h` (both indexed like `z`).
    fn add(&self, x: &Globals<'_>, hg: Option<(&mut DMatrix<f64>, &mut DVector<f64>)>) -> f64;
}

/// `½ Σ_i w_i (s_i − t_i)²` on scale unknowns: the weak pull toward 1 that keeps unobservable
/// scales determined, and the stature-ratio prior of bodies no survey dimension measures.
#[derive(Clone, Debug)]
pub struct ScaleToward {
    pub target: Vec<f64>,
    pub weight: Vec<f64>,
}

impl GlobalTerm for ScaleToward {
    fn name(&self) -> &'static str {
        "scale_toward"
    }
    fn add(&self, x: &Globals<'_>, mut hg: Option<(&mut DMatrix<f64>, &mut DVector<f64>)>) -> f64 {
        let mut e = 0.0;
        for (i, &k) in x.scale.iter().enumerate() {
            let (w, d) = (self.weight[i], x.p[k] - self.target[i]);
            e += 0.5 * w * d * d;
            if let Some((h, g)) = hg.as_mut() {
                h[(i, i)] += w;
                g[i] += w * d;
            }
        }
        e
    }
}

/// `½ w Σ (s_a − s_b)²` over pairs of scale unknowns: the axes of one body's scale (`xyz`
/// groups) kept close, so that a body does not stretch along one axis to absorb marker error.
#[derive(Clone, Debug)]
pub struct Anisotropy {
    pub pairs: Vec<(usize, usize)>,
    pub weight: f64,
}

impl GlobalTerm for Anisotropy {
    fn name(&self) -> &'static str {
        "anisotropy"
    }
    fn add(&self, x: &Globals<'_>, mut hg: Option<(&mut DMatrix<f64>, &mut DVector<f64>)>) -> f64 {
        let mut e = 0.0;
        for &(a, b) in &self.pairs {
            let d = x.p[x.scale[a]] - x.p[x.scale[b]];
            e += 0.5 * self.weight * d * d;
            if let Some((h, g)) = hg.as_mut() {
                let w = self.weight;
                h[(a, a)] += w;
                h[(b, b)] += w;
                h[(a, b)] -= w;
                h[(b, a)] -= w;
                g[a] += w * d;
                g[b] -= w * d;
            }
        }
        e
    }
}

/// `½ Σ_m κ_m ‖o_m − o_m⁰‖²` over registered markers: offsets stay near the model's, strongly
/// for anatomical markers, weakly for tracking markers (`κ_m = σ_n² / σ_m²`).
#[derive(Clone, Debug)]
pub struct OffsetPrior {
    pub reference: Vec<Vector3<f64>>,
    pub weight: Vec<f64>,
}

impl GlobalTerm for OffsetPrior {
    fn name(&self) -> &'static str {
        "offset_prior"
    }
    fn add(&self, x: &Globals<'_>, mut hg: Option<(&mut DMatrix<f64>, &mut DVector<f64>)>) -> f64 {
        let mut e = 0.0;
        for (m, col) in x.offset_col.iter().enumerate() {
            let Some(c) = *col else { continue };
            let d = x.offsets[m] - self.reference[m];
            let w = self.weight[m];
            e += 0.5 * w * d.norm_squared();
            if let Some((h, g)) = hg.as_mut() {
                for a in 0..3 {
                    h[(c + a, c + a)] += w;
                    g[c + a] += w * d[a];
                }
            }
        }
        e
    }
}

/// The anthropometric prior: `½ w σ_n² (κ⊙d(s) − μ)ᵀ Σ⁻¹ (κ⊙d(s) − μ)` over body dimensions
/// `d(s)` measured on the model in its neutral pose, `(μ, Σ)` the survey's distribution
/// conditioned on the subject, `κ` the survey-to-model ratio at the generic subject.
/// `∂d/∂s` by central differences (a few forward-kinematics passes; calibration only).
#[derive(Clone, Debug)]
pub struct Anthropometric {
    pub model: Model,
    pub proxy: ProxyMap,
    pub dims: Vec<Dimension>,
    pub up: Vector3<f64>,
    /// Survey value per model value of each dimension at the generic subject.
    pub kappa: Vec<f64>,
    pub mean: DVector<f64>,
    pub cov_inv: DMatrix<f64>,
    /// Standard deviation of each dimension (m), for z-scores.
    pub sd: Vec<f64>,
    /// `w σ_n²`.
    pub weight: f64,
}

impl Anthropometric {
    /// The dimensions (m, model units) at the proxies `p` in the neutral pose with its scales.
    pub fn measure(&self, p: &[f64]) -> Vec<f64> {
        measure(&self.model, &self.proxy, &self.dims, &self.up, p)
    }

    /// Survey-equivalent dimensions `κ⊙d(s)` (m).
    pub fn survey_values(&self, p: &[f64]) -> Vec<f64> {
        self.measure(p).iter().zip(&self.kappa).map(|(d, k)| d * k).collect()
    }
}

/// Dimensions `dims` on `model` at proxies `p` (pose entries as given: pass the neutral pose).
pub fn measure(model: &Model, proxy: &ProxyMap, dims: &[Dimension], up: &Vector3<f64>, p: &[f64]) -> Vec<f64> {
    let y = proxy.state(p);
    let mut ws = Workspace::new(model);
    forward(model, &y, &mut ws);
    let point = |(b, o): &(usize, Vector3<f64>)| {
        let s = Vector3::new(y[model.scale_index(*b, 0)], y[model.scale_index(*b, 1)], y[model.scale_index(*b, 2)]);
        ws.body_pos[*b] + ws.body_rot[*b] * s.component_mul(o)
    };
    dims.iter()
        .map(|d| {
            let v = point(&d.a) - point(&d.b);
            match d.along {
                Along::Distance => v.norm(),
                Along::Up => v.dot(up),
            }
        })
        .collect()
}

impl GlobalTerm for Anthropometric {
    fn name(&self) -> &'static str {
        "anthropometric"
    }
    fn add(&self, x: &Globals<'_>, hg: Option<(&mut DMatrix<f64>, &mut DVector<f64>)>) -> f64 {
        let n = self.dims.len();
        let v = DVector::from_vec(self.survey_values(x.p));
        let r = &v - &self.mean;
        let e = 0.5 * self.weight * (r.transpose() * &self.cov_inv * &r)[(0, 0)];
        if let Some((h, g)) = hg {
            let ns = x.scale.len();
            let mut jac = DMatrix::zeros(n, ns);
            let mut p = x.p.to_vec();
            for (i, &k) in x.scale.iter().enumerate() {
                let step = 1e-6;
                let v0 = p[k];
                p[k] = v0 + step;
                let hi = self.survey_values(&p);
                p[k] = v0 - step;
                let lo = self.survey_values(&p);
                p[k] = v0;
                for d in 0..n {
                    jac[(d, i)] = (hi[d] - lo[d]) / (2.0 * step);
                }
            }
            let jt_ci = jac.transpose() * &self.cov_inv * self.weight;
            let hh = &jt_ci * &jac;
            let gg = &jt_ci * &r;
            for i in 0..ns {
                g[i] += gg[i];
                for j in 0..ns {
                    h[(i, j)] += hh[(i, j)];
                }
            }
        }
        e
    }
}

/// One scale factor of the calibrated subject against the prior.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ScaleReport {
    /// Scale proxy name.
    pub name: String,
    pub value: f64,
    /// Allowed range.
    pub range: (f64, f64),
    /// Whether the value sits at an end of its range (a suspect fit).
    pub at_bound: bool,
    /// Standard score against the prior: of the survey dimension this scale governs most, or
    /// of the stature-ratio prior for bodies no dimension measures.
    pub z: f64,
    /// The dimension the z-score is of (`None`: the stature-ratio prior).
    pub dimension: Option<String>,
}

/// What the priors say of a calibration (for the report).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PriorReport {
    /// Landmark file used (`None`: no anthropometric prior for this model).
    pub landmarks: Option<String>,
    pub subject: crate::model::anthropometry::SubjectInfo,
    /// Calibrated stature estimate (m), from the landmark file's stature dimension.
    pub stature_m: Option<f64>,
    pub scales: Vec<ScaleReport>,
    /// Survey dimensions `(name, value m, prior mean m, prior sd m)`.
    pub dimensions: Vec<(String, f64, f64, f64)>,
}
