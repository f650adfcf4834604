//! The articulated model: an immutable kinematic tree of bodies, joints made of elementary
//! motions driven by coordinates, per-body scale factors, and markers.
//!
//! Conventions (all SI: metres, radians):
//! - Bodies are stored in topological order (a parent before its children); body `None` parent
//!   means the body hangs from ground (the world frame).
//! - The joint of body `b` places it relative to its parent `p`:
//!   `X_b = X_p · P(s_p) · M_1(q) ⋯ M_k(q) · C(s_b)⁻¹`, where `P` is the parent offset frame (in
//!   `p`'s frame, translation multiplied component-wise by `p`'s scale `s_p`), `M_i` are the
//!   elementary motions (rotation about / translation along a unit axis of the current moving
//!   frame), and `C` is the child offset frame (in `b`'s frame, translation multiplied by `s_b`).
//!   This is how OpenSim scales a body: its child offset frames and its markers scale with it.
//! - A marker on body `b` sits at `X_b · (s_b ⊙ offset)`.
//! - The state vector is `y = [q; s]`: `nq` coordinates, then `3·nb` scale factors ordered
//!   body-major (`s[3b + axis]`).

pub mod anthropometry;
pub mod fixed;
pub mod function;
pub mod math;
pub mod profile;
pub mod proxy;
pub mod roles;

pub use function::{CubicSpline, Function};

use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Whether a coordinate is an angle (radians) or a length (metres).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoordinateKind {
    Rotational,
    Translational,
}

/// A generalized coordinate.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Coordinate {
    pub name: String,
    pub kind: CoordinateKind,
    /// Default value (rad or m).
    pub default: f64,
    /// Allowed range `[lo, hi]` (rad or m); infinite ends allowed.
    pub range: (f64, f64),
    /// Locked coordinates stay at `default` and are never optimised.
    pub locked: bool,
    /// Clamped coordinates are kept inside `range` by the solver's bounds.
    pub clamped: bool,
}

/// Rotation about or translation along an axis of the current moving frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionKind {
    Rotation,
    Translation,
}

/// One elementary motion of a joint: amount `f(q_coord)` (rad or m) about/along `axis`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Motion {
    pub kind: MotionKind,
    /// Unit axis in the moving frame (after the previous motions of the joint).
    pub axis: Vector3<f64>,
    /// Driving coordinate; `None` makes the motion constant (`func` evaluated at 0).
    pub coordinate: Option<usize>,
    pub func: Function,
    /// Translations only: the amount is multiplied by `w · s_parent` when set (OpenSim scales
    /// coordinate-driven translation functions of a joint with its parent body). `None`: 1.
    pub parent_scale_weights: Option<Vector3<f64>>,
}

/// The joint that attaches a body to its parent.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Joint {
    pub name: String,
    /// Joint frame on the parent, in the parent body's frame; translation scales with the parent.
    pub parent_offset: Isometry3<f64>,
    /// Joint frame on the child, in the child body's frame; translation scales with the child.
    pub child_offset: Isometry3<f64>,
    /// Range of this joint's motions in [`Model::motions`].
    pub motions: Range<usize>,
}

/// A rigid body (segment).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Body {
    pub name: String,
    /// Parent body index, or `None` for ground.
    pub parent: Option<usize>,
    pub joint: Joint,
}

/// A marker fixed on a body.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Marker {
    pub name: String,
    pub body: usize,
    /// Location in the body frame at unit scale (m).
    pub offset: Vector3<f64>,
    /// Weight on the squared marker error (OpenSim IK convention); 1 by default.
    pub weight: f64,
    /// Kept where it is by marker placement (OpenSim `<fixed>`); false by default, as in OpenSim.
    #[serde(default)]
    pub fixed: bool,
    /// The class the model file gives it (OpenSim `<fixed>true</fixed>`: anatomical,
    /// `<fixed>false</fixed>`: tracking); `None` when the file says nothing. See
    /// [`marker_classes`] for how registration resolves it.
    #[serde(default)]
    pub class: Option<MarkerClass>,
}

