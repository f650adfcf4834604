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

/// `½ Σ_m Σ_a κ_ma (o_ma − o_ma⁰)²` over registered markers and the three axes `a` of their
/// body's frame: offsets stay near the model's, strongly for landmarks, weakly for tracking
/// markers (`κ_ma = σ_n² / σ_ma²`, times `prior_fraction · N` for landmarks; per axis so that a
/// role constraining one direction only can say so).
#[derive(Clone, Debug)]
pub struct OffsetPrior {
    pub reference: Vec<Vector3<f64>>,
    /// Per marker, the weight of each body-frame axis.
    pub weight: Vec<Vector3<f64>>,
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
            e += 0.5 * d.component_mul(&d).dot(&w);
            if let Some((h, g)) = hg.as_mut() {
                for a in 0..3 {
                    h[(c + a, c + a)] += w[a];
                    g[c + a] += w[a] * d[a];
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
        let e = 0.5 * self.weight * r.dot(&crate::model::fixed::mul_v(&self.cov_inv, &r));
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
            // Fixed-order products: the same bits on every CPU (`super::fixed`).
            let jt_ci = crate::model::fixed::t_mul(&jac, &self.cov_inv) * self.weight;
            let hh = crate::model::fixed::mul(&jt_ci, &jac);
            let gg = crate::model::fixed::mul_v(&jt_ci, &r);
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

/// The known posture of a static trial (a per-frame term: it acts on each static calibration
/// frame's pose, not on the subject's globals): `½ w Σ_j (q_j − q_j⁰)²` over the non-root
/// coordinates, `q⁰` the anatomical neutral (0 within the coordinate's range; an OpenSim Scale
/// setup's coordinate values where it gives them), `w = (σ_n / σ_q)²` so that a deviation of one
/// standard deviation `σ_q` costs what one marker missed by the marker noise `σ_n` costs. It fixes
/// what the markers of a standing subject cannot: the rotation about a long axis of a body whose
/// markers are free (a thigh wand), and the pose traded against registered marker offsets
/// (Plug-in Gait's static calibration defines the neutral the same way; OpenSim's MarkerPlacer
/// solves the static pose toward its setup's coordinate values). Derivation: docs/CALIBRATION.md.
#[derive(Clone, Debug)]
pub struct StaticPosture {
    /// Target per state entry (length ny; only coordinates are pulled).
    pub reference: Vec<f64>,
    /// Weight per state entry (m² per rad² or per m²).
    pub weights: Vec<f64>,
}

/// Whether a body (lower-case name) is of an arm: humerus, ulna, radius, hand, arm, scapula,
/// clavicle, wrist, elbow, shoulder, finger.
fn is_arm_body(name: &str) -> bool {
    const ARM: [&str; 11] =
        ["humer", "ulna", "radius", "hand", "arm", "scap", "clav", "wrist", "elbow", "shoulder", "finger"];
    ARM.iter().any(|a| name.contains(a))
}

impl StaticPosture {
    /// The neutral posture of `model` with standard deviation `sd_rad` for the coordinates a
    /// standing posture fixes ([`StaticPosture::held_coordinates`]), priced at marker noise
    /// `noise_m`; `tasks` `(coordinate, value rad or m, weight)` replace it where a setup gives
    /// the static pose (an OpenSim Scale setup's `MarkerPlacer` coordinate tasks, with their own
    /// weights, as OpenSim weighs them against its markers).
    pub fn neutral(model: &Model, sd_rad: f64, noise_m: f64, tasks: &[(usize, f64, f64)]) -> StaticPosture {
        let ny = model.ny();
        let mut reference = vec![0.0; ny];
        let mut weights = vec![0.0; ny];
        let w = (noise_m / sd_rad).powi(2);
        for (j, held) in StaticPosture::held_coordinates(model).into_iter().enumerate() {
            if held && sd_rad > 0.0 {
                let c = &model.coordinates[j];
                reference[j] = 0.0f64.clamp(c.range.0, c.range.1);
                weights[j] = w;
            }
        }
        for &(j, value, weight) in tasks {
            reference[j] = value;
            weights[j] = weight;
        }
        StaticPosture { reference, weights }
    }

    /// With a static protocol whose arms hang at the model's neutral (`static_arms = "neutral"`):
    /// the arm coordinates ([`StaticPosture::arm_coordinates`]) are held at 0 (within their
    /// range) with the same standard deviation `sd_rad`, except those a setup's coordinate
    /// tasks (`tasks`, as in [`StaticPosture::neutral`]) already give.
    pub fn hold_arms(&mut self, model: &Model, sd_rad: f64, noise_m: f64, tasks: &[(usize, f64, f64)]) {
        if sd_rad <= 0.0 {
            return;
        }
        let w = (noise_m / sd_rad).powi(2);
        for (j, arm) in StaticPosture::arm_coordinates(model).into_iter().enumerate() {
            if arm && !tasks.iter().any(|t| t.0 == j) {
                let c = &model.coordinates[j];
                self.reference[j] = 0.0f64.clamp(c.range.0, c.range.1);
                self.weights[j] = w;
            }
        }
    }

    /// The coordinates a standing posture fixes: rotational, unlocked, not of the root body (the
    /// subject's place and heading are free) and not of an arm (a static trial's arms are held as
    /// its protocol says: down, in a T or crossed). Arm bodies are told by name (humerus, ulna,
    /// radius, hand, arm, scapula, clavicle, wrist, elbow, shoulder, finger).
    pub fn held_coordinates(model: &Model) -> Vec<bool> {
        let mut held = StaticPosture::body_coordinates(model, |name| !is_arm_body(name));
        // A coordinate that also drives the root's motion stays free.
        for b in model.bodies.iter().filter(|b| b.parent.is_none()) {
            for m in &model.motions[b.joint.motions.clone()] {
                if let Some(c) = m.coordinate {
                    held[c] = false;
                }
            }
        }
        held
    }

    /// The arm coordinates a static protocol may hold (`static_arms`): rotational and unlocked,
    /// of the bodies [`StaticPosture::held_coordinates`] leaves out as an arm's.
    pub fn arm_coordinates(model: &Model) -> Vec<bool> {
        StaticPosture::body_coordinates(model, is_arm_body)
    }

    /// Rotational, unlocked coordinates of the non-root bodies whose name `pick` accepts.
    fn body_coordinates(model: &Model, pick: impl Fn(&str) -> bool) -> Vec<bool> {
        let mut out = vec![false; model.nq()];
        for b in model.bodies.iter().filter(|b| b.parent.is_some()) {
            if !pick(&b.name.to_ascii_lowercase()) {
                continue;
            }
            for m in &model.motions[b.joint.motions.clone()] {
                if let Some(c) = m.coordinate {
                    let coord = &model.coordinates[c];
                    out[c] = !coord.locked && coord.kind == crate::model::CoordinateKind::Rotational;
                }
            }
        }
        out
    }

    /// This term folded into the tracking arrays `(reference, weights)` of a frame (an IK setup's
    /// coordinate targets): the sum of both quadratics, up to a constant.
    pub fn fold(&self, reference: &[f64], weights: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let mut r = reference.to_vec();
        crate::kinematics::assembly::fold_tracking_reference(&mut r, weights, &self.reference, &self.weights);
        let w = weights.iter().zip(&self.weights).map(|(a, b)| a + b).collect();
        (r, w)
    }
}

/// Holds the common rotation of a body's registered markers: the rotation `ω` that best explains
/// their offsets' displacements `d_m = o_m − o_m⁰` (`d_m ≈ ω × p_m`, `p_m = o_m⁰ − c`, `c` their
/// centroid) is penalised as `½ κ Σ_m ‖ω × p_m‖²`, `κ` times the squared displacement that rotation
/// explains. That part cannot be told from the body's own rotation (turning every marker of a foot
/// back while the foot turns forward fits the markers as well): left free, registration buys
/// marker fit with joint angles. Used on the bodies whose registered markers are all free
/// (clusters, wands): their landmarks would otherwise hold it. Couples only the offsets of one
/// body's markers. Derivation: docs/CALIBRATION.md.
#[derive(Clone, Debug)]
pub struct LandmarkAnchor {
    /// The anchored bodies.
    pub bodies: Vec<AnchoredBody>,
    /// `κ` (m² objective per m² of rotational displacement).
    pub weight: f64,
    /// Reference offset of every model marker (unit-scale body frame, m).
    pub reference: Vec<Vector3<f64>>,
}

/// One body's markers in a [`LandmarkAnchor`].
#[derive(Clone, Debug)]
pub struct AnchoredBody {
    pub markers: Vec<usize>,
    /// `G` (3n × k, k ≤ 3): orthonormal columns spanning the rotational displacements of the
    /// markers, so that the rotational part of `d` is `G Gᵀ d` and its squared norm `‖Gᵀ d‖²`.
    pub basis: DMatrix<f64>,
}

impl LandmarkAnchor {
    /// The anchor of the markers `anchored` (per model marker) at reference offsets `reference`
    /// (unit-scale body frame, m), per body; bodies with fewer than two of them get none.
    pub fn new(model: &Model, reference: &[Vector3<f64>], anchored: &[bool], weight: f64) -> LandmarkAnchor {
        let mut bodies = Vec::new();
        for b in 0..model.bodies.len() {
            let markers: Vec<usize> =
                (0..model.markers.len()).filter(|&m| anchored[m] && model.markers[m].body == b).collect();
            if markers.len() < 2 {
                continue;
            }
            let n = markers.len();
            let c = markers.iter().map(|&m| reference[m]).sum::<Vector3<f64>>() / n as f64;
            // Generators of the rotational displacements: ω × p for ω along each axis.
            let mut gen = DMatrix::zeros(3 * n, 3);
            for (i, &m) in markers.iter().enumerate() {
                let p = reference[m] - c;
                for a in 0..3 {
                    let r = Vector3::ith(a, 1.0).cross(&p);
                    for k in 0..3 {
                        gen[(3 * i + k, a)] = r[k];
                    }
                }
            }
            // Orthonormal basis of their span (two markers cannot see the rotation about the
            // line through them: that direction drops out).
            let svd = gen.svd(true, false);
            let u = svd.u.expect("u requested");
            let smax = svd.singular_values.max();
            let keep: Vec<usize> =
                (0..svd.singular_values.len()).filter(|&i| svd.singular_values[i] > 1e-6 * smax.max(1e-12)).collect();
            let basis = u.select_columns(&keep);
            bodies.push(AnchoredBody { markers, basis });
        }
        LandmarkAnchor { bodies, weight, reference: reference.to_vec() }
    }
}

impl GlobalTerm for LandmarkAnchor {
    fn name(&self) -> &'static str {
        "landmark_anchor"
    }
    fn add(&self, x: &Globals<'_>, mut hg: Option<(&mut DMatrix<f64>, &mut DVector<f64>)>) -> f64 {
        let mut e = 0.0;
        for body in &self.bodies {
            let n = body.markers.len();
            let mut d = DVector::zeros(3 * n);
            for (i, &m) in body.markers.iter().enumerate() {
                let dm = x.offsets[m] - self.reference[m];
                d.rows_mut(3 * i, 3).copy_from(&dm);
            }
            let coef = body.basis.tr_mul(&d);
            e += 0.5 * self.weight * coef.norm_squared();
            let Some((h, g)) = hg.as_mut() else { continue };
            let cols: Vec<Option<usize>> = body.markers.iter().map(|&m| x.offset_col[m]).collect();
            let grad = &body.basis * &coef * self.weight;
            let hess = &body.basis * body.basis.transpose() * self.weight;
            for (i, ci) in cols.iter().enumerate() {
                let Some(ci) = *ci else { continue };
                for a in 0..3 {
                    g[ci + a] += grad[3 * i + a];
                    for (j, cj) in cols.iter().enumerate() {
                        let Some(cj) = *cj else { continue };
                        for b in 0..3 {
                            h[(ci + a, cj + b)] += hess[(3 * i + a, 3 * j + b)];
                        }
                    }
                }
            }
        }
        e
    }
}

/// Mean angles of a left/right pair (degrees).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Asymmetry {
    /// The pair's name without its side (`knee_angle`).
    pub coordinate: String,
    pub right: f64,
    pub left: f64,
    /// `left − right`.
    pub difference: f64,
}

/// The posture of a calibration's static frames (degrees): per rotational coordinate, the mean
/// over the frames; with what makes it implausible for a standing subject.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct StaticPostureReport {
    pub frames: usize,
    /// `(coordinate, mean angle)` of the coordinates the static posture prior holds.
    pub angles: Vec<(String, f64)>,
    pub asymmetry: Vec<Asymmetry>,
    /// Why the posture is not a standing subject's (makes the calibration `suspect`).
    pub suspect: Vec<String>,
    /// The feet levelled (`static_feet_flat_sd_deg`): each foot's tilt in the first poses and
    /// the angles that level it. Empty where not applied.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub feet: Vec<FootLevelReport>,
}

