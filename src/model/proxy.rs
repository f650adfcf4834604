//! The proxy map `y = Φ(p)`: how a few control variables `p` drive the coordinates and scale
//! factors `y = [q; s]` of a model, with its analytic Jacobian `J_Φ = ∂Φ/∂p`.
//!
//! Each entry of `y` is `y_j = c_j + Σ_t f_t(p_{k_t})` over its terms `t`: a fixed entry has no
//! term, an identity entry one term `f = x`, a coupled spine coordinate a polynomial of its
//! proxy, and a coordinate coupled in the model (`CoordinateCoupling`) the coupling function of
//! its independent coordinate's proxy. `J_Φ` is stored as its non-zeros, one per term.

use super::profile::{Profile, ScaleAxes};
use super::{CoordinateKind, Function, Model};
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// What a proxy controls, which sets its step bound and units.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProxyKind {
    /// Drives rotational coordinates (rad).
    Rotation,
    /// Drives translational coordinates (m).
    Translation,
    /// Drives scale factors (dimensionless).
    Scale,
}

/// One control variable.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Proxy {
    pub name: String,
    pub kind: ProxyKind,
    /// Allowed range `[lo, hi]`; infinite ends allowed.
    pub range: (f64, f64),
    /// Value at the model's default state.
    pub default: f64,
}

/// One non-zero of `J_Φ`: `y[y_index] += func(p[proxy])`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Term {
    pub y_index: usize,
    pub proxy: usize,
    pub func: Function,
}

/// Errors building a proxy map from a profile.
#[derive(Debug, thiserror::Error)]
pub enum ProxyError {
    #[error("profile names {what} '{name}', which the model does not have (it has: {valid})")]
    Unknown { what: &'static str, name: String, valid: String },
    #[error("coordinate '{0}' is driven twice (by two couplings, or fixed and coupled)")]
    DrivenTwice(String),
    #[error("coupling '{proxy}' lists {coords} coordinates but {coefs} coefficient rows")]
    CouplingShape { proxy: String, coords: usize, coefs: usize },
    #[error("body '{0}' is in two scale groups")]
    ScaledTwice(String),
    #[error(
        "coupled coordinate '{dependent}' depends on '{independent}', which is not driven by a single identity proxy"
    )]
    CouplingSource { dependent: String, independent: String },
    #[error("{what} '{name}' has an invalid range [{lo}, {hi}] (need lo ≤ hi, no NaN)")]
    BadRange { what: &'static str, name: String, lo: f64, hi: f64 },
}

fn check_range(what: &'static str, name: &str, lo: f64, hi: f64) -> Result<(), ProxyError> {
    if lo.is_nan() || hi.is_nan() || lo > hi {
        return Err(ProxyError::BadRange { what, name: name.to_string(), lo, hi });
    }
    Ok(())
}

/// A resolved linear inequality `lo ≤ Σ coef·p_k ≤ hi` on proxies.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ProxyConstraint {
    pub coefficients: Vec<(usize, f64)>,
    pub lo: f64,
    pub hi: f64,
}

impl ProxyConstraint {
    /// `Σ coef·p_k`.
    pub fn value(&self, p: &[f64]) -> f64 {
        self.coefficients.iter().map(|&(k, c)| c * p[k]).sum()
    }
}

/// The map `Φ` from proxies to model state, with its sparsity.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ProxyMap {
    pub proxies: Vec<Proxy>,
    /// Constant part `c_j` of each `y_j`.
    pub offsets: Vec<f64>,
    /// Terms sorted by `y_index`; `y_terms[j]` is the range of `y_j`'s terms.
    pub terms: Vec<Term>,
    pub y_terms: Vec<Range<usize>>,
    /// General linear constraints on the proxies (profile `[[constraint]]`).
    pub constraints: Vec<ProxyConstraint>,
}

