//! The anthropometric prior's data: body dimensions of a population survey (ANSUR II, derived
//! statistics in `models/anthropometry/ansur2.toml`), conditioned on what is known of a subject
//! (sex, stature, mass), and the landmark definitions that measure those dimensions on a model
//! (`models/landmarks/*.toml`).
//!
//! A dimension is a linear combination of survey measurements (e.g. thigh length =
//! `trochanterionheight − lateralfemoralepicondyleheight`) measured on the model between two
//! body points in its default pose: their distance, or their separation along the model's up
//! direction. Its population distribution is the survey's Gaussian pushed through the
//! combination and conditioned on the subject's known measurements (Gaussian conditioning).
//! The solver's use of it is in `solve::prior`.

use super::Model;
use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The shipped survey statistics (ANSUR II; see the file's header for the source).
pub const ANSUR2: &str = include_str!("../../models/anthropometry/ansur2.toml");

/// Shipped landmark files: `(name, text)`; the first whose bodies a model has applies.
pub const SHIPPED_LANDMARKS: &[(&str, &str)] = &[
    ("fullbody", include_str!("../../models/landmarks/fullbody.toml")),
    ("rajagopal", include_str!("../../models/landmarks/rajagopal.toml")),
    ("gait2354", include_str!("../../models/landmarks/gait2354.toml")),
];

/// Errors reading survey or landmark data, or subject information.
#[derive(Debug, thiserror::Error)]
pub enum AnthropometryError {
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("cannot read {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error(
        "{path}: dimension '{dimension}' names survey measurement '{name}', which the survey lacks (it has: {valid})"
    )]
    UnknownMeasurement { path: String, dimension: String, name: String, valid: String },
    #[error("{path}: dimension '{dimension}' names body or marker '{body}', which the model lacks")]
    UnknownBody { path: String, dimension: String, body: String },
    #[error("subject {what} = {value}: {why}")]
    Subject { what: &'static str, value: String, why: &'static str },
}

/// Biological sex as the survey records it (selects its sub-population).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Sex {
    Male,
    Female,
}

impl std::str::FromStr for Sex {
    type Err = AnthropometryError;
    fn from_str(s: &str) -> Result<Sex, AnthropometryError> {
        match s.to_ascii_lowercase().as_str() {
            "male" | "m" => Ok(Sex::Male),
            "female" | "f" => Ok(Sex::Female),
            _ => Err(AnthropometryError::Subject {
                what: "sex",
                value: s.into(),
                why: "unknown (valid: male, female; leave it out when unknown)",
            }),
        }
    }
}

/// What is known of a subject; every field optional.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SubjectInfo {
    /// Standing height (m).
    pub height_m: Option<f64>,
    /// Body mass (kg).
    pub mass_kg: Option<f64>,
    pub sex: Option<Sex>,
}

impl SubjectInfo {
    /// Checks the values are plausible for a person: height in (0.3, 2.8) m, mass in (2, 500) kg.
    pub fn validate(&self) -> Result<(), AnthropometryError> {
        if let Some(h) = self.height_m {
            if !(h.is_finite() && h > 0.3 && h < 2.8) {
                return Err(AnthropometryError::Subject {
                    what: "height",
                    value: format!("{h}"),
                    why: "must be a standing height in metres between 0.3 and 2.8",
                });
            }
        }
        if let Some(m) = self.mass_kg {
            if !(m.is_finite() && m > 2.0 && m < 500.0) {
                return Err(AnthropometryError::Subject {
                    what: "mass",
                    value: format!("{m}"),
                    why: "must be a body mass in kilograms between 2 and 500",
                });
            }
        }
        Ok(())
    }
}

#[derive(Deserialize)]
struct SurveyFile {
    columns: Vec<String>,
    male: Population,
    female: Population,
}

#[derive(Deserialize)]
struct Population {
    #[allow(dead_code)]
    subjects: usize,
    mean: Vec<f64>,
    covariance: Vec<Vec<f64>>,
}

/// Survey statistics: per sex, mean and covariance of the measurements (mm; `weightkg` in kg).
#[derive(Clone, Debug)]
pub struct Survey {
    pub columns: Vec<String>,
    male: (DVector<f64>, DMatrix<f64>),
    female: (DVector<f64>, DMatrix<f64>),
}

impl Survey {
    /// The shipped ANSUR II statistics.
    pub fn ansur2() -> Survey {
        Survey::parse(ANSUR2, "models/anthropometry/ansur2.toml").expect("the shipped survey parses")
    }

