//! Shaping the body to the subject's markers, in the manner of MoSh: the shape coefficients
//! and a per-segment stretch and shift of the skin are solved so that each marker sits on the
//! skin at its radius and the body is the subject's stature.
//!
//! **What moves.** The skeleton is the subject's (the calibrated model at its scales); only the
//! skin moves relative to its bones. A displacement `Δv_i` of vertex `i` in the asset's frame
//! at the bind pose is
//! `Δv_i = Σ_k β_k B_ik + Σ_s w_is (R_s diag(a_s) R_sᵀ (v_i − c_s) + t_s)`:
//! the rank-20 shape basis `B` (coefficients `β`) and, per asset segment `s` (skinning weight
//! `w_is`), a stretch `a_s` along the axes `R_s` of the body carrying it about the segment's
//! centroid `c_s`, and a shift `t_s`. It is stored into every influence's body-frame position
//! ([`super::Influence::local`]), so posing and the glTF export carry it unchanged.
//!
//! **What is fitted**, at the bind pose and the subject's scales (no skinning distortion):
//! - landmark markers: `(d − ρ)/σ_l`, `d` the signed distance of the marker's centre to the
//!   skin (positive outside), `ρ` the marker radius;
//! - other skin markers (wands, clusters, which stand off by what they stand off): only inside
//!   the skin, `min(0, d − ρ)/σ_o`;
//! - the enclosed volume (where the mass is known): `(V − m/ρ)/(σ_V m/ρ)`, `ρ` the body's density;
//! - the stature (where known): `(H − h)/σ_h`, `H` the highest minus the lowest vertex, acting
//!   on the highest (the soles are where the feet's markers put them);
//! - the joint centres (the bodies' origins the binding placed): only where one is less than
//!   `joint_depth_m` inside the skin, `(d + depth)/σ_j`;
//! - priors: `β_k` at `σ_β` of its spread over adults, `a_s` at `σ_a` of
//!   the displacement of the segment's extremity, `t_s` at `σ_t`; both bounded.
//!
//! Gauss–Newton with the nearest skin point held per iteration (the map `θ → Δv` is linear, so
//! each step is one least-squares solve); residuals beyond [`FitSettings::huber_m`] are weighed
//! down (Huber), so one misplaced marker cannot drag a segment. Computed points (joint
//! centres, midpoints of two markers) are not skin markers and take no part.

use super::asset::BodyAsset;
pub use super::pose::ShapeFit;
use super::pose::{Dressed, PoseWorkspace};
use super::skin_distance::{nearest_on_skin, MarkerKind, SkinIndex};
use crate::model::Model;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// How the body is shaped to the markers (into the outputs' provenance).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FitSettings {
    /// Marker radius ρ (m): a marker resting on the skin has its centre this far out.
    pub marker_radius_m: f64,
    /// σ of a landmark's distance to the skin (m).
    pub landmark_sd_m: f64,
    /// σ of another marker's depth inside the skin (m).
    pub other_sd_m: f64,
    /// σ of the body's height against the stature (m).
    pub stature_sd_m: f64,
    /// Least depth (m) of a joint centre inside the skin, and the σ (m) of a shortfall.
    pub joint_depth_m: f64,
    pub joint_sd_m: f64,
    /// σ of the enclosed volume, as a fraction of the target.
    pub volume_sd: f64,
    /// σ of a shape coefficient's change, in units of its spread over adults (it is kept within
    /// twice that spread).
    pub shape_sd: f64,
    /// σ of a segment's stretch, as the displacement (m) of its extremity.
    pub stretch_sd_m: f64,
    /// σ of a segment's shift (m).
    pub shift_sd_m: f64,
    /// Largest shift of a segment, and largest displacement of its extremity by its stretch (m).
    pub shift_max_m: f64,
    /// Residuals beyond this (m) count linearly (Huber).
    pub huber_m: f64,
    pub iterations: usize,
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings {
            marker_radius_m: super::skin_distance::MARKER_RADIUS,
            landmark_sd_m: 0.005,
            other_sd_m: 0.01,
            stature_sd_m: 0.002,
            volume_sd: 0.005,
            joint_depth_m: 0.01,
            joint_sd_m: 0.002,
            shape_sd: 0.5,
            stretch_sd_m: 0.015,
            shift_sd_m: 0.01,
            shift_max_m: 0.03,
            huber_m: 0.02,
            iterations: 10,
        }
    }
}

