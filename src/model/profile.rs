//! Solver profiles: how a model's coordinates and scale factors are driven by the proxies that
//! the solver moves, plus marker weights and solver overrides. Read from TOML; see
//! `models/fullbody.toml` for a documented example.
//!
//! ```toml
//! [[coupling]]                     # several coordinates driven by one proxy (e.g. a "poly" spine)
//! proxy = "lumbar_flexion"
//! range = [-1.0, 1.0]              # proxy range (rad)
//! coordinates = ["L5_S1_flexion", "L4_L5_flexion"]
//! coefficients = [[0.0, 0.3], [0.0, 0.25, 0.01]]   # polynomial in the proxy, per coordinate
//!
//! [fixed]                          # coordinates held at a value (rad or m)
//! mtp_angle_r = 0.0
//!
//! [[scale_group]]                  # bodies sharing scale factors
//! name = "thigh"
//! bodies = ["femur_r", "femur_l"]
//! axes = "uniform"                 # "uniform": one factor; "xyz": one per body axis
//! range = [0.6, 1.6]
//!
//! [[constraint]]                  # linear inequalities on proxies (solved with clarabel)
//! proxies = { thigh_r = 1.0, thigh_l = -1.0 }
//! min = -0.02
//! max = 0.02
//!
//! [markers]
//! default_weight = 1.0
//! weights = { LASI = 2.0 }
//! exclude = ["RBAK"]
//! synonyms = [["LFWT", "LASI"]]    # file labels that mean a model marker (besides the built-ins)
//! tracking = ["RTHI"]              # marker classes for registration (override the model's flags)
//! anatomical = ["RKNE"]
//!
//! [solver]                         # overrides of the solver settings (see solve::SolverSettings)
//! max_iterations = 20
//! ```
//! Coordinates named nowhere get their own identity proxy; bodies in no scale group keep scale 1.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How the scale factors of a group are shared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ScaleAxes {
    /// One factor for x, y and z of every body in the group.
    #[default]
    Uniform,
    /// One factor per body axis, shared by the bodies of the group.
    Xyz,
}

/// Coordinates driven by polynomials of one proxy.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Coupling {
    pub proxy: String,
    /// Proxy range `[lo, hi]` (rad or m).
    pub range: [f64; 2],
    pub coordinates: Vec<String>,
    /// Per coordinate, polynomial coefficients `[c0, c1, c2, …]` in the proxy.
    pub coefficients: Vec<Vec<f64>>,
}

/// Bodies whose scale factors are one set of proxies.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleGroup {
    pub name: String,
    pub bodies: Vec<String>,
    #[serde(default)]
    pub axes: ScaleAxes,
    /// Allowed range of the factors.
    #[serde(default = "default_scale_range")]
    pub range: [f64; 2],
}

fn default_scale_range() -> [f64; 2] {
    [0.5, 2.0]
}

/// A linear inequality on proxies, `min ≤ Σ coef·proxy ≤ max` (e.g. left/right scale symmetry
/// within a tolerance: `proxies = { femur_r = 1.0, femur_l = -1.0 }, min = -0.03, max = 0.03`).
/// Solved with the clarabel backend.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Constraint {
    pub proxies: BTreeMap<String, f64>,
    pub min: Option<f64>,
    pub max: Option<f64>,
}

/// Marker weighting and selection.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkerSettings {
    /// Weight of markers not named in `weights` (when set, it replaces the model's own weight).
    pub default_weight: Option<f64>,
    #[serde(default)]
    pub weights: BTreeMap<String, f64>,
    /// Markers never used by the solver.
    #[serde(default)]
    pub exclude: Vec<String>,
    /// Extra groups of marker names that mean the same marker (file label ↔ model marker), added
    /// to the built-in table of `pipeline::matching` (Plug-in Gait, CMU, OpenSim spellings).
    #[serde(default)]
    pub synonyms: Vec<Vec<String>>,
    /// Markers registered as tracking markers (clusters, wands: offsets estimated freely within
    /// their bound), overriding the model file's `<fixed>` flags and the cluster-name rule.
    #[serde(default)]
    pub tracking: Vec<String>,
    /// Markers registered as anatomical markers (bony landmarks: offsets held close to the
    /// model's), overriding the model file and the cluster-name rule.
    #[serde(default)]
    pub anatomical: Vec<String>,
}

