//! One volume corrective as posing applies it: its weight from the bend of its pair, and its
//! displacements turned with the vertices' joints. [`super::correctives`] builds them.

use super::helpers::JointInfluence;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// The bends (rad) each corrective's weight is measured at: every 22.5° up to 135°.
pub const CALIBRATION_STEP: f64 = std::f64::consts::FRAC_PI_8;
pub const CALIBRATION_KEYS: usize = 6;

/// One corrective shape of one bend direction of one pair.
#[derive(Clone, Debug, PartialEq)]
pub struct Corrective {
    /// The pair: ancestor `a` and descendant `d` ([`Helper::parent`], [`Helper::child`]).
    pub parent: usize,
    pub child: usize,
    /// The bend axis (unit; the output frame at the bind pose) and the direction answered (±1).
    pub axis: Vector3<f64>,
    pub sign: f64,
    /// Its weight at bends of `k ·` [`CALIBRATION_STEP`], `k = 1 ..=` [`CALIBRATION_KEYS`] (0 at
    /// no bend; linear between, and past the last key along the last two's slope).
    pub weights: Vec<f64>,
    /// The displaced vertices and their displacement at weight 1 (m; output frame, rest pose).
    pub vertices: Vec<u32>,
    pub deltas: Vec<[f32; 3]>,
}

impl Corrective {
    /// Its weight with its pair's bodies turned by `parent` and `child` since the bind pose
    /// (output frame; [`super::PoseWorkspace::add_corrective`]'s `since`).
    pub fn weight(&self, parent: &Matrix3<f64>, child: &Matrix3<f64>) -> f64 {
        let e = parent.transpose() * child;
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(e));
        let v = q.imag().dot(&self.axis);
        let twist = 2.0 * crate::model::math::atan2(v, q.w);
        let twist = if twist > std::f64::consts::PI { twist - std::f64::consts::TAU } else { twist };
        let x = (self.sign * twist).max(0.0) / CALIBRATION_STEP;
        let k = (x.floor() as usize).min(self.weights.len() - 1);
        let at = |i: usize| if i == 0 { 0.0 } else { self.weights[i - 1] };
        (at(k) + (x - k as f64) * (at(k + 1) - at(k))).max(0.0)
    }
}

impl Corrective {
    /// Adds it at weight `w` to the posed vertices `out`: each displacement turned by the
    /// vertex's joints' rotations since the bind pose (`since`, per joint), blended by `joints`.
    pub fn add_to(&self, w: f64, joints: &[[JointInfluence; 4]], since: &[Matrix3<f64>], out: &mut [[f32; 3]]) {
        if w == 0.0 {
            return;
        }
        for (&v, d) in self.vertices.iter().zip(&self.deltas) {
            let d = Vector3::new(d[0] as f64, d[1] as f64, d[2] as f64) * w;
            let mut x = Vector3::zeros();
            for j in &joints[v as usize] {
                if j.weight == 0.0 {
                    break;
                }
                x += since[j.joint as usize] * d * j.weight as f64;
            }
            let o = &mut out[v as usize];
            *o = [o[0] + x.x as f32, o[1] + x.y as f32, o[2] + x.z as f32];
        }
    }
}
