//! CPU forward kinematics and marker Jacobian (the reference implementation).
//!
//! With the body convention of [`crate::model`], for a marker at world point `x` on body `b`:
//! - a rotation motion with world axis `ω` through world point `o`, amount `f(q_c)`, adds
//!   `f'(q_c) · ω × (x − o)` to column `q_c`; a translation adds `f'(q_c) σ ω` (`σ = w·s_parent`);
//! - the parent offset translation `s_p ⊙ t_P` of a joint on `b`'s chain adds `R_p e_k t_P,k` to
//!   column `s_p,k` (and a weighted translation motion adds `f(q_c) w_k ω`);
//! - the child offset `C⁻¹ = (R_Cᵀ, −R_Cᵀ (s_a ⊙ t_C))` adds `−R_a e_k t_C,k` to column `s_a,k`;
//! - the marker offset `s_b ⊙ o_m` adds `R_b e_k o_m,k` to column `s_b,k`.
//!
//! See `docs/KINEMATICS.md` for the derivation.

use super::Layout;
use crate::model::{Model, MotionKind};
use nalgebra::{DMatrix, Matrix3, Vector3};

/// Scratch for one evaluation. Create one per thread with [`Workspace::new`]; the evaluation
/// functions never allocate.
#[derive(Clone, Debug)]
pub struct Workspace {
    /// Body orientations in the world frame.
    pub body_rot: Vec<Matrix3<f64>>,
    /// Body origins in the world frame (m).
    pub body_pos: Vec<Vector3<f64>>,
    /// Per motion: world axis, world point on the axis (m), value `f`, derivative `f'`, factor `σ`.
    motion_axis: Vec<Vector3<f64>>,
    motion_origin: Vec<Vector3<f64>>,
    motion_val: Vec<f64>,
    motion_der: Vec<f64>,
    motion_sigma: Vec<f64>,
    /// Model marker positions in the world frame (m), `3·marker + axis`.
    pub markers: Vec<f64>,
    /// `J_yᵀ` (ny × 3M, column `3m + axis` is row `3m + axis` of `J_y`), filled by [`jacobian`].
    pub jy_t: DMatrix<f64>,
}

impl Workspace {
    pub fn new(model: &Model) -> Workspace {
        let nb = model.nb();
        let nm = model.motions.len();
        Workspace {
            body_rot: vec![Matrix3::identity(); nb],
            body_pos: vec![Vector3::zeros(); nb],
            motion_axis: vec![Vector3::zeros(); nm],
            motion_origin: vec![Vector3::zeros(); nm],
            motion_val: vec![0.0; nm],
            motion_der: vec![0.0; nm],
            motion_sigma: vec![1.0; nm],
            markers: vec![0.0; 3 * model.markers.len()],
            jy_t: DMatrix::zeros(model.ny(), 3 * model.markers.len()),
        }
    }

    /// Motion `k` at the last [`forward`]: its world axis, a world point on it (m), and the
    /// derivative `f'` times `σ` (rotations: `σ = 1`) of its amount by its coordinate.
    #[inline]
    pub fn motion(&self, k: usize) -> (Vector3<f64>, Vector3<f64>, f64) {
        (self.motion_axis[k], self.motion_origin[k], self.motion_der[k] * self.motion_sigma[k])
    }

    /// World position of marker `m` (m).
    pub fn marker(&self, m: usize) -> Vector3<f64> {
        Vector3::new(self.markers[3 * m], self.markers[3 * m + 1], self.markers[3 * m + 2])
    }
}

#[inline]
fn scale_of(y: &[f64], model: &Model, body: Option<usize>) -> Vector3<f64> {
    match body {
        Some(b) => {
            let i = model.scale_index(b, 0);
            Vector3::new(y[i], y[i + 1], y[i + 2])
        }
        None => Vector3::new(1.0, 1.0, 1.0),
    }
}

/// Forward kinematics of every body and marker at state `y = [q; s]`.
pub fn forward(model: &Model, y: &[f64], ws: &mut Workspace) {
    for b in 0..model.nb() {
        forward_body(model, y, ws, b);
    }
    for m in 0..model.markers.len() {
        forward_marker(model, y, ws, m);
    }
}

/// [`forward`] of `bodies` and `markers` only, the rest of `ws` left as it is: `bodies` in
/// ascending order, each one's parent either listed before it or already at `y` in `ws`, and
/// `markers` on bodies at `y`. What it computes is bit for bit what [`forward`] gives.
pub fn forward_part(model: &Model, y: &[f64], ws: &mut Workspace, bodies: &[usize], markers: &[usize]) {
    for &b in bodies {
        forward_body(model, y, ws, b);
    }
    for &m in markers {
        forward_marker(model, y, ws, m);
    }
}