    pub fn parse(text: &str, path: &str) -> Result<Survey, AnthropometryError> {
        let f: SurveyFile = toml::from_str(text)
            .map_err(|e| AnthropometryError::Parse { path: path.into(), message: e.to_string() })?;
        let k = f.columns.len();
        let pop = |p: &Population| -> Result<(DVector<f64>, DMatrix<f64>), AnthropometryError> {
            if p.mean.len() != k || p.covariance.len() != k || p.covariance.iter().any(|r| r.len() != k) {
                return Err(AnthropometryError::Parse {
                    path: path.into(),
                    message: format!("mean and covariance must have {k} entries per row"),
                });
            }
            Ok((DVector::from_vec(p.mean.clone()), DMatrix::from_fn(k, k, |i, j| p.covariance[i][j])))
        };
        Ok(Survey { columns: f.columns.clone(), male: pop(&f.male)?, female: pop(&f.female)? })
    }

    fn column(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }

    /// Mean and covariance of all columns for `sex`; unknown sex: the equal mixture of both
    /// sub-populations, moment-matched.
    fn population(&self, sex: Option<Sex>) -> (DVector<f64>, DMatrix<f64>) {
        match sex {
            Some(Sex::Male) => self.male.clone(),
            Some(Sex::Female) => self.female.clone(),
            None => {
                let (m1, c1) = &self.male;
                let (m2, c2) = &self.female;
                let m = (m1 + m2) * 0.5;
                let d1 = m1 - &m;
                let d2 = m2 - &m;
                let c = (c1 + c2) * 0.5 + (&d1 * d1.transpose() + &d2 * d2.transpose()) * 0.5;
                (m, c)
            }
        }
    }

    /// The distribution of the combinations `rows` (each: survey column weights, result in
    /// metres) given what is known of the subject: `(mean (m), covariance (m²))`.
    pub fn conditioned(&self, rows: &[Vec<(usize, f64)>], info: &SubjectInfo) -> (DVector<f64>, DMatrix<f64>) {
        let (mu, sigma) = self.population(info.sex);
        let k = self.columns.len();
        // Known measurements: stature (mm) and mass (kg).
        let mut known: Vec<(usize, f64)> = Vec::new();
        if let (Some(h), Some(c)) = (info.height_m, self.column("stature")) {
            known.push((c, h * 1000.0));
        }
        if let (Some(m), Some(c)) = (info.mass_kg, self.column("weightkg")) {
            known.push((c, m));
        }
        let n = rows.len();
        let mut l = DMatrix::zeros(n, k);
        for (i, r) in rows.iter().enumerate() {
            for &(c, w) in r {
                l[(i, c)] += w;
            }
        }
        // Fixed-order products: the same bits on every CPU (`crate::model::fixed`).
        use crate::model::fixed::{mul, mul_t, mul_v};
        let mut mean = mul_v(&l, &mu);
        let mut cov = mul_t(&mul(&l, &sigma), &l);
        if !known.is_empty() {
            let nk = known.len();
            let sel = DMatrix::from_fn(nk, k, |i, j| if known[i].0 == j { 1.0 } else { 0.0 });
            let s_kk = mul_t(&mul(&sel, &sigma), &sel);
            let s_dk = mul_t(&mul(&l, &sigma), &sel);
            let resid = DVector::from_iterator(nk, known.iter().map(|&(c, v)| v - mu[c]));
            if let Some(inv) = s_kk.try_inverse() {
                let s_inv = mul(&s_dk, &inv);
                mean += mul_v(&s_inv, &resid);
                cov -= mul_t(&s_inv, &s_dk);
            }
        }
        (mean / 1000.0, cov / 1.0e6)
    }
}

/// A point fixed on a body: a marker's generic position, or `body` + `offset` (unit-scale body
/// frame, m; default 0, the body's origin).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyPoint {
    pub marker: Option<String>,
    pub body: Option<String>,
    pub offset: Option<[f64; 3]>,
}

/// How a dimension is read off its two points.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Along {
    /// Euclidean distance.
    #[default]
    Distance,
    /// Separation along the model's up direction (`a` above `b`).
    Up,
}

/// One body dimension: survey combination and where it is measured on the model.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DimensionDef {
    pub name: String,
    /// Survey columns and their weights (e.g. `{ trochanterionheight = 1, lateralfemoralepicondyleheight = -1 }`).
    pub survey: BTreeMap<String, f64>,
    pub a: BodyPoint,
    pub b: BodyPoint,
    #[serde(default)]
    pub along: Along,
}

