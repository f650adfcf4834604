//! Virtual markers: each skin marker of the model (landmarks, wands and clusters; computed points
//! apart) fixed on the body's skin, as the thesis' SMPL-X pipeline fixed its markers on the mesh,
//! so that how far the skin carries a marker from where the model's rigid body carries it can
//! be measured (its "marker spatial error" and, projected, "pixel error").
//!
//! A virtual marker is the skin point nearest the model's marker at the bind pose and the
//! subject's scales (a triangle and barycentric weights), plus the marker's signed distance
//! there along the posed triangle's unit normal. Frames: as the posed vertices (Z-up world, m).

use super::pose::{Dressed, PoseWorkspace};
use super::skin_distance::{marker_kinds, nearest_on_skin, MarkerKind, SkinIndex};
use crate::model::Model;
use nalgebra::Vector3;

/// One marker on the skin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VirtualMarker {
    /// Index into the model's markers.
    pub marker: usize,
    pub landmark: bool,
    pub triangle: [u32; 3],
    pub weights: [f64; 3],
    /// Signed distance (m) from the skin along the outward normal.
    pub offset: f64,
}

/// The virtual markers of a body.
#[derive(Clone, Debug, PartialEq)]
pub struct VirtualMarkers {
    pub markers: Vec<VirtualMarker>,
}

fn v3(a: [f32; 3]) -> Vector3<f64> {
    Vector3::new(a[0] as f64, a[1] as f64, a[2] as f64)
}

impl VirtualMarkers {
    /// Every skin marker of `model` fixed on `body` at the bind pose and `scales`.
    pub fn new(model: &Model, body: &Dressed, scales: &[f64]) -> VirtualMarkers {
        let kinds = marker_kinds(model);
        let index = SkinIndex::new(model, body);
        let mut ws = PoseWorkspace::new(model, body);
        body.pose(model, &body.bind_state(model, scales), &mut ws);
        let r0 = body.binding.world_from_model.to_rotation_matrix().into_inner();
        let markers = (0..model.markers.len())
            .filter(|&k| kinds[k] != MarkerKind::Computed)
            .filter_map(|k| {
                let p = r0 * Vector3::from_fn(|r, _| ws.kin.markers[3 * k + r]);
                if !p.iter().all(|c| c.is_finite()) {
                    return None;
                }
                let near = nearest_on_skin(&ws.vertices, &body.triangles, &index.per_body[model.markers[k].body], p);
                Some(VirtualMarker {
                    marker: k,
                    landmark: kinds[k] == MarkerKind::Landmark,
                    triangle: near.vertices,
                    weights: near.weights,
                    offset: near.distance,
                })
            })
            .collect();
        VirtualMarkers { markers }
    }

    /// Each virtual marker on the posed `vertices`, into `out` (in [`Self::markers`] order).
    pub fn evaluate(&self, vertices: &[[f32; 3]], out: &mut Vec<Vector3<f64>>) {
        out.clear();
        out.extend(self.markers.iter().map(|m| {
            let [a, b, c] = m.triangle.map(|i| v3(vertices[i as usize]));
            let n = (b - a).cross(&(c - a));
            let n = if n.norm() > 0.0 { n.normalize() } else { Vector3::zeros() };
            a * m.weights[0] + b * m.weights[1] + c * m.weights[2] + n * m.offset
        }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{BodyAsset, Phenotype};
    use crate::pipeline::context::Context;
    use nalgebra::UnitQuaternion;

    #[test]
    fn virtual_markers_sit_on_the_model_markers_at_the_bind_pose() {
        let asset = BodyAsset::shipped().unwrap();
        let model = Context::shipped().unwrap().model;
        let ones = vec![1.0; 3 * model.nb()];
        let body =
            Dressed::new(&model, &UnitQuaternion::identity(), &asset, &ones, None, Phenotype::default()).unwrap();
        let vm = VirtualMarkers::new(&model, &body, &ones);
        assert!(vm.markers.len() > 30);
        let mut ws = PoseWorkspace::new(&model, &body);
        body.pose(&model, &body.bind_state(&model, &ones), &mut ws);
        let mut out = Vec::new();
        vm.evaluate(&ws.vertices, &mut out);
        for (m, p) in vm.markers.iter().zip(&out) {
            let k = m.marker;
            let x = Vector3::from_fn(|r, _| ws.kin.markers[3 * k + r]);
            // exact where the nearest point is inside a face; an edge or corner tilts the offset
            assert!((p - x).norm() < 0.3 * m.offset.abs() + 1e-4, "{} {}", model.markers[k].name, (p - x).norm());
        }
    }
}