/// One foot of a static trial levelled (degrees).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct FootLevelReport {
    /// The foot body.
    pub body: String,
    /// Its mean tilt from level in the static frames' first poses (deg).
    pub tilt_deg: f64,
    /// `(coordinate, value)` that level it, the static frames' targets (deg).
    pub targets: Vec<(String, f64)>,
}

/// One marker's move by registration or placement (mm at the subject's scale).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MarkerMove {
    pub marker: String,
    pub class: crate::model::MarkerClass,
    /// Why it has its class ([`crate::model::ClassSource`]).
    pub class_from: crate::model::ClassSource,
    pub moved_mm: f64,
}

/// What registration did to the markers, for the report.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct RegistrationReport {
    /// Every registered marker's move, largest first.
    pub moves: Vec<MarkerMove>,
    /// Landmarks moved beyond half the suspect threshold (worth a look).
    pub warnings: Vec<String>,
    /// Landmarks moved beyond `registration_suspect_mm`: the calibration is `suspect`.
    pub suspect: Vec<String>,
}

/// A joint that calibration moved to where the motion says it is (`functional_hips = "apply"`,
/// [`crate::pipeline::calibration::joint_centres`]).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct JointMove {
    /// The body whose joint moved (a child of the root: a femur).
    pub body: String,
    /// The joint's name in the model.
    pub joint: String,
    /// The joint's location in its parent's frame at unit scale after the move (m): the model's
    /// parent offset translation, which scales with the parent as every joint location does.
    pub location_m: [f64; 3],
    /// The move at the subject's scale, in the parent's frame (mm; the shipped model's pelvis:
    /// x forward, y left, z up).
    pub moved_mm: [f64; 3],
    /// The functional centre's distance from the moved joint after the final solve (mm; `None`
    /// when that solve's fit is not determined).
    #[serde(default)]
    pub residual_mm: Option<f64>,
}

/// A joint's centre found from the motion against the calibrated model's
/// ([`crate::pipeline::calibration::joint_centres`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FunctionalCentre {
    /// The body whose joint it is (a child of the root: a femur).
    pub body: String,
    /// Distance between the sphere fit's centre and the model's joint centre (mm).
    pub distance_mm: f64,
    /// The sphere fit's centre minus the model's, in the root body's frame (mm; the shipped
    /// model's pelvis: x forward, y left, z up).
    #[serde(default)]
    pub offset_mm: [f64; 3],
    /// The child's range of motion relative to the root over the frames fitted (deg).
    pub range_of_motion_deg: f64,
    /// Marker positions fitted.
    pub samples: usize,
}
