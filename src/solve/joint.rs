//! The joint calibration problem: what is solved for together (shared scales, per-frame poses,
//! registered markers' offsets), its data and terms ([`JointProblem`]), its unknowns
//! ([`JointState`]) and what one solve did ([`JointOutcome`]). Solved in [`super::calibrate`];
//! its reduced system is formed in `super::schur`.

use super::prior::GlobalTerm;
use super::settings::SolverSettings;
use crate::model::proxy::ProxyMap;
use crate::model::Model;
use nalgebra::Vector3;

/// One joint calibration: shared scales `s`, per-frame poses `q_k` and the registered markers'
/// offsets `o`, minimising
/// `Σ_k ½ Σ_m w_m ‖x̂_m(q_k, s, o_m) − x_km‖² + Σ_k (coordinate targets) + Σ terms(s, o)`.
pub struct JointProblem<'a> {
    /// The model; its marker offsets are replaced by the state's.
    pub model: &'a Model,
    pub proxy: &'a ProxyMap,
    pub settings: &'a SolverSettings,
    /// Observed markers per frame (`3·marker + axis`, m, NaN gaps).
    pub frames: &'a [&'a [f64]],
    /// Marker weights of each frame (a static trial's and a motion's may differ).
    pub weights: &'a [&'a [f64]],
    /// Coordinate targets (length ny each) and their weights, per frame: an IK setup's
    /// coordinate tasks, and a static frame's pull toward its known posture.
    pub tracking_refs: &'a [&'a [f64]],
    pub tracking_weights: &'a [&'a [f64]],
    /// Markers whose offsets are unknowns.
    pub registered: &'a [bool],
    /// Centre of each marker's offset bound (unit-scale body frame, m).
    pub reference: &'a [Vector3<f64>],
    pub bound_m: f64,
    pub terms: &'a [&'a dyn GlobalTerm],
}

/// The unknowns of a [`JointProblem`].
#[derive(Clone, Debug)]
pub struct JointState {
    /// Full proxies of each frame (scale entries are kept equal to `p_scale`).
    pub poses: Vec<Vec<f64>>,
    /// Current offset of every marker (unit-scale body frame, m).
    pub offsets: Vec<Vector3<f64>>,
}

/// What one joint solve did.
#[derive(Clone, Copy, Debug)]
pub struct JointOutcome {
    /// Accepted steps.
    pub iterations: u32,
    /// Rejected steps (the damping grew).
    pub rejected: u32,
    pub energy: f64,
    /// Mean over frames of the marker RMSE (m).
    pub rmse_m: f64,
}
