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
//! **The hips' width.** The rig's `upper-leg` cube sits in the middle of the thigh's top, over
//! the femoral shaft, not over the femoral head, which the femoral neck puts some 4 cm further
//! in: on every OpenSim model tried the cubes are 1.27–1.47× further apart than the model's
//! hip centres (the shipped model: 1.24×). Fitted to them, the bind widened the model's pelvis
//! by as much, so at the subject's own pelvis the skin's pelvis narrowed (OpenCap: 0.72×)
//! against thighs that kept their girth, and the groin folded flat already at rest (DJ5: 63
//! edges under half their bind length; 42 % of its edge-frames out of 0.5–2× in motion came
//! from them). So the hips' pairs leave out their side-to-side part and the pelvis keeps its
//! own width (`PelvisWidth`): the cubes give the hips' height and fore–aft place, the model
//! their width. The hips now sit 3.1–3.9 cm inside the cubes each side (shipped, Rajagopal,
//! OpenCap), and DJ5's edge-frames in range went 99.871 → 99.916 %.
//!
//! The joint centres leave each forearm's roll free: a roll residual (`body/forearm.rs`) turns
//! the radius so that the model's hand lies as the mesh's does (palm toward the thigh),
//! whatever pronation the model calls neutral. Without it the mesh's hand hung on OpenSim's supinated default and
//! walking's 90–120° of pronation twisted the forearm skin flat (edge-frames within 0.5–2× rest
//! on the OpenCap walk: 99.84 % before, 99.91 % with it).
//!
//! Left as it is: the forearm's `radius` takes the rig's distal forearm bone, so pronation
//! twists the wrist end only.

use super::asset::{BodyAsset, BodyShape};
use super::forearm::forearm_rolls;
use super::segments::{find_body, map_segments, BindError, SegmentMap};
use crate::kinematics::cpu::{forward, Workspace};
use crate::model::{CoordinateKind, Model};
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
    /// Per pair of [`targets`]: body name and distance (m) from its origin to its target at `y`
    /// (a hip's without its side-to-side part: the pelvis keeps the model's width).
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
    let mut hips = Vec::new();
    for (b, cubes, w) in targets(model, &map, asset) {
        if cubes.iter().any(|c| c.ends_with("-upper-leg")) {
            hips.push(pairs.len());
        }
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
    let width = PelvisWidth::new(model, hips, &model_from_world, &y0);
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
        if width.as_ref().is_none_or(|w| i != w.scale + w.side) {
            free.push((i, 0.5, 2.0, PRIOR_SCALE));
        }
    }
    let mut ws = Workspace::new(model);
    let mut residual = |y: &[f64]| -> DVector<f64> {
        forward(model, y, &mut ws);
        let mut r = DVector::zeros(3 * pairs.len() + 3 * rolls.len() + free.len());
        for (k, (b, t, w)) in pairs.iter().enumerate() {
            let d = pair_offset(width.as_ref(), &ws, k, ws.body_pos[*b] - t) * *w;
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
    if let Some(w) = &width {
        y[w.scale + w.side] = y0[w.scale + w.side];
    }
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
    let errors = pairs
        .iter()
        .enumerate()
        .map(|(k, (b, t, _))| {
            (model.bodies[*b].name.clone(), pair_offset(width.as_ref(), &ws, k, ws.body_pos[*b] - t).norm())
        })
        .collect();
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

/// The hips' width in the bind (see the module's notes): the pairs of the femurs leave out
/// their part along the pelvis's side-to-side axis, and the pelvis keeps its own scale along
/// that axis (the model's hip width; the mesh has no femoral heads to measure it by).
struct PelvisWidth {
    pelvis: usize,
    /// Indices into the pairs of the hips.
    hips: Vec<usize>,
    /// The pelvis frame's side-to-side axis (0, 1, 2).
    side: usize,
    /// Index of the pelvis's first scale in the state.
    scale: usize,
}

impl PelvisWidth {
    /// Where the model has a pelvis and both hips' pairs (`hips`, their indices): the axis is
    /// the pelvis frame's nearest to the asset's Y (left) at the default state `y0`.
    fn new(model: &Model, hips: Vec<usize>, model_from_world: &Matrix3<f64>, y0: &[f64]) -> Option<PelvisWidth> {
        let pelvis = find_body(model, "pelvis")?;
        let hips = (hips.len() == 2).then_some(hips)?;
        let mut ws = Workspace::new(model);
        forward(model, y0, &mut ws);
        let left = model_from_world * Vector3::y();
        let rot = &ws.body_rot[pelvis];
        let side = (0..3).max_by(|&a, &b| rot.column(a).dot(&left).abs().total_cmp(&rot.column(b).dot(&left).abs()))?;
        Some(PelvisWidth { pelvis, hips, side, scale: model.scale_index(pelvis, 0) })
    }
}

/// Pair `k`'s offset from its target, a hip's without its side-to-side part.
fn pair_offset(width: Option<&PelvisWidth>, ws: &Workspace, k: usize, d: Vector3<f64>) -> Vector3<f64> {
    match width {
        Some(w) if w.hips.contains(&k) => {
            let side = ws.body_rot[w.pelvis].column(w.side).into_owned();
            d - side * side.dot(&d)
        }
        _ => d,
    }
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
    fn hips_sit_inside_the_thigh_cubes_at_the_pelvis_proportions() {
        let asset = BodyAsset::shipped().unwrap();
        let y_up = crate::model::math::quaternion(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
        let cube = |n: &str| asset.rest.joints[asset.joint_index(n).unwrap()];
        let cubes = (cube("joint-l-upper-leg") - cube("joint-r-upper-leg")).norm();
        let mut models = vec![(Context::shipped().unwrap().model, UnitQuaternion::identity())];
        for rel in ["rajagopal2016_walk/Rajagopal2016.osim", "opencap_addbiomechanics/unscaled_generic.osim"] {
            models.extend(opensim(rel).map(|m| (m, y_up)));
        }
        for (model, frame) in &models {
            let b = bind(model, frame, &asset, &asset.rest).unwrap();
            let pelvis = model.body_index("pelvis").unwrap();
            let s = model.scale_index(pelvis, 0);
            let femur = |n: &str| b.body_pos[model.body_index(n).unwrap()];
            let hips = (femur("femur_l") - femur("femur_r")).norm();
            let scales = &b.y[s..s + 3];
            eprintln!("hips {:.1} mm apart, cubes {:.1} mm; pelvis scales {scales:.3?}", hips * 1e3, cubes * 1e3);
            // the femoral heads 2-6 cm inside the thighs' middles, each side, at the model's width
            assert!(hips < cubes - 0.04 && hips > cubes - 0.12, "{hips} {cubes}");
            assert!(scales.iter().filter(|&&x| x == 1.0).count() == 1, "{scales:?}");
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