impl ProxyMap {
    /// Builds `Φ` for `model` as the profile describes.
    pub fn new(model: &Model, profile: &Profile) -> Result<ProxyMap, ProxyError> {
        let nq = model.nq();
        let mut offsets = model.default_state();
        let mut proxies: Vec<Proxy> = Vec::new();
        let mut terms: Vec<Term> = Vec::new();
        let mut driven = vec![false; model.ny()];

        let coord = |name: &str| {
            model.coordinate_index(name).ok_or_else(|| ProxyError::Unknown {
                what: "coordinate",
                name: name.into(),
                valid: list(model.coordinates.iter().map(|c| c.name.as_str())),
            })
        };
        for (name, value) in &profile.fixed {
            let j = coord(name)?;
            offsets[j] = *value;
            driven[j] = true;
        }
        for c in &profile.couplings {
            if c.coefficients.len() != c.coordinates.len() {
                return Err(ProxyError::CouplingShape {
                    proxy: c.proxy.clone(),
                    coords: c.coordinates.len(),
                    coefs: c.coefficients.len(),
                });
            }
            let k = proxies.len();
            let kind = if c
                .coordinates
                .iter()
                .filter_map(|n| model.coordinate_index(n))
                .all(|j| model.coordinates[j].kind == CoordinateKind::Translational)
            {
                ProxyKind::Translation
            } else {
                ProxyKind::Rotation
            };
            check_range("coupling", &c.proxy, c.range[0], c.range[1])?;
            proxies.push(Proxy { name: c.proxy.clone(), kind, range: (c.range[0], c.range[1]), default: 0.0 });
            for (name, coefs) in c.coordinates.iter().zip(&c.coefficients) {
                let j = coord(name)?;
                if driven[j] {
                    return Err(ProxyError::DrivenTwice(name.clone()));
                }
                driven[j] = true;
                offsets[j] = 0.0;
                terms.push(Term { y_index: j, proxy: k, func: Function::Polynomial { coefficients: coefs.clone() } });
            }
        }
        for c in &model.couplings {
            if driven[c.dependent] {
                return Err(ProxyError::DrivenTwice(model.coordinates[c.dependent].name.clone()));
            }
            driven[c.dependent] = true;
        }
        // Remaining free coordinates: identity proxies (locked ones stay fixed at their default).
        let mut identity_of = vec![None; nq];
        for (j, c) in model.coordinates.iter().enumerate() {
            if driven[j] || c.locked {
                continue;
            }
            let kind = match c.kind {
                CoordinateKind::Rotational => ProxyKind::Rotation,
                CoordinateKind::Translational => ProxyKind::Translation,
            };
            let range = if c.clamped { c.range } else { (f64::NEG_INFINITY, f64::INFINITY) };
            identity_of[j] = Some(proxies.len());
            offsets[j] = 0.0;
            terms.push(Term { y_index: j, proxy: proxies.len(), func: Function::IDENTITY });
            proxies.push(Proxy { name: c.name.clone(), kind, range, default: c.default });
        }
        for c in &model.couplings {
            let k = identity_of[c.independent].ok_or_else(|| ProxyError::CouplingSource {
                dependent: model.coordinates[c.dependent].name.clone(),
                independent: model.coordinates[c.independent].name.clone(),
            })?;
            offsets[c.dependent] = 0.0;
            terms.push(Term { y_index: c.dependent, proxy: k, func: c.func.clone() });
        }
        // Scale groups.
        let mut scaled = vec![false; model.nb()];
        for g in &profile.scale_groups {
            check_range("scale group", &g.name, g.range[0], g.range[1])?;
            let bodies = g
                .bodies
                .iter()
                .map(|n| {
                    model.body_index(n).ok_or_else(|| ProxyError::Unknown {
                        what: "body",
                        name: n.clone(),
                        valid: list(model.bodies.iter().map(|b| b.name.as_str())),
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            let axes: &[(&str, &[usize])] = match g.axes {
                ScaleAxes::Uniform => &[("", &[0, 1, 2])],
                ScaleAxes::Xyz => &[("_x", &[0]), ("_y", &[1]), ("_z", &[2])],
            };
            for &b in &bodies {
                if scaled[b] {
                    return Err(ProxyError::ScaledTwice(model.bodies[b].name.clone()));
                }
                scaled[b] = true;
            }
            for (suffix, dims) in axes {
                let k = proxies.len();
                proxies.push(Proxy {
                    name: format!("{}{}", g.name, suffix),
                    kind: ProxyKind::Scale,
                    range: (g.range[0], g.range[1]),
                    default: 1.0,
                });
                for &b in &bodies {
                    for &a in *dims {
                        let j = model.scale_index(b, a);
                        offsets[j] = 0.0;
                        terms.push(Term { y_index: j, proxy: k, func: Function::IDENTITY });
                    }
                }
            }
        }
        terms.sort_by_key(|t| t.y_index);
        let mut y_terms = vec![0..0; model.ny()];
        let mut t = 0;
        for (j, r) in y_terms.iter_mut().enumerate() {
            let start = t;
            while t < terms.len() && terms[t].y_index == j {
                t += 1;
            }
            *r = start..t;
        }
        let mut constraints = Vec::new();
        for c in &profile.constraints {
            let mut coefficients = Vec::new();
            for (name, &coef) in &c.proxies {
                let k = proxies.iter().position(|p| &p.name == name).ok_or_else(|| ProxyError::Unknown {
                    what: "proxy",
                    name: name.clone(),
                    valid: list(proxies.iter().map(|p| p.name.as_str())),
                })?;
                coefficients.push((k, coef));
            }
            let (lo, hi) = (c.min.unwrap_or(f64::NEG_INFINITY), c.max.unwrap_or(f64::INFINITY));
            let name = c.proxies.keys().cloned().collect::<Vec<_>>().join(" + ");
            check_range("constraint on", &name, lo, hi)?;
            if coefficients.iter().any(|(_, v)| !v.is_finite()) {
                return Err(ProxyError::BadRange { what: "constraint coefficients of", name, lo, hi });
            }
            constraints.push(ProxyConstraint { coefficients, lo, hi });
        }
        Ok(ProxyMap { proxies, offsets, terms, y_terms, constraints })
    }

    /// Number of proxies `np`.
    pub fn np(&self) -> usize {
        self.proxies.len()
    }
    /// Length of `y`.
    pub fn ny(&self) -> usize {
        self.offsets.len()
    }
    /// Proxy values at the model's default state.
    pub fn default_proxies(&self) -> Vec<f64> {
        self.proxies.iter().map(|p| p.default).collect()
    }
    pub fn proxy_index(&self, name: &str) -> Option<usize> {
        self.proxies.iter().position(|p| p.name == name)
    }

    /// `y = Φ(p)`; `dphi[t]` receives `∂y_{terms[t].y_index}/∂p_{terms[t].proxy}` (length = terms).
    #[inline]
    pub fn apply(&self, p: &[f64], y: &mut [f64], dphi: &mut [f64]) {
        y.copy_from_slice(&self.offsets);
        for (t, term) in self.terms.iter().enumerate() {
            let (v, d) = term.func.eval(p[term.proxy]);
            y[term.y_index] += v;
            dphi[t] = d;
        }
    }

    /// `y = Φ(p)` without the derivative.
    pub fn state(&self, p: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.ny()];
        let mut d = vec![0.0; self.terms.len()];
        self.apply(p, &mut y, &mut d);
        y
    }

    /// Proxies that reproduce `y` where each proxy has an identity term (coupled proxies keep
    /// `fallback`): the left inverse used to start from a known state.
    pub fn proxies_from_state(&self, y: &[f64], fallback: &[f64]) -> Vec<f64> {
        let mut p = fallback.to_vec();
        for t in &self.terms {
            if t.func == Function::IDENTITY {
                p[t.proxy] = y[t.y_index];
            }
        }
        p
    }
}

fn list<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let v: Vec<&str> = names.collect();
    if v.len() > 100 {
        format!("{} … ({} in all)", v[..100].join(", "), v.len())
    } else {
        v.join(", ")
    }
}