/// How far (m) the fit can move a skin point at most, with margin: the shift and the stretch's
/// [`FitSettings::shift_max_m`] (3 cm) each, the shape coefficients' reach and a triangle's size.
const REACH: f64 = 0.08;

/// One residual's dependence on posed vertices: `(vertex, d r / d x_vertex)`.
type Row = Vec<(usize, Vector3<f64>)>;

struct Problem<'a> {
    rank: usize,
    /// Per vertex: bind-pose position (asset frame).
    rest: Vec<Vector3<f64>>,
    /// Per asset segment: its axes and centroid (asset frame), and its extent along each axis
    /// (m, the largest distance from the centroid of a vertex it carries most).
    axes: Vec<Matrix3<f64>>,
    centre: Vec<Vector3<f64>>,
    extent: Vec<Vector3<f64>>,
    basis: Vec<&'a [f32]>,
    /// Each shape coefficient's spread over adults.
    spread: Vec<f64>,
    skin: &'a [super::asset::Skin],
}

impl Problem<'_> {
    fn params(&self) -> usize {
        self.rank + 6 * self.axes.len()
    }

    /// Keeps each segment's stretch within what moves its extremity by
    /// [`FitSettings::shift_max_m`] (and within ±0.3), and its shift within that too (a projected
    /// Gauss–Newton step).
    fn clamp(&self, theta: &mut [f64], settings: &FitSettings) {
        for (t, s) in theta.iter_mut().zip(&self.spread) {
            *t = t.clamp(-2.0 * s, 2.0 * s);
        }
        for s in 0..self.axes.len() {
            let at = self.rank + 6 * s;
            for j in 0..3 {
                let max = (settings.shift_max_m / self.extent[s][j]).min(0.3);
                theta[at + j] = theta[at + j].clamp(-max, max);
                theta[at + 3 + j] = theta[at + 3 + j].clamp(-settings.shift_max_m, settings.shift_max_m);
            }
        }
    }

    /// Vertex `i`'s segment terms: per skinning segment, the index of its first parameter, the
    /// weight, the segment's axes and the vertex in them about the segment's centroid.
    fn segment_terms(&self, i: usize) -> impl Iterator<Item = (usize, f64, &Matrix3<f64>, Vector3<f64>)> + '_ {
        let sk = &self.skin[i];
        sk.segments.iter().zip(&sk.weights).filter(|(_, &w)| w != 0.0).map(move |(&s, &w)| {
            let (s, r) = (s as usize, &self.axes[s as usize]);
            (self.rank + 6 * s, w as f64, r, r.transpose() * (self.rest[i] - self.centre[s]))
        })
    }

    /// `Δv_i` of every vertex at parameters `theta`.
    fn displacement(&self, theta: &[f64], out: &mut [Vector3<f64>]) {
        for (i, o) in out.iter_mut().enumerate() {
            let mut d = Vector3::zeros();
            for (k, b) in self.basis.iter().enumerate() {
                if theta[k] != 0.0 {
                    d += theta[k] * basis_at(b, i);
                }
            }
            for (at, w, r, local) in self.segment_terms(i) {
                let stretched = Vector3::new(theta[at] * local.x, theta[at + 1] * local.y, theta[at + 2] * local.z);
                d += w * (r * stretched + Vector3::new(theta[at + 3], theta[at + 4], theta[at + 5]));
            }
            *o = d;
        }
    }

    /// The gradient of a residual over the parameters into `out`: `row` (scaled by `weight`)
    /// through the state's map `to_posed` from `Δv` to the posed vertices.
    fn jacobian_row(&self, row: &Row, to_posed: &[Matrix3<f64>], weight: f64, out: &mut [f64]) {
        out.iter_mut().for_each(|x| *x = 0.0);
        for &(i, g) in row {
            let h = to_posed[i].transpose() * g * weight;
            for (k, b) in self.basis.iter().enumerate() {
                out[k] += h.dot(&basis_at(b, i));
            }
            for (at, w, r, local) in self.segment_terms(i) {
                let hw = h * w;
                for j in 0..3 {
                    out[at + j] += hw.dot(&r.column(j)) * local[j];
                    out[at + 3 + j] += hw[j];
                }
            }
        }
    }
}

