//! Binding the body mesh to a model: the model posed (its coordinates) and sized (its body
//! scales) so that its joint centres sit on the mesh's joint cubes, in the mesh's A-pose; the
//! body frames at that state are the bind frames of linear-blend skinning, and each vertex is
//! stored, per influence, in its body's frame at unit scale ([`Influence`]).
//!
//! Which body carries which segment is [`super::segments`]'s; the pairs of body origin and
//! joint cube follow from it ([`targets`]): a body's origin is the centre of the joint that
//! attaches it to its parent (true of `models/fullbody.xml`, gait2354, Rajagopal and OpenCap's
//! models), so `femur_*` goes to the hip cube, `tibia_*` to the knee, `talus_*` (or a foot
//! hanging on the tibia) to the ankle, `toes_*` to the first foot joint, `humerus_*` to the
//! shoulder, `ulna_*` to the elbow, `hand_*` to the wrist, `head` to the neck, and the spine's
//! bodies (lowest lumbar, `lumbar3`, the torso) to the rig's spine levels with a lower weight.
//! The fit is a damped Gauss–Newton (Levenberg–Marquardt, forward-difference Jacobian) over
//! every unlocked coordinate (kept in its range) and every scale factor (in [0.5, 2]), with a
//! weak pull toward the default coordinates and unit scales to settle what the pairs leave free
//! (axial rotations, the foot and hand scales, a torso without a head body).
//!
//! The mesh is in the asset's frame (Z up, X forward); the model works in its own frame,
//! `world_from_model` apart (an OpenSim model is Y up): the targets and vertices are turned into
//! the model's frame before the fit.
//!
//! The joint centres leave each forearm's roll free: a [`ForearmRoll`] residual turns the radius
//! so that the model's hand lies as the mesh's does (palm toward the thigh), whatever pronation
//! the model calls neutral. Without it the mesh's hand hung on OpenSim's supinated default and
//! walking's 90–120° of pronation twisted the forearm skin flat (edge-frames within 0.5–2× rest
//! on the OpenCap walk: 99.84 % before, 99.91 % with it).
//!
//! Left as it is: the forearm's `radius` takes the rig's distal forearm bone, so pronation
//! twists the wrist end only.

use super::asset::{BodyAsset, BodyShape};
use super::segments::{find_body, map_segments, BindError, SegmentMap};
use crate::kinematics::cpu::{forward, Workspace};
use crate::model::{CoordinateKind, Model, MotionKind};
use nalgebra::{DMatrix, DVector, Matrix3, UnitQuaternion, Vector3};

pub use super::influence::Influence;