/// A landmark file: the dimensions measurable on one model family.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Landmarks {
    /// Informational: which models this file is for.
    #[serde(default)]
    pub models: String,
    /// Who the generic model represents (its dimensions correspond to the survey's expected
    /// ones for such a person).
    pub generic: SubjectInfo,
    #[serde(default, rename = "dimension")]
    pub dimensions: Vec<DimensionDef>,
    /// Name of the dimension that estimates stature (its survey mean ratio to stature converts
    /// it); used for the report's calibrated stature and the units check.
    pub stature_from: String,
}

impl Landmarks {
    pub fn parse(text: &str, path: &str) -> Result<Landmarks, AnthropometryError> {
        toml::from_str(text).map_err(|e| AnthropometryError::Parse { path: path.into(), message: e.to_string() })
    }

    pub fn read(path: &Path) -> Result<Landmarks, AnthropometryError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| AnthropometryError::Io { path: path.display().to_string(), source })?;
        Landmarks::parse(&text, &path.display().to_string())
    }

    /// Whether every body and marker this file names exists in `model`.
    pub fn fits(&self, model: &Model) -> bool {
        let ok = |p: &BodyPoint| match (&p.marker, &p.body) {
            (Some(m), None) => model.marker_index(m).is_some(),
            (None, Some(b)) => model.body_index(b).is_some(),
            _ => false,
        };
        self.dimensions.iter().all(|d| ok(&d.a) && ok(&d.b))
    }

    /// The first shipped landmark file that fits `model`, with its name.
    pub fn shipped_for(model: &Model) -> Option<(String, Landmarks)> {
        SHIPPED_LANDMARKS.iter().find_map(|(name, text)| {
            let l = Landmarks::parse(text, name).expect("shipped landmark files parse");
            l.fits(model).then(|| (format!("shipped:models/landmarks/{name}.toml"), l))
        })
    }
}

/// A dimension resolved against a model and a survey.
#[derive(Clone, Debug)]
pub struct Dimension {
    pub name: String,
    /// Survey combination `(column, weight)`.
    pub survey: Vec<(usize, f64)>,
    pub a: (usize, Vector3<f64>),
    pub b: (usize, Vector3<f64>),
    pub along: Along,
}

/// Dimensions of `landmarks` resolved on `model` and `survey`.
pub fn resolve(
    landmarks: &Landmarks,
    model: &Model,
    survey: &Survey,
    path: &str,
) -> Result<Vec<Dimension>, AnthropometryError> {
    let point = |d: &DimensionDef, p: &BodyPoint| -> Result<(usize, Vector3<f64>), AnthropometryError> {
        let missing = |what: &str| AnthropometryError::UnknownBody {
            path: path.into(),
            dimension: d.name.clone(),
            body: what.to_string(),
        };
        match (&p.marker, &p.body) {
            (Some(m), None) => {
                let mk = model.marker_index(m).map(|i| &model.markers[i]).ok_or_else(|| missing(m))?;
                Ok((mk.body, mk.offset + Vector3::from(p.offset.unwrap_or_default())))
            }
            (None, Some(b)) => {
                let i = model.body_index(b).ok_or_else(|| missing(b))?;
                Ok((i, Vector3::from(p.offset.unwrap_or_default())))
            }
            _ => Err(AnthropometryError::Parse {
                path: path.into(),
                message: format!("dimension '{}': each point names exactly one of `marker` and `body`", d.name),
            }),
        }
    };
    landmarks
        .dimensions
        .iter()
        .map(|d| {
            let survey_cols = d
                .survey
                .iter()
                .map(|(name, &w)| {
                    survey.column(name).map(|c| (c, w)).ok_or_else(|| AnthropometryError::UnknownMeasurement {
                        path: path.into(),
                        dimension: d.name.clone(),
                        name: name.clone(),
                        valid: survey.columns.join(", "),
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok(Dimension {
                name: d.name.clone(),
                survey: survey_cols,
                a: point(d, &d.a)?,
                b: point(d, &d.b)?,
                along: d.along,
            })
        })
        .collect()
}

/// Ratio of mean stature to the mean of the survey combination `dim` (for estimating stature
/// from that dimension).
pub fn stature_ratio(survey: &Survey, dim: &Dimension, sex: Option<Sex>) -> f64 {
    let (mu, _) = survey.population(sex);
    let d: f64 = dim.survey.iter().map(|&(c, w)| w * mu[c]).sum();
    survey.column("stature").map_or(1.0, |c| mu[c] / d)
}