/// One state the skin is fitted at: its posed vertices before the fit, the map from `Δv` to
/// their change, and the model's markers there (asset frame, m).
struct State {
    posed: Vec<Vector3<f64>>,
    to_posed: Vec<Matrix3<f64>>,
    markers: Vec<Vector3<f64>>,
    /// Every body's origin (its joint centre).
    joints: Vec<Vector3<f64>>,
}

/// Poses `body` at `y` (`[q; s]`) and gathers a [`State`].
fn state(model: &Model, body: &Dressed, y: &[f64], ws: &mut PoseWorkspace) -> State {
    body.pose(model, y, ws);
    let r0 = body.binding.world_from_model.to_rotation_matrix().into_inner();
    // per body: Δv (asset frame) → posed change, R0 R_b diag(s / s_bind) R_bindᵀ R0ᵀ
    let per_body: Vec<Matrix3<f64>> = (0..model.nb())
        .map(|b| {
            let i = model.scale_index(b, 0);
            let ratio = Vector3::from_fn(|k, _| y[i + k] / body.binding.y[i + k]);
            r0 * ws.kin.body_rot[b]
                * Matrix3::from_diagonal(&ratio)
                * body.binding.body_rot[b].transpose()
                * r0.transpose()
        })
        .collect();
    let to_posed = body
        .binding
        .influences
        .iter()
        .map(|inf| inf.iter().filter(|x| x.weight > 0.0).map(|x| per_body[x.body as usize] * x.weight as f64).sum())
        .collect();
    State {
        posed: ws.vertices.iter().map(|v| Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)).collect(),
        to_posed,
        markers: (0..model.markers.len()).map(|k| r0 * Vector3::from_fn(|r, _| ws.kin.markers[3 * k + r])).collect(),
        joints: ws.kin.body_pos.iter().map(|p| r0 * p).collect(),
    }
}

/// Vertex `i`'s displacement in a basis component (flattened `x, y, z` per point).
fn basis_at(b: &[f32], i: usize) -> Vector3<f64> {
    Vector3::new(b[3 * i] as f64, b[3 * i + 1] as f64, b[3 * i + 2] as f64)
}

