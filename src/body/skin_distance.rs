//! Marker-to-skin distances: for each model marker at a posed state, the signed distance from
//! the marker's centre to the posed skin (the nearest point on the triangle mesh; positive
//! outside). A marker of radius [`MARKER_RADIUS`] resting on the skin is that far out.
//!
//! The search is bounded without a BVH: a marker is compared with the triangles of its own
//! body (those with a vertex influenced by it), or of the nearest ancestor body that has some.
//! The sign is the side of the nearest triangle's plane (of the nearest triangles at one
//! distance, the one the marker is most squarely above), which is right wherever the nearest
//! point is inside a face and may be wrong where it is on a crease's edge.

use super::pose::{Dressed, PoseWorkspace};
use crate::model::{MarkerClass, Model};
use nalgebra::Vector3;

/// The radius of a typical retro-reflective marker (m): 7 mm (a 14 mm sphere).
pub const MARKER_RADIUS: f64 = 0.007;

/// Per model body, the triangles its markers are compared with.
#[derive(Clone, Debug)]
pub struct SkinIndex {
    pub per_body: Vec<Vec<u32>>,
}

impl SkinIndex {
    pub fn new(model: &Model, body: &Dressed) -> SkinIndex {
        let mut own: Vec<Vec<u32>> = vec![Vec::new(); model.nb()];
        for (t, tri) in body.triangles.iter().enumerate() {
            let mut seen: [u16; 12] = [u16::MAX; 12];
            let mut n = 0;
            for &v in tri {
                for inf in &body.binding.influences[v as usize] {
                    if inf.weight > 0.0 && !seen[..n].contains(&inf.body) {
                        seen[n] = inf.body;
                        n += 1;
                        own[inf.body as usize].push(t as u32);
                    }
                }
            }
        }
        let per_body = (0..model.nb())
            .map(|b| {
                let mut c = Some(b);
                while let Some(k) = c {
                    if !own[k].is_empty() {
                        return own[k].clone();
                    }
                    c = model.bodies[k].parent;
                }
                (0..body.triangles.len() as u32).collect()
            })
            .collect();
        SkinIndex { per_body }
    }
}

fn v3(a: [f32; 3]) -> Vector3<f64> {
    Vector3::new(a[0] as f64, a[1] as f64, a[2] as f64)
}

/// The point of triangle `abc` nearest `p` (Ericson, Real-Time Collision Detection, 5.1.5).
pub fn closest_on_triangle(p: Vector3<f64>, a: Vector3<f64>, b: Vector3<f64>, c: Vector3<f64>) -> Vector3<f64> {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// The skin point nearest a point: signed distance (m, positive outside), the triangle's
/// vertices with the point's barycentric weights, and the outward unit direction along which
/// the distance grows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nearest {
    pub distance: f64,
    pub vertices: [u32; 3],
    pub weights: [f64; 3],
    pub normal: Vector3<f64>,
}

/// Barycentric weights of `q` (in the plane of `abc`).
fn barycentric(q: Vector3<f64>, a: Vector3<f64>, b: Vector3<f64>, c: Vector3<f64>) -> [f64; 3] {
    let (v0, v1, v2) = (b - a, c - a, q - a);
    let (d00, d01, d11, d20, d21) = (v0.dot(&v0), v0.dot(&v1), v1.dot(&v1), v2.dot(&v0), v2.dot(&v1));
    let den = d00 * d11 - d01 * d01;
    if den.abs() < 1e-30 {
        return [1.0, 0.0, 0.0];
    }
    let v = (d11 * d20 - d01 * d21) / den;
    let w = (d00 * d21 - d01 * d20) / den;
    [1.0 - v - w, v, w]
}

/// The nearest point to `p` on triangles `tris` ([`Nearest`]). The sign is the side of the
/// nearest triangle's plane (of the nearest at one distance, the one `p` is most squarely above).
pub fn nearest_on_skin(vertices: &[[f32; 3]], triangles: &[[u32; 3]], tris: &[u32], p: Vector3<f64>) -> Nearest {
    let (mut best, mut best_cos) = (f64::INFINITY, 0.0f64);
    let mut out = Nearest { distance: f64::INFINITY, vertices: [0; 3], weights: [1.0, 0.0, 0.0], normal: Vector3::z() };
    for &t in tris {
        let tri = triangles[t as usize];
        let [a, b, c] = tri.map(|i| v3(vertices[i as usize]));
        let q = closest_on_triangle(p, a, b, c);
        let d = (p - q).norm();
        if d > best + 1e-9 {
            continue;
        }
        let n = (b - a).cross(&(c - a));
        let cos = if d > 0.0 && n.norm() > 0.0 { (p - q).dot(&n) / (d * n.norm()) } else { 1.0 };
        if d < best - 1e-9 || cos.abs() > best_cos.abs() {
            best = best.min(d);
            best_cos = cos;
            let sign = if cos < 0.0 { -1.0 } else { 1.0 };
            let normal = if d > 1e-6 { (p - q) * (sign / d) } else { n.normalize() };
            out = Nearest { distance: sign * d, vertices: tri, weights: barycentric(q, a, b, c), normal };
        }
    }
    out
}

/// Signed distance (m) from `p` to the nearest of triangles `tris` (positive outside).
pub fn signed_distance(vertices: &[[f32; 3]], triangles: &[[u32; 3]], tris: &[u32], p: Vector3<f64>) -> f64 {
    nearest_on_skin(vertices, triangles, tris, p).distance
}

