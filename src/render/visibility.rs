//! Keypoint visibility from the rendered buffers (COCO `v`): 0 behind the camera or outside the
//! image; otherwise, at the keypoint's pixel (its coordinates rounded):
//! - a point on the skin (the body's surface keypoints: nose, eyes, ears, toes, heels): 2 where
//!   that pixel or one of its 8 neighbours shows a body within [`DEPTH_TOLERANCE_M`] of the
//!   point's depth (the drawn surface confirms it; the neighbours catch points on an outline,
//!   whose own pixel centre sees past the edge); 1 where the pixel shows a body more than the
//!   tolerance in front; else the buffers cannot tell (a point on a rim, such as a heel seen from
//!   the side, whose pixel sees past the edge while its neighbours see the nearer flank of the
//!   heel 1–3 cm in front; or a sliver thinner than a pixel in front of it), and the posed
//!   meshes decide exactly: 1 where a triangle crosses the ray from the camera to the point more
//!   than the tolerance in front of it ([`occluded_on_meshes`]), else 2;
//! - a point off the skin (markers, never drawn themselves): 1 (occluded, by its own body or
//!   another subject) where a body lies at its pixel more than the tolerance in front of it;
//!   else 2 (the body there is within the tolerance, behind it, or absent: a marker beside the
//!   silhouette is in plain view);
//! - a point inside the body (joint centres, the surface set's joints): 2 where the mask shows
//!   its own segment or one adjoining it (of the same subject; skinless bodies are looked
//!   through to the next ones), or nothing, or where the point is not more than the tolerance
//!   behind the surface there (a joint centre the skin does not wrap); 1 where another segment
//!   or subject lies more than the tolerance in front of it.

use super::raster::Images;
use super::rig::{Camera, Pixel};
use crate::model::Model;
use nalgebra::Vector3;

/// How far (m) along the camera axis a surface may lie in front of a point that still counts
/// as visible.
pub const DEPTH_TOLERANCE_M: f64 = 0.01;

/// What a keypoint is, for its test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// On the skin: the body's surface keypoints.
    Skin,
    /// Off the skin: markers.
    Marker,
    /// Inside the body, at body `b`'s joint centre.
    Inside(usize),
}

/// The labels of one subject in the mask: `first + body`, and per body the labels of the
/// segments adjoining it.
#[derive(Clone, Debug)]
pub struct Labels {
    pub first: u16,
    pub count: u16,
    adjoining: Vec<Vec<u16>>,
}

impl Labels {
    /// The labels of `model`'s bodies from `first`; `skinned[b]`: whether body `b` carries skin.
    pub fn new(model: &Model, first: u16, skinned: &[bool]) -> Labels {
        let nb = model.nb();
        let mut near: Vec<Vec<usize>> = vec![Vec::new(); nb];
        for (b, body) in model.bodies.iter().enumerate() {
            if let Some(p) = body.parent {
                near[b].push(p);
                near[p].push(b);
            }
        }
        let adjoining = (0..nb)
            .map(|b| {
                let mut out = vec![b];
                let mut stack: Vec<usize> = near[b].clone();
                let mut seen = vec![false; nb];
                seen[b] = true;
                while let Some(x) = stack.pop() {
                    if std::mem::replace(&mut seen[x], true) {
                        continue;
                    }
                    out.push(x);
                    if !skinned[x] {
                        stack.extend(near[x].iter().filter(|&&y| !seen[y]));
                    }
                }
                out.sort_unstable();
                out.into_iter().map(|x| first + x as u16).collect()
            })
            .collect();
        Labels { first, count: nb as u16, adjoining }
    }

    /// Whether `label` is one of this subject's.
    pub fn owns(&self, label: u16) -> bool {
        label >= self.first && label < self.first + self.count
    }
}

/// The pixel a projected point falls in (its coordinates rounded), if inside the image.
pub fn pixel_of(px: &Pixel, img: &Images) -> Option<usize> {
    if !px.in_image {
        return None;
    }
    img.index((px.u + 0.5).floor() as i64, (px.v + 0.5).floor() as i64)
}

/// The COCO visibility of a point projected to `px` (see the module documentation);
/// `occluded` is the exact test of a skin point the buffers leave open.
pub fn visibility(px: &Pixel, kind: Kind, img: &Images, labels: &Labels, occluded: impl FnOnce() -> bool) -> u8 {
    let Some(i) = pixel_of(px, img) else { return 0 };
    let label = img.mask[i];
    if kind == Kind::Skin {
        return if confirmed(img, i, px.depth) {
            2
        } else if label != 0 && (img.depth_m[i] as f64) < px.depth - DEPTH_TOLERANCE_M || occluded() {
            1
        } else {
            2
        };
    }
    if label == 0 {
        return 2;
    }
    match kind {
        _ if px.depth <= img.depth_m[i] as f64 + DEPTH_TOLERANCE_M => 2,
        Kind::Skin | Kind::Marker => 1,
        Kind::Inside(b) => {
            if labels.adjoining[b].contains(&label) {
                2
            } else {
                1
            }
        }
    }
}