/// The problem's fixed parts: bind-pose vertices, segment frames and centroids, the basis.
fn problem<'a>(model: &Model, body: &Dressed, asset: &'a BodyAsset) -> Problem<'a> {
    let mut ws = PoseWorkspace::new(model, body);
    body.pose(model, &body.binding.y, &mut ws);
    let rest: Vec<Vector3<f64>> =
        ws.vertices.iter().map(|v| Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)).collect();
    let r0 = body.binding.world_from_model.to_rotation_matrix().into_inner();
    let nseg = asset.segments.len();
    let mut centre = vec![Vector3::zeros(); nseg];
    let mut mass = vec![0.0; nseg];
    for (v, sk) in rest.iter().zip(&asset.skin) {
        for (&s, &w) in sk.segments.iter().zip(&sk.weights) {
            centre[s as usize] += v * w as f64;
            mass[s as usize] += w as f64;
        }
    }
    for (c, m) in centre.iter_mut().zip(&mass) {
        *c /= m.max(1e-9);
    }
    let axes: Vec<Matrix3<f64>> = (0..nseg).map(|s| r0 * body.binding.body_rot[body.binding.map.host[s]]).collect();
    let mut extent = vec![Vector3::repeat(0.01); nseg];
    for (v, sk) in rest.iter().zip(&asset.skin) {
        let s = sk.segments[0] as usize;
        let local = axes[s].transpose() * (v - centre[s]);
        extent[s] = extent[s].zip_map(&local, |e: f64, l: f64| e.max(l.abs()));
    }
    let basis = (0..asset.rank()).map(|k| asset.component(k)).collect();
    Problem {
        rank: asset.rank(),
        rest,
        axes,
        centre,
        extent,
        basis,
        spread: asset.coefficient_spread(),
        skin: &asset.skin,
    }
}

/// What is fitted, gathered once: the problem, the states, which markers and joints count.
struct Fit<'a> {
    p: Problem<'a>,
    states: Vec<State>,
    triangles: &'a [[u32; 3]],
    /// Per state, per point (the skin markers, then the joints): the triangles near enough to
    /// hold its nearest skin point at any parameters ([`Fit::narrow`]).
    near: Vec<Vec<Vec<u32>>>,
    /// `(marker, its body, landmark?)` of the skin markers.
    markers: Vec<(usize, usize, bool)>,
    joints: Vec<usize>,
    stature: Option<f64>,
    /// The vertices the height is read down to ([`Dressed::height`]).
    sole: &'a [u32],
    volume_m3: Option<f64>,
    settings: &'a FitSettings,
}

/// The cost at one set of parameters, its Gauss–Newton normal equations, and the measures.
struct Eval {
    cost: f64,
    h: DMatrix<f64>,
    g: DVector<f64>,
    landmark_median: f64,
    stature_error: Option<f64>,
    volume_error: Option<f64>,
}