/// What a model marker is to the skin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MarkerKind {
    /// On a bony landmark ([`crate::model::marker_classes`]: anatomical).
    Landmark,
    /// On the skin, standing off by a wand or cluster plate.
    Other,
    /// A point computed by other software: role `joint_centre` in `models/markers/roles.toml`
    /// (a regression joint centre, a ground projection), or the midpoint of two markers of its
    /// body (within 2 mm; OpenSim marker sets' `MidASIS`).
    Computed,
}

/// Each model marker's [`MarkerKind`].
pub fn marker_kinds(model: &Model) -> Vec<MarkerKind> {
    let classes = crate::model::marker_classes(model, &[], &[]);
    let roles = crate::model::roles::RoleTable::shipped();
    let midpoint = |k: usize| {
        let m = &model.markers[k];
        let same: Vec<&crate::model::Marker> =
            model.markers.iter().enumerate().filter(|(j, o)| *j != k && o.body == m.body).map(|(_, o)| o).collect();
        same.iter()
            .enumerate()
            .any(|(i, a)| same[i + 1..].iter().any(|b| ((a.offset + b.offset) * 0.5 - m.offset).norm() < 0.002))
    };
    (0..model.markers.len())
        .map(|k| {
            if matches!(roles.role_of(&model.markers[k].name), Some((crate::model::roles::MarkerRole::JointCentre, _)))
                || midpoint(k)
            {
                MarkerKind::Computed
            } else if classes[k] == MarkerClass::Anatomical {
                MarkerKind::Landmark
            } else {
                MarkerKind::Other
            }
        })
        .collect()
}

/// One marker's signed distances to the skin over the frames.
#[derive(Clone, Debug)]
pub struct MarkerSkin {
    pub name: String,
    pub body: String,
    /// A landmark marker ([`MarkerKind::Landmark`]).
    pub landmark: bool,
    /// A computed point, not a marker on the skin ([`MarkerKind::Computed`]).
    pub computed: bool,
    pub distances: Vec<f64>,
}

impl MarkerSkin {
    /// `(median, 90th percentile)` of |distance − [`MARKER_RADIUS`]| (m).
    pub fn off_skin(&self) -> (f64, f64) {
        quantiles(self.distances.iter().map(|d| (d - MARKER_RADIUS).abs()).collect())
    }
}

/// `(median, 90th percentile)` of `x` (nearest rank; NaN when empty).
pub fn quantiles(mut x: Vec<f64>) -> (f64, f64) {
    if x.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    x.sort_by(f64::total_cmp);
    let at = |q: f64| x[((q * x.len() as f64).ceil() as usize).clamp(1, x.len()) - 1];
    (at(0.5), at(0.9))
}

/// Each model marker's signed distance to the skin at each state of `states` (`[q; s]`).
pub fn marker_skin_distances<'a>(
    model: &Model,
    body: &Dressed,
    states: impl IntoIterator<Item = &'a [f64]>,
) -> Vec<MarkerSkin> {
    let index = SkinIndex::new(model, body);
    let kinds = marker_kinds(model);
    let mut out: Vec<MarkerSkin> = model
        .markers
        .iter()
        .zip(&kinds)
        .map(|(m, k)| MarkerSkin {
            name: m.name.clone(),
            body: model.bodies[m.body].name.clone(),
            landmark: *k == MarkerKind::Landmark,
            computed: *k == MarkerKind::Computed,
            distances: Vec::new(),
        })
        .collect();
    let mut ws = PoseWorkspace::new(model, body);
    let r0 = body.binding.world_from_model.to_rotation_matrix().into_inner();
    for y in states {
        body.pose(model, y, &mut ws);
        for (k, m) in model.markers.iter().enumerate() {
            let p = r0 * Vector3::new(ws.kin.markers[3 * k], ws.kin.markers[3 * k + 1], ws.kin.markers[3 * k + 2]);
            if p.iter().all(|x| x.is_finite()) {
                out[k].distances.push(signed_distance(&ws.vertices, &body.triangles, &index.per_body[m.body], p));
            }
        }
    }
    out
}

/// `(median, 90th percentile)` of |distance − radius| pooled over the markers `pick` keeps, and
/// the number of markers.
pub fn pooled(markers: &[MarkerSkin], pick: impl Fn(&MarkerSkin) -> bool) -> (f64, f64, usize) {
    let sel: Vec<&MarkerSkin> = markers.iter().filter(|m| pick(m)).collect();
    let all = sel.iter().flat_map(|m| m.distances.iter().map(|d| (d - MARKER_RADIUS).abs())).collect();
    let (a, b) = quantiles(all);
    (a, b, sel.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_to_a_triangle() {
        let (a, b, c) = (Vector3::zeros(), Vector3::x(), Vector3::y());
        let p = Vector3::new(0.2, 0.2, 0.5);
        assert!((closest_on_triangle(p, a, b, c) - Vector3::new(0.2, 0.2, 0.0)).norm() < 1e-12);
        assert!((closest_on_triangle(Vector3::new(2.0, -1.0, 0.0), a, b, c) - b).norm() < 1e-12);
        let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!((signed_distance(&v, &[[0, 1, 2]], &[0], p) - 0.5).abs() < 1e-6);
        assert!((signed_distance(&v, &[[0, 1, 2]], &[0], Vector3::new(0.2, 0.2, -0.5)) + 0.5).abs() < 1e-6);
        assert_eq!(quantiles(vec![3.0, 1.0, 2.0, 4.0]), (2.0, 4.0));
    }
}