/// Body `b`'s frame and its joint's motions, from its parent's frame in `ws`.
#[inline]
fn forward_body(model: &Model, y: &[f64], ws: &mut Workspace, b: usize) {
    let body = &model.bodies[b];
    let (r_p, t_p) = match body.parent {
        Some(p) => (ws.body_rot[p], ws.body_pos[p]),
        None => (Matrix3::identity(), Vector3::zeros()),
    };
    let s_p = scale_of(y, model, body.parent);
    let po = &body.joint.parent_offset;
    let mut r = r_p * po.rotation.to_rotation_matrix().matrix();
    let mut t = t_p + r_p * s_p.component_mul(&po.translation.vector);
    for k in body.joint.motions.clone() {
        let mo = &model.motions[k];
        let x = mo.coordinate.map_or(0.0, |c| y[c]);
        let (val, der) = mo.func.eval(x);
        let axis_w = r * mo.axis;
        ws.motion_axis[k] = axis_w;
        ws.motion_origin[k] = t;
        ws.motion_val[k] = val;
        ws.motion_der[k] = der;
        match mo.kind {
            MotionKind::Rotation => {
                r *= crate::model::math::rotation(&mo.axis, val);
            }
            MotionKind::Translation => {
                let sigma = mo.parent_scale_weights.map_or(1.0, |w| w.dot(&s_p));
                ws.motion_sigma[k] = sigma;
                t += axis_w * (val * sigma);
            }
        }
    }
    let s_b = scale_of(y, model, Some(b));
    let co = &body.joint.child_offset;
    let r_b = r * co.rotation.to_rotation_matrix().matrix().transpose();
    ws.body_pos[b] = t - r_b * s_b.component_mul(&co.translation.vector);
    ws.body_rot[b] = r_b;
}

/// Marker `m`'s world position, from its body's frame in `ws`.
#[inline]
fn forward_marker(model: &Model, y: &[f64], ws: &mut Workspace, m: usize) {
    let mk = &model.markers[m];
    let s_b = scale_of(y, model, Some(mk.body));
    let x = ws.body_pos[mk.body] + ws.body_rot[mk.body] * s_b.component_mul(&mk.offset);
    ws.markers[3 * m..3 * m + 3].copy_from_slice(x.as_slice());
}

/// Calls `f(j, a, w)` for every contribution `∂x/∂y_j += a + w × x` of the joints on the chain
/// of `body` to the Jacobian of a point `x` fixed on that body (at the state of the last
/// [`forward`] call). Rotations give `w = f'ω`, `a = −f'ω × o`; everything else `w = 0`. The
/// point's own offset (its scale columns) is not included: see [`marker_contributions`].
#[inline]
pub fn chain_contributions(
    model: &Model,
    ws: &Workspace,
    body: usize,
    mut f: impl FnMut(usize, Vector3<f64>, Vector3<f64>),
) {
    let zero = Vector3::zeros();
    for &a in model.chain(body) {
        let b = &model.bodies[a];
        if let Some(p) = b.parent {
            let t_p = b.joint.parent_offset.translation.vector;
            let r_p = &ws.body_rot[p];
            for k in 0..3 {
                f(model.scale_index(p, k), r_p.column(k) * t_p[k], zero);
            }
        }
        for k in b.joint.motions.clone() {
            let mo = &model.motions[k];
            let w = ws.motion_axis[k];
            if let Some(c) = mo.coordinate {
                match mo.kind {
                    MotionKind::Rotation => {
                        let wd = w * ws.motion_der[k];
                        f(c, -wd.cross(&ws.motion_origin[k]), wd);
                    }
                    MotionKind::Translation => f(c, w * (ws.motion_der[k] * ws.motion_sigma[k]), zero),
                }
            }
            if let (MotionKind::Translation, Some(wts), Some(p)) = (mo.kind, mo.parent_scale_weights, b.parent) {
                for k2 in 0..3 {
                    f(model.scale_index(p, k2), w * (ws.motion_val[k] * wts[k2]), zero);
                }
            }
        }
        let t_c = b.joint.child_offset.translation.vector;
        let r_a = &ws.body_rot[a];
        for k in 0..3 {
            f(model.scale_index(a, k), -r_a.column(k) * t_c[k], zero);
        }
    }
}

/// Calls `f(j, v)` for the scale columns of marker `m`'s own offset: `v = R_b e_k o_k`.
#[inline]
pub fn marker_offset_contributions(model: &Model, ws: &Workspace, m: usize, mut f: impl FnMut(usize, Vector3<f64>)) {
    let mk = &model.markers[m];
    let r_b = &ws.body_rot[mk.body];
    for k in 0..3 {
        f(model.scale_index(mk.body, k), r_b.column(k) * mk.offset[k]);
    }
}

/// Calls `f(j, ∂x/∂y_j)` for every contribution to the Jacobian of marker `m` (at the state
/// of the last [`forward`] call); a `y_j` may receive several contributions, to be summed.
#[inline]
pub fn marker_contributions(model: &Model, ws: &Workspace, m: usize, mut f: impl FnMut(usize, Vector3<f64>)) {
    let x = ws.marker(m);
    chain_contributions(model, ws, model.markers[m].body, |j, a, w| f(j, a + w.cross(&x)));
    marker_offset_contributions(model, ws, m, f);
}

/// Fills `ws.jy_t` with `J_yᵀ` at the state of the last [`forward`] call (entries that cannot
/// be non-zero are left at zero).
pub fn jacobian(model: &Model, layout: &Layout, ws: &mut Workspace) {
    let ny = model.ny();
    let mut jy_t = std::mem::replace(&mut ws.jy_t, DMatrix::zeros(0, 0));
    for deps in &layout.bodies {
        for &m in &deps.markers {
            // Columns 3m, 3m+1, 3m+2 of J_yᵀ are contiguous in column-major storage.
            let block = &mut jy_t.as_mut_slice()[3 * m * ny..(3 * m + 3) * ny];
            let (c0, rest) = block.split_at_mut(ny);
            let (c1, c2) = rest.split_at_mut(ny);
            for &j in &deps.ys {
                c0[j] = 0.0;
                c1[j] = 0.0;
                c2[j] = 0.0;
            }
            marker_contributions(model, ws, m, |j, v| {
                c0[j] += v.x;
                c1[j] += v.y;
                c2[j] += v.z;
            });
        }
    }
    ws.jy_t = jy_t;
}