impl Fit<'_> {
    /// The residuals of state `si` with its posed vertices: `(value, d value / d vertices, σ)`.
    fn residuals(&self, si: usize, posed: &[[f32; 3]], landmarks: &mut Vec<f64>, e: &mut Eval) -> Vec<(f64, Row, f64)> {
        let (st, set) = (&self.states[si], self.settings);
        let mut res = Vec::new();
        let near = &self.near[si];
        let on_skin = |p: Vector3<f64>, slot: usize| nearest_on_skin(posed, self.triangles, &near[slot], p);
        let row_of = |n: &super::skin_distance::Nearest| -> Row {
            n.vertices.iter().zip(&n.weights).map(|(&v, &w)| (v as usize, -n.normal * w)).collect()
        };
        for (slot, &(k, _, landmark)) in self.markers.iter().enumerate() {
            let x = st.markers[k];
            if !x.iter().all(|c| c.is_finite()) {
                continue;
            }
            let near = on_skin(x, slot);
            let off = near.distance - set.marker_radius_m;
            if landmark {
                landmarks.push(off.abs());
                res.push((off, row_of(&near), set.landmark_sd_m));
            } else if off < 0.0 {
                res.push((off, row_of(&near), set.other_sd_m));
            }
        }
        // the joint centres stay inside the skin, by `joint_depth_m` at least; a joint's nearest
        // triangle may face away, so "outside" is confirmed by the winding number
        for (j, &b) in self.joints.iter().enumerate() {
            let (x, near) = (st.joints[b], on_skin(st.joints[b], self.markers.len() + j));
            // (a joint "outside" by more than 3 cm is a deep one whose nearest triangle faces away)
            let outside = near.distance > 0.0
                && near.distance < 0.03
                && super::metrics::winding_number(posed, self.triangles, [x.x, x.y, x.z]) < 0.5;
            let depth = if outside { -near.distance } else { near.distance.abs() };
            if depth < set.joint_depth_m {
                res.push((set.joint_depth_m - depth, row_of(&near), set.joint_sd_m));
            }
        }
        if si == 0 {
            // weighed as if in every state, as the markers are
            let per_state = (self.states.len() as f64).sqrt();
            let (lo, hi) = extremes(posed, self.sole);
            e.stature_error = self.stature.map(|h| posed[hi][2] as f64 - posed[lo][2] as f64 - h);
            if let Some(err) = e.stature_error {
                // the top of the head moves; the soles stay where the feet's markers put them
                res.push((err, vec![(hi, Vector3::z())], set.stature_sd_m / per_state));
            }
            if let Some(v) = self.volume_m3 {
                let (now, row) = volume_gradient(posed, self.triangles);
                e.volume_error = Some(now / v - 1.0);
                res.push((now - v, row, set.volume_sd * v / per_state));
            }
        }
        res
    }

    /// Per state and point, the triangles of the point's body ([`SkinIndex`]) with a vertex
    /// within [`REACH`] of the farthest the nearest skin point can be: its distance before the
    /// fit plus what the fit can move the skin.
    fn narrow(&self, index: &SkinIndex) -> Vec<Vec<Vec<u32>>> {
        let bodies: Vec<usize> = self.markers.iter().map(|m| m.1).chain(self.joints.iter().copied()).collect();
        self.states
            .iter()
            .map(|st| {
                let posed: Vec<[f32; 3]> = st.posed.iter().map(|v| [v.x as f32, v.y as f32, v.z as f32]).collect();
                let points =
                    self.markers.iter().map(|m| st.markers[m.0]).chain(self.joints.iter().map(|&b| st.joints[b]));
                points
                    .zip(&bodies)
                    .enumerate()
                    .map(|(slot, (x, &b))| {
                        let all = &index.per_body[b];
                        if !x.iter().all(|c| c.is_finite()) {
                            return Vec::new();
                        }
                        let d0 = nearest_on_skin(&posed, self.triangles, all, x).distance;
                        // a wand or cluster marker the skin cannot reach never counts
                        if slot < self.markers.len() && !self.markers[slot].2 && d0 > REACH {
                            return Vec::new();
                        }
                        let reach = d0.abs() + REACH;
                        let within = |t: &u32| {
                            self.triangles[*t as usize].iter().any(|&v| (st.posed[v as usize] - x).norm() < reach)
                        };
                        all.iter().copied().filter(within).collect()
                    })
                    .collect()
            })
            .collect()
    }

    /// The cost (Huber on the residuals over σ, plus the priors) at `theta` and its normal equations.
    fn evaluate(
        &self,
        theta: &[f64],
        sd: &[f64],
        dv: &mut [Vector3<f64>],
        posed: &mut [[f32; 3]],
        normal: bool,
    ) -> Eval {
        let n = if normal { self.p.params() } else { 0 };
        let mut e = Eval {
            cost: 0.0,
            h: DMatrix::zeros(n, n),
            g: DVector::zeros(n),
            landmark_median: f64::NAN,
            stature_error: None,
            volume_error: None,
        };
        self.p.displacement(theta, dv);
        let (mut landmarks, mut row) = (Vec::new(), vec![0.0; self.p.params()]);
        for (si, st) in self.states.iter().enumerate() {
            for (o, ((x0, m), d)) in posed.iter_mut().zip(st.posed.iter().zip(&st.to_posed).zip(dv.iter())) {
                let x = x0 + m * d;
                *o = [x.x as f32, x.y as f32, x.z as f32];
            }
            for (value, r, sigma) in self.residuals(si, posed, &mut landmarks, &mut e) {
                let (z, k) = (value / sigma, self.settings.huber_m / sigma);
                e.cost += if z.abs() <= k { 0.5 * z * z } else { k * z.abs() - 0.5 * k * k };
                if !normal {
                    continue;
                }
                // iteratively reweighted: the Huber weight on the squared residual
                let w = (if z.abs() > k { k / z.abs() } else { 1.0 }).sqrt() / sigma;
                self.p.jacobian_row(&r, &st.to_posed, w, &mut row);
                let j = DVector::from_column_slice(&row);
                e.h.ger(1.0, &j, &j, 1.0);
                e.g.axpy(value * w, &j, 1.0);
            }
        }
        for (k, (t, s)) in theta.iter().zip(sd).enumerate() {
            e.cost += 0.5 * (t / s).powi(2);
            if normal {
                e.h[(k, k)] += 1.0 / s.powi(2);
                e.g[k] += t / s.powi(2);
            }
        }
        e.landmark_median = super::skin_distance::quantiles(landmarks).0;
        e
    }
}