/// How marker registration treats a marker.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MarkerClass {
    /// On a bony landmark: its offset stays close to the model's and informs the scales.
    Anatomical,
    /// On a cluster, wand or soft tissue: its offset is estimated freely within its bound.
    Tracking,
}

/// Why a marker has its registration class (for the report).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "from", content = "what")]
pub enum ClassSource {
    /// The profile's `[markers] anatomical` / `tracking` lists.
    Profile,
    /// The role table (`models/markers/roles.toml`): what the marker is on.
    Role(String),
    /// The model file's `<fixed>` flag, in a marker set that sets both values.
    Flag,
    /// A numbered name sharing its stem with another (`r_thigh1` … `r_thigh5`): a cluster.
    NumberedCluster,
    /// Nothing says otherwise: taken as a landmark.
    Default,
}

/// Each marker's registration class ([`marker_classes_with_sources`]).
pub fn marker_classes(model: &Model, tracking: &[String], anatomical: &[String]) -> Vec<MarkerClass> {
    marker_classes_with_sources(model, tracking, anatomical).into_iter().map(|(c, _)| c).collect()
}

/// Each marker's registration class and why: the profile's lists (`tracking`, `anatomical`)
/// first; then the shipped role table ([`roles`]: landmarks anatomical; wands, clusters and
/// computed joint centres tracking); then the model file's flag (OpenSim `<fixed>true</fixed>`
/// anatomical, `false` tracking) where the marker set sets both values — `<fixed>false</fixed>`
/// on every marker is OpenSim's default, not a statement that they are clusters; then numbered
/// names that share their stem (of three characters or more, so that vertebrae such as `T10`,
/// `T12` are not one) with another such name (`r_thigh1` … `r_thigh5`) are a cluster; the rest are
/// anatomical.
pub fn marker_classes_with_sources(
    model: &Model,
    tracking: &[String],
    anatomical: &[String],
) -> Vec<(MarkerClass, ClassSource)> {
    let table = roles::RoleTable::shipped();
    let flags_deliberate = model.markers.iter().any(|m| m.class == Some(MarkerClass::Anatomical))
        && model.markers.iter().any(|m| m.class == Some(MarkerClass::Tracking));
    let stem = |n: &str| n.trim_end_matches(|c: char| c.is_ascii_digit()).to_string();
    let numbered: Vec<Option<String>> = model
        .markers
        .iter()
        .map(|m| (m.name.ends_with(|c: char| c.is_ascii_digit())).then(|| stem(&m.name)).filter(|s| s.len() >= 3))
        .collect();
    model
        .markers
        .iter()
        .enumerate()
        .map(|(i, m)| {
            if tracking.contains(&m.name) {
                return (MarkerClass::Tracking, ClassSource::Profile);
            }
            if anatomical.contains(&m.name) {
                return (MarkerClass::Anatomical, ClassSource::Profile);
            }
            if let Some((role, what)) = table.role_of(&m.name) {
                return (role.class(), ClassSource::Role(what.to_string()));
            }
            if let (true, Some(c)) = (flags_deliberate, m.class) {
                return (c, ClassSource::Flag);
            }
            let cluster = numbered[i]
                .as_ref()
                .is_some_and(|s| numbered.iter().enumerate().any(|(j, t)| j != i && t.as_ref() == Some(s)));
            if cluster {
                (MarkerClass::Tracking, ClassSource::NumberedCluster)
            } else {
                (MarkerClass::Anatomical, ClassSource::Default)
            }
        })
        .collect()
}

/// A coordinate that is a function of another (OpenSim `CoordinateCouplerConstraint`, MuJoCo
/// joint equality `polycoef`): `q_dependent = f(q_independent)`. Eliminated through the proxy map.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CoordinateCoupling {
    pub dependent: usize,
    pub independent: usize,
    pub func: Function,
}

