//! The body's surface keypoints: COCO-17 plus each foot's big toe, small toe and heel (the
//! COCO-WholeBody / OpenPose BODY_25 foot points), each a fixed combination of mesh vertices,
//! so a keypoint follows the skin as the body is shaped and posed.
//!
//! Defined here, from the reference shape's geometry and the joint cubes (our own definitions,
//! no annotated regressor):
//! - **joints** (shoulders, elbows, wrists, hips, knees, ankles): the [`RING`] vertices nearest
//!   the joint cube among the segments meeting at that joint, their equal weights corrected by
//!   the least change (affine weights, summing to 1) that puts the combination on the cube's
//!   centre in the rest shape — a joint regressor in the manner of SMPL's, fitted to one shape;
//! - **nose**: the foremost head vertex within 1.5 cm of the mid-sagittal plane between the
//!   mouth and the eyes' height;
//! - **eyes**: the foremost head vertex within 8 mm of the eye cube's sagittal and transverse
//!   planes (the closed lid in front of the eyeball);
//! - **ears**: the most lateral head vertex within 1.5 cm of the height 1.5 cm below the eye
//!   cube (the helix beside the tragus);
//! - **big toe / small toe**: the foremost vertex of the foot's medial / lateral third;
//! - **heel**: the hindmost foot vertex in the lowest 3 cm.
//!
//! Frame: the asset's (Z up, X forward, Y to the figure's left).

use super::asset::{BodyAsset, BodyShape};
use nalgebra::{DMatrix, DVector, Vector3};

/// Vertices in a joint keypoint's combination.
pub const RING: usize = 32;

/// The keypoints' names, COCO-17 order then the feet (left first, as COCO-WholeBody).
pub const NAMES: [&str; 23] = [
    "nose",
    "left_eye",
    "right_eye",
    "left_ear",
    "right_ear",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_big_toe",
    "left_small_toe",
    "left_heel",
    "right_big_toe",
    "right_small_toe",
    "right_heel",
];

/// COCO's skeleton (1-based keypoint pairs) extended to the feet.
pub const SKELETON: [[usize; 2]; 25] = [
    [16, 14],
    [14, 12],
    [17, 15],
    [15, 13],
    [12, 13],
    [6, 12],
    [7, 13],
    [6, 7],
    [6, 8],
    [7, 9],
    [8, 10],
    [9, 11],
    [2, 3],
    [1, 2],
    [1, 3],
    [2, 4],
    [3, 5],
    [4, 6],
    [5, 7],
    [16, 18],
    [16, 19],
    [16, 20],
    [17, 21],
    [17, 22],
    [17, 23],
];

/// Each keypoint as `(vertex, weight)` pairs, in [`NAMES`] order.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceKeypoints {
    pub combos: Vec<Vec<(u32, f32)>>,
}

impl SurfaceKeypoints {
    /// The definitions on the asset's reference shape.
    pub fn new(asset: &BodyAsset) -> SurfaceKeypoints {
        let d = Definer { asset, shape: &asset.rest };
        let mut combos = vec![d.nose()];
        for side in ["l", "r"] {
            combos.push(d.eye(side));
        }
        for side in ["l", "r"] {
            combos.push(d.ear(side));
        }
        let joints: [(&str, &[&str]); 6] = [
            ("shoulder", &["torso", "humerus"]),
            ("elbow", &["humerus", "ulna", "radius"]),
            ("hand", &["radius", "ulna", "hand"]),
            ("upper-leg", &["pelvis", "femur"]),
            ("knee", &["femur", "tibia"]),
            ("ankle", &["tibia", "calcn"]),
        ];
        for (cube, segments) in joints {
            for side in ["l", "r"] {
                combos.push(d.joint(side, cube, segments));
            }
        }
        for side in ["l", "r"] {
            combos.extend(d.foot(side));
        }
        SurfaceKeypoints { combos }
    }

    /// Every keypoint on `vertices` (any frame, metres), into `out` (one per keypoint).
    pub fn evaluate(&self, vertices: &[[f32; 3]], out: &mut Vec<[f64; 3]>) {
        out.clear();
        out.extend(self.combos.iter().map(|c| {
            let mut p = [0.0; 3];
            for &(v, w) in c {
                let x = vertices[v as usize];
                for k in 0..3 {
                    p[k] += w as f64 * x[k] as f64;
                }
            }
            p
        }));
    }
}

struct Definer<'a> {
    asset: &'a BodyAsset,
    shape: &'a BodyShape,
}