/// The spine levels: `(which body, cube, weight)`; `Lowest` is the first body above the pelvis
/// on the torso's chain (the torso itself in a model without lumbar bodies).
enum Spine {
    Lowest,
    Named(&'static str),
    Torso,
}
const SPINE: &[(Spine, &str, f64)] = &[
    (Spine::Lowest, "joint-spine-4", 0.3),
    (Spine::Named("lumbar3"), "joint-spine-3", 0.3),
    (Spine::Torso, "joint-spine-2", 0.3),
];

/// `(model body, joint cubes whose mean centre its origin goes to, weight)` for `model`.
pub fn targets(model: &Model, map: &SegmentMap, asset: &BodyAsset) -> Vec<(usize, Vec<String>, f64)> {
    let seg = |s: &str| asset.segment_index(s).map(|i| (map.host[i], map.own[i]));
    let mut out: Vec<(usize, Vec<String>, f64)> = Vec::new();
    let mut put = |b: usize, cubes: Vec<String>, w: f64| {
        if !out.iter().any(|o| o.0 == b) {
            out.push((b, cubes, w));
        }
    };
    for side in ["r", "l"] {
        let c = |n: &str| format!("joint-{side}-{n}");
        let own = |s: &str| seg(&format!("{s}_{side}")).filter(|x| x.1).map(|x| x.0);
        if let Some(b) = own("femur") {
            put(b, vec![c("upper-leg")], 1.0);
        }
        let tibia = own("tibia");
        if let Some(b) = tibia {
            put(b, vec![c("knee")], 1.0);
        }
        // the ankle: the body hanging on the tibia on the foot's chain (talus, or the foot)
        if let (Some(t), Some((foot, _))) = (tibia, seg(&format!("calcn_{side}"))) {
            if let Some(&a) = model.chain(foot).iter().find(|&&b| model.bodies[b].parent == Some(t)) {
                put(a, vec![c("ankle")], 1.0);
            }
        }
        if let Some(b) = own("toes") {
            put(b, vec![c("foot-1")], 1.0);
        }
        if let Some(b) = own("humerus") {
            put(b, vec![c("shoulder")], 1.0);
        }
        if let Some(b) = own("ulna") {
            put(b, vec![c("elbow")], 1.0);
        }
        if let Some(b) = own("hand") {
            put(b, vec![c("hand")], 1.0);
        }
    }
    if let Some((b, true)) = seg("head") {
        put(b, vec!["joint-neck".to_string()], 1.0);
    }
    if let (Some((torso, true)), Some(pelvis)) = (seg("torso"), find_body(model, "pelvis")) {
        let chain = model.chain(torso);
        if let Some(at) = chain.iter().position(|&b| b == pelvis) {
            for (which, cube, w) in SPINE {
                let b = match which {
                    Spine::Lowest => chain.get(at + 1).copied(),
                    Spine::Named(n) => model.body_index(n).filter(|b| chain.contains(b)),
                    Spine::Torso => Some(torso),
                };
                if let Some(b) = b {
                    put(b, vec![cube.to_string()], *w);
                }
            }
        }
    }
    out
}

/// Pull toward the default coordinates (per radian or metre) and unit scales, relative to the
/// pair residuals in metres.
const PRIOR_COORDINATE: f64 = 0.01;
const PRIOR_SCALE: f64 = 0.02;

/// The mesh bound to a model: the model's state in the mesh's bind pose, its body frames
/// there, and every vertex's influences.
#[derive(Clone, Debug)]
pub struct Binding {
    /// Which body carries each asset segment.
    pub map: SegmentMap,
    /// State `y = [q; s]` of the model in the bind pose.
    pub y: Vec<f64>,
    /// Body orientations and origins at `y` (the model's frame), per model body.
    pub body_rot: Vec<Matrix3<f64>>,
    pub body_pos: Vec<Vector3<f64>>,
    /// Per pair of [`targets`]: body name and distance (m) from its origin to its target at `y`.
    pub errors: Vec<(String, f64)>,
    pub iterations: usize,
    /// Per vertex, up to four influences, largest first (unused: weight 0), weights summing to 1.
    pub influences: Vec<[Influence; 4]>,
    /// The rotation from the model's frame to the asset's (Z-up) frame.
    pub world_from_model: UnitQuaternion<f64>,
    /// Helper joints between bodies and their descendants, and every vertex's influences over
    /// bodies and helpers, which skinning uses ([`super::helpers`]).
    pub helpers: super::helpers::Helpers,
}

impl Binding {
    /// Largest pair distance (m).
    pub fn max_error(&self) -> f64 {
        self.errors.iter().map(|e| e.1).fold(0.0, f64::max)
    }
}

/// Binds `shape` of `asset` to `model`, whose frame is `world_from_model` from the asset's:
/// fits the model's pose and scales to the joint cubes, then stores every vertex in its bodies'
/// frames.
pub fn bind(
    model: &Model,
    world_from_model: &UnitQuaternion<f64>,
    asset: &BodyAsset,
    shape: &BodyShape,
) -> Result<Binding, BindError> {
    bind_from(model, world_from_model, asset, shape, None)
}

/// [`bind`] starting from state `start` (a binding of a nearby shape) instead of the model's
/// default state; the pull stays toward the default state.
pub fn bind_from(
    model: &Model,
    world_from_model: &UnitQuaternion<f64>,
    asset: &BodyAsset,
    shape: &BodyShape,
    start: Option<&[f64]>,
) -> Result<Binding, BindError> {
    let map = map_segments(model, asset)?;
    let model_from_world = world_from_model.inverse().to_rotation_matrix().into_inner();
    let mut pairs = Vec::new();
    for (b, cubes, w) in targets(model, &map, asset) {
        let mut t = Vector3::zeros();
        for c in &cubes {
            let j = asset.joint_index(c).ok_or_else(|| BindError::MissingJoint(c.clone()))?;
            t += shape.joints[j];
        }
        pairs.push((b, model_from_world * t / cubes.len() as f64, w));
    }
    let nq = model.nq();
    let y0 = model.default_state();
    let rolls = forearm_rolls(model, &map, asset, shape, &model_from_world, &y0);
    // free variables and their bounds
    let mut free: Vec<(usize, f64, f64, f64)> = Vec::new(); // (index in y, lo, hi, prior weight)
    for (i, c) in model.coordinates.iter().enumerate() {
        if !c.locked {
            let prior = match c.kind {
                CoordinateKind::Translational => 0.0,
                _ => PRIOR_COORDINATE,
            };
            free.push((i, c.range.0, c.range.1, prior));
        }
    }
    for i in nq..model.ny() {
        free.push((i, 0.5, 2.0, PRIOR_SCALE));
    }
    let mut ws = Workspace::new(model);
    let mut residual = |y: &[f64]| -> DVector<f64> {
        forward(model, y, &mut ws);
        let mut r = DVector::zeros(3 * pairs.len() + 3 * rolls.len() + free.len());
        for (k, (b, t, w)) in pairs.iter().enumerate() {
            let d = (ws.body_pos[*b] - t) * *w;
            r.fixed_rows_mut::<3>(3 * k).copy_from(&d);
        }
        for (k, roll) in rolls.iter().enumerate() {
            r.fixed_rows_mut::<3>(3 * (pairs.len() + k)).copy_from(&roll.residual(&ws));
        }
        let at = 3 * (pairs.len() + rolls.len());
        for (k, &(i, _, _, p)) in free.iter().enumerate() {
            r[at + k] = p * (y[i] - y0[i]);
        }
        r
    };
    let clamp = |y: &mut [f64]| {
        for &(i, lo, hi, _) in &free {
            y[i] = y[i].clamp(lo, hi);
        }
    };

    let mut y = start.map_or_else(|| y0.clone(), <[f64]>::to_vec);
    let mut r = residual(&y);
    let mut cost = r.norm_squared();
    let mut mu = 1e-3;
    let n = free.len();
    let mut iterations = 0;
    for it in 0..200 {
        iterations = it + 1;
        let mut jac = DMatrix::zeros(r.len(), n);
        for (k, &(i, _, _, _)) in free.iter().enumerate() {
            let h = 1e-6;
            let mut yh = y.clone();
            yh[i] += h;
            let col = (residual(&yh) - &r) / h;
            jac.set_column(k, &col);
        }
        let jt = jac.transpose();
        let hess = &jt * &jac;
        let grad = &jt * &r;
        let mut accepted = false;
        while mu < 1e10 {
            let mut a = hess.clone();
            for k in 0..n {
                a[(k, k)] += mu * (1.0 + hess[(k, k)]);
            }
            let Some(chol) = a.cholesky() else {
                mu *= 10.0;
                continue;
            };
            let step = chol.solve(&grad);
            let mut yn = y.clone();
            for (k, &(i, _, _, _)) in free.iter().enumerate() {
                yn[i] -= step[k];
            }
            clamp(&mut yn);
            let rn = residual(&yn);
            let cn = rn.norm_squared();
            if cn < cost {
                let gain = cost - cn;
                y = yn;
                r = rn;
                cost = cn;
                mu = (mu / 3.0).max(1e-9);
                accepted = true;
                if gain < 1e-9 * cost.max(1e-12) {
                    accepted = false; // converged
                }
                break;
            }
            mu *= 4.0;
        }
        if !accepted {
            break;
        }
    }
    forward(model, &y, &mut ws);
    let errors = pairs.iter().map(|(b, t, _)| (model.bodies[*b].name.clone(), (ws.body_pos[*b] - t).norm())).collect();
    let influences = influences(model, asset, shape, &map, &y, &ws, &model_from_world);
    let helpers = super::helpers::split(model, &influences, &ws.body_rot, &ws.body_pos, &y);
    Ok(Binding {
        map,
        y,
        body_rot: ws.body_rot.clone(),
        body_pos: ws.body_pos.clone(),
        errors,
        iterations,
        influences,
        world_from_model: *world_from_model,
        helpers,
    })
}

/// Weight of a forearm's roll residual (m per unit of direction error: 0.1 makes 10° cost
/// about as much as 17 mm of joint-centre error).
const ROLL_WEIGHT: f64 = 0.1;

/// The roll of a forearm in the bind pose. The joint centres leave pronation free, so the
/// mesh's hand (palm toward the thigh in the A-pose) would otherwise hang on a model hand at its
/// default pronation (supinated in OpenSim's arm models, 90° away). The residual is
/// `ROLL_WEIGHT · (R_radius u − r)`: `r` is the mesh's radial direction (little-finger knuckle
/// to index knuckle) and `u` the model's, in the radius frame, both made perpendicular to the
/// pronation axis. The model's radial direction is its wrist flexion axis (a coordinate of the
/// hand's joint named `*flex*`; flexion turns the right hand about its radial direction, the
/// left about its ulnar one); where the hand is welded, the wrist centre's offset from the
/// pronation axis, which lies toward the radius (on Rajagopal's and the shipped arm it is 18°
/// and 32° from the flexion axis).
struct ForearmRoll {
    radius: usize,
    /// The model's radial direction and the pronation axis (radius frame, unit, perpendicular).
    radial_local: Vector3<f64>,
    axis: Vector3<f64>,
    /// The mesh's radial direction (model frame, unit).
    radial: Vector3<f64>,
}

impl ForearmRoll {
    fn residual(&self, ws: &Workspace) -> Vector3<f64> {
        let rot = ws.body_rot[self.radius];
        let a = rot * self.axis;
        let target = (self.radial - a * a.dot(&self.radial)).try_normalize(1e-9).unwrap_or(self.radial);
        (rot * self.radial_local - target) * ROLL_WEIGHT
    }
}

/// The forearms whose radius turns on one unlocked coordinate and carries a hand body: their
/// [`ForearmRoll`]s, each axis found by turning its coordinate a little at `y0`.
fn forearm_rolls(
    model: &Model,
    map: &SegmentMap,
    asset: &BodyAsset,
    shape: &BodyShape,
    model_from_world: &Matrix3<f64>,
    y0: &[f64],
) -> Vec<ForearmRoll> {
    let mut ws0 = Workspace::new(model);
    let mut ws1 = Workspace::new(model);
    forward(model, y0, &mut ws0);
    // the world axis `body` turns about, and the velocity of `point`'s origin, as `coord` turns
    let mut turn = |coord: usize, body: usize, point: usize| -> Option<(Vector3<f64>, Vector3<f64>)> {
        let h = 1e-6;
        let mut y1 = y0.to_vec();
        y1[coord] += h;
        forward(model, &y1, &mut ws1);
        let d = (ws1.body_rot[body] * ws0.body_rot[body].transpose() - Matrix3::identity()) / h;
        let axis = Vector3::new(d[(2, 1)] - d[(1, 2)], d[(0, 2)] - d[(2, 0)], d[(1, 0)] - d[(0, 1)]);
        Some((axis.try_normalize(1e-6)?, (ws1.body_pos[point] - ws0.body_pos[point]) / h))
    };
    let rotations = |body: usize, unlocked: bool| -> Vec<usize> {
        model.motions[model.bodies[body].joint.motions.clone()]
            .iter()
            .filter(|m| m.kind == MotionKind::Rotation)
            .filter_map(|m| m.coordinate)
            .filter(|&c| !(unlocked && model.coordinates[c].locked))
            .collect()
    };
    let owned = |s: &str| asset.segment_index(s).filter(|&i| map.own[i]).map(|i| map.host[i]);
    let mut out = Vec::new();
    for (side, sign) in [('r', 1.0), ('l', -1.0)] {
        let (Some(radius), Some(hand)) = (owned(&format!("radius_{side}")), owned(&format!("hand_{side}"))) else {
            continue;
        };
        let cube =
            |n: &str| asset.joint_index(&format!("joint-{side}-{n}")).map(|j| model_from_world * shape.joints[j]);
        let (Some(index), Some(little)) = (cube("finger-2-1"), cube("finger-5-1")) else { continue };
        let [pronation] = rotations(radius, true)[..] else { continue };
        let Some((axis, wrist_velocity)) = turn(pronation, radius, hand) else { continue };
        let flexion = rotations(hand, false).into_iter().find(|&c| model.coordinates[c].name.contains("flex"));
        let radial_world = match flexion.and_then(|c| turn(c, hand, hand)) {
            Some((flex_axis, _)) => flex_axis * sign,
            None => wrist_velocity.cross(&axis),
        };
        let Some(radial_world) = (radial_world - axis * axis.dot(&radial_world)).try_normalize(1e-6) else { continue };
        let Some(radial) = (index - little).try_normalize(1e-9) else { continue };
        let back = ws0.body_rot[radius].transpose();
        out.push(ForearmRoll { radius, radial_local: back * radial_world, axis: back * axis, radial });
    }
    out
}

/// Every vertex's influences at the bind state `y` (bodies at `ws`): segments to their bodies,
/// the torso's weight split along the spine, weights of one body merged, the four largest kept.
fn influences(
    model: &Model,
    asset: &BodyAsset,
    shape: &BodyShape,
    map: &SegmentMap,
    y: &[f64],
    ws: &Workspace,
    model_from_world: &Matrix3<f64>,
) -> Vec<[Influence; 4]> {
    let torso_seg = asset.segment_index("torso");
    let mut out = Vec::with_capacity(shape.vertices.len());
    for (v, skin) in shape.vertices.iter().zip(&asset.skin) {
        let v = model_from_world * v;
        let mut acc: [(usize, f64); 8] = [(0, 0.0); 8];
        let mut n = 0;
        let mut add = |b: usize, w: f64| {
            match acc[..n].iter_mut().find(|a| a.0 == b) {
                Some(a) => a.1 += w,
                None => {
                    acc[n] = (b, w);
                    n += 1;
                }
            };
        };
        for k in 0..4 {
            let (seg, w) = (skin.segments[k] as usize, skin.weights[k] as f64);
            if w <= 0.0 {
                continue;
            }
            match map.spine {
                Some((lo, hi)) if Some(seg) == torso_seg => {
                    let axis = ws.body_pos[hi] - ws.body_pos[lo];
                    let tau = ((v - ws.body_pos[lo]).dot(&axis) / axis.norm_squared()).clamp(0.0, 1.0);
                    add(lo, w * (1.0 - tau));
                    add(hi, w * tau);
                }
                _ => add(map.host[seg], w),
            }
        }
        let acc = &mut acc[..n];
        acc.sort_by(|a, b| b.1.total_cmp(&a.1));
        let kept = &acc[..n.min(4)];
        let total: f64 = kept.iter().map(|a| a.1).sum();
        let mut inf = [Influence::default(); 4];
        for (i, &(b, w)) in kept.iter().enumerate() {
            let i0 = model.scale_index(b, 0);
            let s = Vector3::new(y[i0], y[i0 + 1], y[i0 + 2]);
            let local = (ws.body_rot[b].transpose() * (v - ws.body_pos[b])).component_div(&s);
            inf[i] = Influence { body: b as u16, weight: (w / total) as f32, local: local.map(|x| x as f32).into() };
        }
        out.push(inf);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::context::Context;

    fn report(model: &Model, b: &Binding) {
        eprintln!("iterations {}, errors (mm):", b.iterations);
        for (n, e) in &b.errors {
            eprintln!("  {n:10} {:6.1}", 1e3 * e);
        }
        for c in ["arm_add_r", "arm_add_l", "elbow_flex_r", "hip_adduction_r", "knee_angle_r"] {
            if let Some(i) = model.coordinate_index(c) {
                eprintln!("  {c:16} {:7.1} deg", b.y[i].to_degrees());
            }
        }
    }

    #[test]
    fn shipped_model_binds_to_the_reference_mesh() {
        let asset = BodyAsset::shipped().unwrap();
        let model = Context::shipped().unwrap().model;
        let b = bind(&model, &UnitQuaternion::identity(), &asset, &asset.rest).unwrap();
        report(&model, &b);
        let q = |name: &str| b.y[model.coordinate_index(name).unwrap()];
        assert!(b.errors.len() >= 17, "{:?}", b.errors);
        // the limb joints land on their cubes
        for (n, e) in &b.errors {
            let tol = if ["lumbar5", "lumbar3", "torso"].contains(&n.as_str()) { 0.04 } else { 0.01 };
            assert!(*e < tol, "{n}: {e}");
        }
        // A-pose: both upper arms abducted well away from the sides, the legs apart
        assert!(q("arm_add_r") < -0.4 && q("arm_add_l") < -0.4, "{} {}", q("arm_add_r"), q("arm_add_l"));
        assert!(q("hip_adduction_r") < 0.0 && q("hip_adduction_l") < 0.0);
        // every segment has a body of its own; the torso's skin is shared with lumbar5
        assert!(b.map.own.iter().all(|&o| o));
        let lumbar5 = model.body_index("lumbar5").unwrap();
        assert_eq!(b.map.spine, Some((lumbar5, model.body_index("torso").unwrap())));
        assert!(b.influences.iter().any(|i| i.iter().any(|x| x.body as usize == lumbar5 && x.weight > 0.5)));
        for inf in &b.influences {
            let w: f32 = inf.iter().map(|x| x.weight).sum();
            assert!((w - 1.0).abs() < 1e-5);
        }
    }

    fn opensim(rel: &str) -> Option<Model> {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets").join(rel);
        let text = std::fs::read_to_string(&path).ok()?;
        Some(crate::io::osim::parse_osim(&text, rel).unwrap().0)
    }

    #[test]
    fn opensim_models_bind_with_folded_segments() {
        let asset = BodyAsset::shipped().unwrap();
        // OpenSim models are Y up: the model's Y is the world's Z
        let y_up = crate::model::math::quaternion(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
        for (rel, folded) in [
            ("gait2354_subject01/gait2354_simbody.osim", &["head", "humerus_r", "ulna_r", "radius_r", "hand_r"][..]),
            ("rajagopal2016_walk/Rajagopal2016.osim", &["head"][..]),
            ("opencap_addbiomechanics/unscaled_generic.osim", &["head"][..]),
        ] {
            let Some(model) = opensim(rel) else {
                eprintln!("skipped: {rel} is absent");
                continue;
            };
            eprintln!("{rel}");
            let b = bind(&model, &y_up, &asset, &asset.rest).unwrap();
            report(&model, &b);
            for (i, seg) in asset.segments.iter().enumerate() {
                let right = seg.replace("_l", "_r");
                assert_eq!(!b.map.own[i], folded.contains(&right.as_str()), "{rel}: {seg}");
            }
            let torso = model.body_index("torso").unwrap();
            assert_eq!(b.map.host[asset.segment_index("head").unwrap()], torso);
            assert_eq!(b.map.spine, None);
            for (n, e) in &b.errors {
                let tol = if n == "torso" { 0.05 } else { 0.02 };
                assert!(*e < tol, "{rel}: {n}: {e}");
            }
        }
    }

    #[test]
    fn a_model_without_legs_is_refused_by_name() {
        let asset = BodyAsset::shipped().unwrap();
        let mut model = Context::shipped().unwrap().model;
        for b in &mut model.bodies {
            if b.name.starts_with("tibia") {
                b.name = format!("segment_{}", b.name.len());
            }
        }
        let e = bind(&model, &UnitQuaternion::identity(), &asset, &asset.rest).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("tibia_r") && text.contains("tibia_l"), "{text}");
    }
}