/// A solver profile (see the module docs for the format).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// Model file this profile belongs to, relative to the profile (informational).
    pub model: Option<String>,
    #[serde(default, rename = "coupling")]
    pub couplings: Vec<Coupling>,
    #[serde(default)]
    pub fixed: BTreeMap<String, f64>,
    #[serde(default, rename = "scale_group")]
    pub scale_groups: Vec<ScaleGroup>,
    #[serde(default, rename = "constraint")]
    pub constraints: Vec<Constraint>,
    #[serde(default)]
    pub markers: MarkerSettings,
    /// Overrides of solver settings, interpreted by the solve layer.
    #[serde(default)]
    pub solver: toml::Table,
}

/// Errors reading a profile.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    #[error("cannot read profile {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("profile {path}: {message}")]
    Parse { path: PathBuf, message: String },
}

impl Profile {
    /// Reads a profile from a TOML file.
    pub fn read(path: &Path) -> Result<Profile, ProfileError> {
        let text = std::fs::read_to_string(path).map_err(|source| ProfileError::Io { path: path.into(), source })?;
        Profile::parse(&text, path)
    }

    /// Parses profile TOML; `path` is used in error messages only.
    pub fn parse(text: &str, path: &Path) -> Result<Profile, ProfileError> {
        toml::from_str(text).map_err(|e| ProfileError::Parse { path: path.into(), message: e.to_string() })
    }

    /// The profile used when none is given: every coordinate its own proxy, and scale groups
    /// that match what marker data can observe ([`auto_scale_groups`]).
    pub fn default_for(model: &crate::model::Model) -> Profile {
        Profile { scale_groups: auto_scale_groups(model), ..Profile::default() }
    }
}

/// The side-free name of a body (`femur_r`, `femur_R`, `r_femur`, `femurRight` → `femur`), and
/// whether it had a side.
pub fn side_free(name: &str) -> (String, bool) {
    for suf in ["_r", "_l", "_R", "_L", "Right", "Left", "_right", "_left"] {
        if let Some(stem) = name.strip_suffix(suf).filter(|s| !s.is_empty()) {
            return (stem.to_string(), true);
        }
    }
    for pre in ["r_", "l_", "R_", "L_", "right_", "left_"] {
        if let Some(stem) = name.strip_prefix(pre).filter(|s| !s.is_empty()) {
            return (stem.to_string(), true);
        }
    }
    (name.to_string(), false)
}

/// Scale groups for a model without a profile: left and right share their factors (`femur_r`
/// with `femur_l`), and a body without markers of its own joins the group of the body whose
/// markers determine it — the first marked body down a chain of single children (talus →
/// calcn, ulna → radius), else its parent's (patella → femur, toes → calcn, hand → radius), as
/// OpenCap's scaling setup ties them. One factor per axis (`xyz`), which calibration's
/// anisotropy penalty keeps close; range [0.5, 2].
pub fn auto_scale_groups(model: &crate::model::Model) -> Vec<ScaleGroup> {
    let nb = model.bodies.len();
    let mut marked = vec![false; nb];
    for m in &model.markers {
        marked[m.body] = true;
    }
    let children = |b: usize| (0..nb).filter(move |&c| model.bodies[c].parent == Some(b));
    let mut anchor: Vec<usize> = (0..nb).collect();
    for b in 0..nb {
        if marked[b] || model.markers.is_empty() {
            continue;
        }
        // Down a chain of single children.
        let mut cur = b;
        let mut found = None;
        for _ in 0..4 {
            let kids: Vec<usize> = children(cur).collect();
            if kids.len() != 1 {
                break;
            }
            cur = kids[0];
            if marked[cur] {
                found = Some(cur);
                break;
            }
        }
        if found.is_none() {
            // Up to the nearest marked ancestor.
            let mut up = model.bodies[b].parent;
            while let Some(p) = up {
                if marked[p] {
                    found = Some(p);
                    break;
                }
                up = model.bodies[p].parent;
            }
        }
        if let Some(a) = found {
            anchor[b] = a;
        }
    }
    let mut groups: Vec<ScaleGroup> = Vec::new();
    for b in 0..nb {
        let key = side_free(&model.bodies[anchor[b]].name).0;
        match groups.iter_mut().find(|g| g.name == key) {
            Some(g) => g.bodies.push(model.bodies[b].name.clone()),
            None => groups.push(ScaleGroup {
                name: key,
                bodies: vec![model.bodies[b].name.clone()],
                axes: ScaleAxes::Xyz,
                range: default_scale_range(),
            }),
        }
    }
    groups
}