/// Errors found while assembling a model.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("body '{body}' names parent index {parent}, which does not come before it")]
    ParentOrder { body: String, parent: usize },
    #[error("duplicate {what} name '{name}'")]
    Duplicate { what: &'static str, name: String },
    #[error("motion {motion} of joint '{joint}' has a zero-length axis")]
    ZeroAxis { joint: String, motion: usize },
    #[error("{what} '{name}' refers to {target} index {index}, but there are only {count}")]
    BadIndex { what: &'static str, name: String, target: &'static str, index: usize, count: usize },
    #[error("joint '{joint}' motion range {start}..{end} is not contiguous with the previous joint")]
    MotionRange { joint: String, start: usize, end: usize },
    #[error("coordinate '{coordinate}' has an empty range [{lo}, {hi}]")]
    EmptyRange { coordinate: String, lo: f64, hi: f64 },
    #[error("the model has {count} {what}; at most {max} are supported")]
    TooLarge { what: &'static str, count: usize, max: usize },
}

/// Most bodies a model may have. The solver's per-frame matrices grow with the square of the
/// proxy count and the root-to-body chains with bodies × depth, so a model far beyond any
/// musculoskeletal or animal model (hundreds of bodies) is refused rather than run out of memory.
pub const MAX_BODIES: usize = 1000;
/// Most coordinates a model may have (six per body at [`MAX_BODIES`]).
pub const MAX_COORDINATES: usize = 6 * MAX_BODIES;
/// Most markers a model may have.
pub const MAX_MARKERS: usize = 10_000;

/// Refuses models beyond [`MAX_BODIES`], [`MAX_COORDINATES`] or [`MAX_MARKERS`].
fn check_size(bodies: usize, motions: usize, coordinates: usize, markers: usize) -> Result<(), ModelError> {
    for (what, count, max) in [
        ("bodies", bodies, MAX_BODIES),
        ("elementary joint motions", motions, MAX_COORDINATES),
        ("coordinates", coordinates, MAX_COORDINATES),
        ("markers", markers, MAX_MARKERS),
    ] {
        if count > max {
            return Err(ModelError::TooLarge { what, count, max });
        }
    }
    Ok(())
}

/// An immutable articulated model with its precomputed topology.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Model {
    pub name: String,
    pub bodies: Vec<Body>,
    pub motions: Vec<Motion>,
    pub coordinates: Vec<Coordinate>,
    pub markers: Vec<Marker>,
    pub couplings: Vec<CoordinateCoupling>,
    /// For each body, its ancestors from the root down to itself (inclusive).
    #[serde(skip)]
    chains: Vec<Vec<usize>>,
}

impl Model {
    /// Validates the parts and precomputes the topology. Axes are normalised.
    pub fn new(
        name: impl Into<String>,
        bodies: Vec<Body>,
        mut motions: Vec<Motion>,
        coordinates: Vec<Coordinate>,
        markers: Vec<Marker>,
        couplings: Vec<CoordinateCoupling>,
    ) -> Result<Model, ModelError> {
        check_size(bodies.len(), motions.len(), coordinates.len(), markers.len())?;
        check_unique("body", bodies.iter().map(|b| b.name.as_str()))?;
        check_unique("coordinate", coordinates.iter().map(|c| c.name.as_str()))?;
        check_unique("marker", markers.iter().map(|m| m.name.as_str()))?;
        let mut next_motion = 0;
        for (i, b) in bodies.iter().enumerate() {
            if let Some(p) = b.parent {
                if p >= i {
                    return Err(ModelError::ParentOrder { body: b.name.clone(), parent: p });
                }
            }
            let r = &b.joint.motions;
            if r.start != next_motion || r.end < r.start || r.end > motions.len() {
                return Err(ModelError::MotionRange { joint: b.joint.name.clone(), start: r.start, end: r.end });
            }
            next_motion = r.end;
            for k in r.clone() {
                let m = &mut motions[k];
                let n = m.axis.norm();
                if n < 1e-12 || !n.is_finite() {
                    return Err(ModelError::ZeroAxis { joint: b.joint.name.clone(), motion: k - r.start });
                }
                m.axis /= n;
                if let Some(c) = m.coordinate {
                    check_index("joint", &b.joint.name, "coordinate", c, coordinates.len())?;
                }
            }
        }
        if next_motion != motions.len() {
            return Err(ModelError::MotionRange { joint: "<end>".into(), start: next_motion, end: motions.len() });
        }
        for c in &coordinates {
            if c.range.0 > c.range.1 || c.range.0.is_nan() || c.range.1.is_nan() {
                return Err(ModelError::EmptyRange { coordinate: c.name.clone(), lo: c.range.0, hi: c.range.1 });
            }
        }
        for m in &markers {
            check_index("marker", &m.name, "body", m.body, bodies.len())?;
        }
        for c in &couplings {
            check_index("coupling", "dependent", "coordinate", c.dependent, coordinates.len())?;
            check_index("coupling", "independent", "coordinate", c.independent, coordinates.len())?;
        }
        let mut model =
            Model { name: name.into(), bodies, motions, coordinates, markers, couplings, chains: Vec::new() };
        model.rebuild_topology();
        Ok(model)
    }