/// A posed mesh: vertices (`world`, m) and triangles.
pub type Mesh<'a> = (&'a [[f32; 3]], &'a [[u32; 3]]);

/// Whether a triangle of `meshes` (posed vertices in `world`, m; triangles) crosses the segment
/// from `cam`'s centre to `p` (`world`, m, at `depth` m along the camera axis) more than
/// [`DEPTH_TOLERANCE_M`] in front of `p` (Möller–Trumbore, both faces).
pub fn occluded_on_meshes(cam: &Camera, p: &Vector3<f64>, depth: f64, meshes: &[Mesh]) -> bool {
    let origin = -(cam.r.transpose() * cam.t);
    let dir = p - origin;
    let t_max = 1.0 - DEPTH_TOLERANCE_M / depth;
    if t_max <= 0.0 {
        return false;
    }
    let at = |v: &[[f32; 3]], k: u32| {
        let x = v[k as usize];
        Vector3::new(x[0] as f64, x[1] as f64, x[2] as f64)
    };
    meshes.iter().any(|(vertices, triangles)| {
        triangles.iter().any(|t| {
            let a = at(vertices, t[0]);
            let (e1, e2) = (at(vertices, t[1]) - a, at(vertices, t[2]) - a);
            let h = dir.cross(&e2);
            let det = e1.dot(&h);
            if det.abs() < 1e-15 {
                return false;
            }
            let s = (origin - a) / det;
            let u = s.dot(&h);
            if !(0.0..=1.0).contains(&u) {
                return false;
            }
            let q = s.cross(&e1);
            let v = dir.dot(&q);
            if v < 0.0 || u + v > 1.0 {
                return false;
            }
            let t = e2.dot(&q);
            t > 0.0 && t < t_max
        })
    })
}

/// Whether pixel `i` or one of its neighbours shows a body within the tolerance of `depth` (m).
fn confirmed(img: &Images, i: usize, depth: f64) -> bool {
    let w = img.size.0 as i64;
    let (x, y) = (i as i64 % w, i as i64 / w);
    (-1..=1).any(|dy| {
        (-1..=1).any(|dx| {
            img.index(x + dx, y + dy)
                .is_some_and(|j| img.mask[j] != 0 && (img.depth_m[j] as f64 - depth).abs() <= DEPTH_TOLERANCE_M)
        })
    })
}

/// The box `[x, y, w, h]` (px, pixel edges: pixel centres at integers) and pixel count of the
/// pixels carrying `labels`' labels; `None` when there are none.
pub fn mask_box(img: &Images, labels: &Labels) -> Option<([f64; 4], usize)> {
    let w = img.size.0 as usize;
    let (mut lo, mut hi, mut n) = ([usize::MAX; 2], [0usize; 2], 0usize);
    for (i, &l) in img.mask.iter().enumerate() {
        if l != 0 && labels.owns(l) {
            let (x, y) = (i % w, i / w);
            lo = [lo[0].min(x), lo[1].min(y)];
            hi = [hi[0].max(x), hi[1].max(y)];
            n += 1;
        }
    }
    (n > 0).then(|| {
        let b = [lo[0] as f64 - 0.5, lo[1] as f64 - 0.5, (hi[0] - lo[0] + 1) as f64, (hi[1] - lo[1] + 1) as f64];
        (b, n)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    #[test]
    fn a_triangle_on_the_ray_occludes_only_more_than_the_tolerance_in_front() {
        let cam = Camera {
            name: "c".into(),
            k: Matrix3::identity(),
            r: Matrix3::identity(),
            t: Vector3::zeros(),
            width_px: 10,
            height_px: 10,
            focal_mm: 1.0,
            sensor_width_mm: 1.0,
        };
        let p = Vector3::new(0.0, 0.0, 2.0);
        let tris = [[0u32, 1, 2]];
        let across = |z: f32, dx: f32| [[-1.0 + dx, -1.0, z], [1.0 + dx, -1.0, z], [0.0 + dx, 1.0, z]];
        let occludes = |v: [[f32; 3]; 3]| occluded_on_meshes(&cam, &p, 2.0, &[(&v[..], &tris[..])]);
        assert!(occludes(across(1.0, 0.0)));
        assert!(occludes(across(1.985, 0.0)));
        assert!(!occludes(across(1.995, 0.0)), "within the tolerance");
        assert!(!occludes(across(3.0, 0.0)), "behind the point");
        assert!(!occludes(across(1.0, 5.0)), "beside the ray");
    }
}