/// Shapes `body` (bound to `model`) to the model's markers at `scales`, to `stature` (m) and to
/// the enclosed volume `volume_m3` (the subject's mass over the body's density), where known,
/// at the bind pose and at `poses` (the model's coordinates `q` of some frames: the skin is
/// fitted where the markers are seen, its skinning distortion included; stature and volume at
/// the bind pose only); returns what it did. Writes the result into the body's influences.
#[allow(clippy::too_many_arguments)]
pub fn fit_to_markers(
    model: &Model,
    body: &mut Dressed,
    asset: &BodyAsset,
    scales: &[f64],
    stature: Option<f64>,
    volume_m3: Option<f64>,
    poses: &[&[f64]],
    settings: &FitSettings,
) -> ShapeFit {
    let kinds = super::skin_distance::marker_kinds(model);
    let sole = body.sole.clone();
    let mut ws = PoseWorkspace::new(model, body);
    let mut states = vec![state(model, body, &body.bind_state(model, scales), &mut ws)];
    for q in poses {
        let mut y = q[..model.nq()].to_vec();
        y.extend_from_slice(scales);
        states.push(state(model, body, &y, &mut ws));
    }
    let mut fit = Fit {
        p: problem(model, body, asset),
        states,
        triangles: &body.triangles,
        near: Vec::new(),
        markers: (0..model.markers.len())
            .filter(|&k| kinds[k] != MarkerKind::Computed)
            .map(|k| (k, model.markers[k].body, kinds[k] == MarkerKind::Landmark))
            .collect(),
        joints: super::bind::targets(model, &body.binding.map, asset).iter().map(|t| t.0).collect(),
        stature,
        sole: &sole,
        volume_m3,
        settings,
    };
    fit.near = fit.narrow(&SkinIndex::new(model, body));
    let sd = prior_sd(&fit.p, settings);
    let nv = fit.p.rest.len();
    let (mut dv, mut posed) = (vec![Vector3::zeros(); nv], vec![[0.0f32; 3]; nv]);
    let mut theta = vec![0.0; fit.p.params()];
    let mut e = fit.evaluate(&theta, &sd, &mut dv, &mut posed, true);
    let mut out = ShapeFit {
        markers_used: fit.markers.len(),
        landmark_median_before_m: e.landmark_median,
        stature_error_before_m: e.stature_error,
        volume_error_before: e.volume_error,
        ..ShapeFit::default()
    };
    // Gauss–Newton steps, each halved until the cost falls (at most four halvings)
    for _ in 0..settings.iterations {
        let Some(step) = e.h.clone().cholesky().map(|c| c.solve(&e.g)) else { break };
        let mut t = 1.0;
        let accepted = loop {
            let mut cand: Vec<f64> = theta.iter().zip(step.iter()).map(|(a, s)| a - t * s).collect();
            fit.p.clamp(&mut cand, settings);
            if fit.evaluate(&cand, &sd, &mut dv, &mut posed, false).cost < e.cost {
                break Some(cand);
            }
            if t < 0.1 {
                break None;
            }
            t *= 0.5;
        };
        let Some(cand) = accepted else { break };
        let ec = fit.evaluate(&cand, &sd, &mut dv, &mut posed, true);
        let converged = e.cost - ec.cost < 1e-6 * e.cost.max(1.0);
        (theta, e) = (cand, ec);
        if converged {
            break;
        }
    }
    fit.p.displacement(&theta, &mut dv);
    out.landmark_median_after_m = e.landmark_median;
    out.stature_error_after_m = e.stature_error;
    out.volume_error_after = e.volume_error;
    out.coefficients = theta[..fit.p.rank].to_vec();
    out.segments = (0..fit.p.axes.len())
        .map(|s| {
            let at = fit.p.rank + 6 * s;
            let t = &theta[at..at + 6];
            (asset.segments[s].clone(), [1.0 + t[0], 1.0 + t[1], 1.0 + t[2]], [t[3], t[4], t[5]])
        })
        .collect();
    drop(fit);
    apply(model, body, &dv);
    out
}