impl Definer<'_> {
    fn cube(&self, name: &str) -> Vector3<f64> {
        let i = self.asset.joint_index(name).unwrap_or_else(|| panic!("the asset lacks joint cube {name}"));
        self.shape.joints[i]
    }

    /// Vertices whose largest skinning weight is on one of `segments` (full names).
    fn on(&self, segments: &[String]) -> Vec<u32> {
        let ids: Vec<u8> = segments.iter().filter_map(|s| self.asset.segment_index(s)).map(|i| i as u8).collect();
        (0..self.shape.vertices.len() as u32)
            .filter(|&v| ids.contains(&self.asset.skin[v as usize].segments[0]))
            .collect()
    }

    /// The vertex of `among` with the largest `score` (ties: the lowest index).
    fn best(&self, among: &[u32], score: impl Fn(&Vector3<f64>) -> Option<f64>) -> Vec<(u32, f32)> {
        let mut pick: Option<(u32, f64)> = None;
        for &v in among {
            if let Some(s) = score(&self.shape.vertices[v as usize]) {
                if pick.is_none_or(|(_, b)| s > b) {
                    pick = Some((v, s));
                }
            }
        }
        vec![(pick.expect("a vertex in the region").0, 1.0)]
    }

    fn nose(&self) -> Vec<(u32, f32)> {
        let head = self.on(&["head".to_string()]);
        let (eye, mouth) = (self.cube("joint-l-eye").z.min(self.cube("joint-r-eye").z), self.cube("joint-mouth").z);
        self.best(&head, |p| (p.y.abs() < 0.015 && p.z > mouth && p.z < eye).then_some(p.x))
    }

    fn eye(&self, side: &str) -> Vec<(u32, f32)> {
        let head = self.on(&["head".to_string()]);
        let c = self.cube(&format!("joint-{side}-eye"));
        self.best(&head, |p| ((p.y - c.y).abs() < 0.008 && (p.z - c.z).abs() < 0.008).then_some(p.x))
    }

    fn ear(&self, side: &str) -> Vec<(u32, f32)> {
        let head = self.on(&["head".to_string()]);
        let c = self.cube(&format!("joint-{side}-eye"));
        let sign = if side == "l" { 1.0 } else { -1.0 };
        self.best(&head, |p| ((p.z - (c.z - 0.015)).abs() < 0.015 && p.x < c.x).then_some(sign * p.y))
    }

    /// The foot's big toe, small toe and heel.
    fn foot(&self, side: &str) -> [Vec<(u32, f32)>; 3] {
        let sfx = if side == "l" { "_l" } else { "_r" };
        let foot = self.on(&[format!("calcn{sfx}"), format!("toes{sfx}")]);
        let ys: Vec<f64> = foot.iter().map(|&v| self.shape.vertices[v as usize].y).collect();
        let (lo, hi) = ys.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &y| (a.min(y), b.max(y)));
        let third = (hi - lo) / 3.0;
        // medial is toward the mid-plane: the left foot's low y, the right foot's high y
        let medial = |y: f64| if side == "l" { y < lo + third } else { y > hi - third };
        let lateral = |y: f64| if side == "l" { y > hi - third } else { y < lo + third };
        let ground = foot.iter().map(|&v| self.shape.vertices[v as usize].z).fold(f64::INFINITY, f64::min);
        [
            self.best(&foot, |p| medial(p.y).then_some(p.x)),
            self.best(&foot, |p| lateral(p.y).then_some(p.x)),
            self.best(&foot, |p| (p.z < ground + 0.03).then_some(-p.x)),
        ]
    }

    /// The [`RING`] vertices of `segments` (base names, sided) nearest joint cube `cube`, with
    /// affine weights of least change from equal that reproduce the cube's centre.
    fn joint(&self, side: &str, cube: &str, segments: &[&str]) -> Vec<(u32, f32)> {
        let sfx = if side == "l" { "_l" } else { "_r" };
        let names: Vec<String> = segments
            .iter()
            .map(|s| if matches!(*s, "torso" | "pelvis") { s.to_string() } else { format!("{s}{sfx}") })
            .collect();
        let c = self.cube(&format!("joint-{side}-{cube}"));
        let mut near: Vec<(f64, u32)> =
            self.on(&names).into_iter().map(|v| ((self.shape.vertices[v as usize] - c).norm(), v)).collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        near.truncate(RING);
        let k = near.len();
        // A w = b with A = [vertices; ones] (4 × k): w = w0 + Aᵀ (A Aᵀ + εI)⁻¹ (b − A w0)
        let a = DMatrix::from_fn(4, k, |r, j| if r == 3 { 1.0 } else { self.shape.vertices[near[j].1 as usize][r] });
        let w0 = DVector::from_element(k, 1.0 / k as f64);
        let b = DVector::from_vec(vec![c.x, c.y, c.z, 1.0]);
        let gram = &a * a.transpose() + DMatrix::identity(4, 4) * 1e-10;
        let w = match gram.cholesky() {
            Some(ch) => &w0 + a.transpose() * ch.solve(&(b - &a * &w0)),
            None => w0,
        };
        near.iter().zip(w.iter()).map(|(&(_, v), &x)| (v, x as f32)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(kp: &SurfaceKeypoints, shape: &BodyShape) -> Vec<[f64; 3]> {
        let v: Vec<[f32; 3]> = shape.vertices.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
        let mut out = Vec::new();
        kp.evaluate(&v, &mut out);
        out
    }

    #[test]
    fn joint_keypoints_sit_on_their_cubes_and_the_face_and_feet_where_they_belong() {
        let asset = BodyAsset::shipped().unwrap();
        let kp = SurfaceKeypoints::new(&asset);
        assert_eq!(kp.combos.len(), NAMES.len());
        let p = at(&kp, &asset.rest);
        let i = |n: &str| NAMES.iter().position(|x| *x == n).unwrap();
        let cube = |n: &str| asset.rest.joints[asset.joint_index(n).unwrap()];
        for (name, c) in
            [("left_knee", "joint-l-knee"), ("right_elbow", "joint-r-elbow"), ("left_hip", "joint-l-upper-leg")]
        {
            let d = (Vector3::from(p[i(name)]) - cube(c)).norm();
            assert!(d < 1e-4, "{name} {d}");
        }
        // left is +Y; the nose is ahead of the eyes, the eyes above it, the ears behind
        assert!(p[i("left_eye")][1] > 0.0 && p[i("right_eye")][1] < 0.0);
        assert!(p[i("nose")][0] > p[i("left_ear")][0] + 0.05);
        assert!(p[i("left_eye")][2] > p[i("nose")][2]);
        assert!(p[i("left_ear")][1] > p[i("left_eye")][1] + 0.02);
        // toes ahead of the ankle, the heel behind it, all near the floor
        for s in ["left", "right"] {
            let ankle = p[i(&format!("{s}_ankle"))];
            assert!(p[i(&format!("{s}_big_toe"))][0] > ankle[0] + 0.1);
            assert!(p[i(&format!("{s}_heel"))][0] < ankle[0] - 0.02);
            assert!(p[i(&format!("{s}_heel"))][2] < ankle[2] - 0.03);
        }
        // the big toe is medial to the small toe
        assert!(p[i("left_big_toe")][1] < p[i("left_small_toe")][1]);
        assert!(p[i("right_big_toe")][1] > p[i("right_small_toe")][1]);
    }

    #[test]
    fn keypoints_follow_the_shape() {
        let asset = BodyAsset::shipped().unwrap();
        let kp = SurfaceKeypoints::new(&asset);
        let tall = asset.shape_from(&crate::body::Phenotype { height: 0.7, weight: 0.7, ..Default::default() });
        let (p0, p1) = (at(&kp, &asset.rest), at(&kp, &tall));
        // affine weights: a moved and scaled body carries its keypoints exactly
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 1.1);
        let t = Vector3::new(0.5, -1.0, 0.2);
        let moved = BodyShape {
            vertices: asset.rest.vertices.iter().map(|v| r * v * 1.1 + t).collect(),
            joints: asset.rest.joints.clone(),
        };
        for (a, b) in p0.iter().zip(at(&kp, &moved)) {
            let e = (r * Vector3::from(*a) * 1.1 + t - Vector3::from(b)).norm();
            assert!(e < 1e-5, "{e}");
        }
        // the nose stays at its fraction of the stature (within 1 %)
        let floor = |s: &BodyShape| s.vertices.iter().map(|v| v.z).fold(f64::INFINITY, f64::min);
        let (f0, f1) =
            ((p0[0][2] - floor(&asset.rest)) / asset.rest.stature(), (p1[0][2] - floor(&tall)) / tall.stature());
        assert!((f0 - f1).abs() < 0.01 && f0 > 0.85, "{f0} {f1}");
    }
}
