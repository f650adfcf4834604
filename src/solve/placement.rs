//! Marker placement (OpenSim's MarkerPlacer): after calibration, each movable marker is moved to
//! where the calibration frames observed it, expressed on its body.
//!
//! A marker on body `b` sits at `x = p_b + R_b (s_b ⊙ o)` (world frame, m), with `o` its offset at
//! unit scale. Given an observation `x̃` at a solved pose, the offset that reproduces it is
//! `o = (R_bᵀ (x̃ − p_b)) ⊘ s_b`; the placed offset is the mean over the frames that observe it.

use crate::kinematics::cpu::{forward, Workspace};
use crate::model::proxy::ProxyMap;
use crate::model::Model;
use nalgebra::Vector3;

/// New unit-scale offsets (body frame, m) for the markers with `movable[m]`, from observations
/// `frames[k]` (`3·marker + axis`, NaN gaps) at solved proxies `proxies[k]`; `None` where a
/// marker is not movable or never observed.
pub fn place_markers(
    model: &Model,
    proxy: &ProxyMap,
    frames: &[&[f64]],
    proxies: &[Vec<f64>],
    movable: &[bool],
) -> Vec<Option<Vector3<f64>>> {
    let nm = model.markers.len();
    let mut sum = vec![Vector3::zeros(); nm];
    let mut count = vec![0usize; nm];
    let mut ws = Workspace::new(model);
    for (obs, p) in frames.iter().zip(proxies) {
        let y = proxy.state(p);
        forward(model, &y, &mut ws);
        for (m, mk) in model.markers.iter().enumerate() {
            let o = &obs[3 * m..3 * m + 3];
            if !movable[m] || o.iter().any(|v| v.is_nan()) {
                continue;
            }
            let b = mk.body;
            let local = ws.body_rot[b].transpose() * (Vector3::new(o[0], o[1], o[2]) - ws.body_pos[b]);
            let s = Vector3::new(y[model.scale_index(b, 0)], y[model.scale_index(b, 1)], y[model.scale_index(b, 2)]);
            sum[m] += local.component_div(&s);
            count[m] += 1;
        }
    }
    sum.into_iter().zip(count).map(|(s, c)| (c > 0).then(|| s / c as f64)).collect()
}