    fn rebuild_topology(&mut self) {
        let mut chains: Vec<Vec<usize>> = Vec::with_capacity(self.bodies.len());
        for (i, b) in self.bodies.iter().enumerate() {
            let mut chain = b.parent.map(|p| chains[p].clone()).unwrap_or_default();
            chain.push(i);
            chains.push(chain);
        }
        self.chains = chains;
    }

    /// Number of coordinates `nq`.
    pub fn nq(&self) -> usize {
        self.coordinates.len()
    }
    /// Number of bodies `nb`.
    pub fn nb(&self) -> usize {
        self.bodies.len()
    }
    /// Length of the state `y = [q; s]`: `nq + 3 nb`.
    pub fn ny(&self) -> usize {
        self.nq() + 3 * self.nb()
    }
    /// Index in `y` of scale factor `axis` (0 = x, 1 = y, 2 = z) of body `b`.
    pub fn scale_index(&self, body: usize, axis: usize) -> usize {
        self.nq() + 3 * body + axis
    }
    /// Root-to-body chain of body indices (inclusive).
    pub fn chain(&self, body: usize) -> &[usize] {
        &self.chains[body]
    }
    /// True when `ancestor` is `body` or lies on its chain to the root.
    pub fn is_ancestor(&self, ancestor: usize, body: usize) -> bool {
        self.chains[body].contains(&ancestor)
    }

    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }
    pub fn coordinate_index(&self, name: &str) -> Option<usize> {
        self.coordinates.iter().position(|c| c.name == name)
    }
    pub fn marker_index(&self, name: &str) -> Option<usize> {
        self.markers.iter().position(|m| m.name == name)
    }

    /// Default state: coordinates at their defaults, every scale factor 1.
    pub fn default_state(&self) -> Vec<f64> {
        let mut y: Vec<f64> = self.coordinates.iter().map(|c| c.default).collect();
        y.resize(self.ny(), 1.0);
        y
    }

    /// Replaces the marker set (e.g. one read from a separate marker-set file).
    pub fn with_markers(mut self, markers: Vec<Marker>) -> Result<Model, ModelError> {
        check_size(self.bodies.len(), self.motions.len(), self.coordinates.len(), markers.len())?;
        check_unique("marker", markers.iter().map(|m| m.name.as_str()))?;
        for m in &markers {
            check_index("marker", &m.name, "body", m.body, self.bodies.len())?;
        }
        self.markers = markers;
        Ok(self)
    }

    /// Validates a deserialised model and restores its derived data (as [`Model::new`]).
    pub fn finish_deserialize(self) -> Result<Model, ModelError> {
        Model::new(self.name, self.bodies, self.motions, self.coordinates, self.markers, self.couplings)
    }
}

fn check_unique<'a>(what: &'static str, names: impl Iterator<Item = &'a str>) -> Result<(), ModelError> {
    let mut seen = std::collections::HashSet::new();
    for n in names {
        if !seen.insert(n) {
            return Err(ModelError::Duplicate { what, name: n.to_string() });
        }
    }
    Ok(())
}

fn check_index(
    what: &'static str,
    name: &str,
    target: &'static str,
    index: usize,
    count: usize,
) -> Result<(), ModelError> {
    if index >= count {
        return Err(ModelError::BadIndex { what, name: name.to_string(), target, index, count });
    }
    Ok(())
}