/// The priors' σ per parameter: a shape coefficient's σ is `shape_sd` of its spread over adults
/// ([`BodyAsset::coefficient_spread`]).
fn prior_sd(p: &Problem, settings: &FitSettings) -> Vec<f64> {
    let mut sd = vec![0.0; p.params()];
    for (k, spread) in p.spread.iter().enumerate() {
        sd[k] = settings.shape_sd * spread.max(1e-9);
    }
    for s in 0..p.axes.len() {
        let at = p.rank + 6 * s;
        for j in 0..3 {
            sd[at + j] = settings.stretch_sd_m / p.extent[s][j];
        }
        sd[at + 3..at + 6].fill(settings.shift_sd_m);
    }
    sd
}

/// The enclosed volume (m³) of `v` and its gradient per vertex (`Σ` over the vertex's
/// triangles of the cross product of the other two, over 6).
fn volume_gradient(v: &[[f32; 3]], triangles: &[[u32; 3]]) -> (f64, Row) {
    let p = |i: u32| Vector3::new(v[i as usize][0] as f64, v[i as usize][1] as f64, v[i as usize][2] as f64);
    let mut grad = vec![Vector3::zeros(); v.len()];
    let mut total = 0.0;
    for t in triangles {
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        total += a.dot(&b.cross(&c)) / 6.0;
        grad[t[0] as usize] += b.cross(&c) / 6.0;
        grad[t[1] as usize] += c.cross(&a) / 6.0;
        grad[t[2] as usize] += a.cross(&b) / 6.0;
    }
    (total, grad.into_iter().enumerate().collect())
}

/// The lowest vertex of `sole` (of all where empty) and the highest vertex, along Z.
fn extremes(v: &[[f32; 3]], sole: &[u32]) -> (usize, usize) {
    let hi = (0..v.len()).fold(0, |hi, i| if v[i][2] > v[hi][2] { i } else { hi });
    (super::pose::lowest(v, sole), hi)
}

/// Stores `Δv` (asset frame, bind pose) into every influence: `u += diag(1/s_bind) Rᵀ R0ᵀ Δv`.
fn apply(model: &Model, body: &mut Dressed, dv: &[Vector3<f64>]) {
    let r0 = body.binding.world_from_model.to_rotation_matrix().into_inner();
    let to_local: Vec<Matrix3<f64>> = (0..model.nb())
        .map(|b| {
            let i = model.scale_index(b, 0);
            let inv = Vector3::from_fn(|k, _| 1.0 / body.binding.y[i + k]);
            Matrix3::from_diagonal(&inv) * body.binding.body_rot[b].transpose() * r0.transpose()
        })
        .collect();
    for (inf, d) in body.binding.influences.iter_mut().zip(dv) {
        for x in inf.iter_mut().filter(|x| x.weight > 0.0) {
            let u = to_local[x.body as usize] * d;
            for k in 0..3 {
                x.local[k] += u[k] as f32;
            }
        }
    }
}
