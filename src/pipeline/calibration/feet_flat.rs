//! Feet flat on the floor in a static trial (`static_feet_flat_sd_deg`, `docs/CALIBRATION.md`).
//!
//! A standing subject's soles rest on the floor, whatever the lean of the shanks: a foot is level
//! when its heel-to-toe line, horizontal at the model's neutral pose, is horizontal again. The
//! static posture prior's neutral (every joint at 0) says the same only for a vertical shank;
//! with the shank leaning a few degrees, "ankle at 0" pitches the sole, and where heel and toe
//! markers sit at different heights on the skin the markers pitch it too. Here each foot's
//! pitching coordinate (the one of the joints between the foot and the nearest ancestor carrying
//! markers that pitches it most: the ankle in the OpenSim family) gets the value that levels it
//! in each static frame's solved pose, averaged over the frames. Only the pitch, as Plug-in
//! Gait's "foot flat" option: the roll of a foot on two markers is not observed, and the
//! subtalar axis, being oblique, would turn the foot's heading with it.

use crate::kinematics::cpu::{forward, Workspace};
use crate::model::proxy::ProxyMap;
use crate::model::roles::RoleTable;
use crate::model::{CoordinateKind, MarkerClass, Model};
use crate::pipeline::context::Context;
use crate::solve::joint::JointState;
use crate::solve::placement::place_markers;
use crate::solve::prior::{FootLevelReport, StaticPosture};
use nalgebra::Vector3;

/// Newton iterations per static frame (the feet start within degrees of level).
const ITERATIONS: usize = 6;
/// Finite-difference step of the pitch's derivative (rad).
const STEP_RAD: f64 = 1e-6;
/// A static foot pitched further than this from level in the first stage's poses (deg) is not
/// levelled, and a warning says so: a subject standing on heels or toes (an equinus foot), not
/// markers put at different heights (which tilt a foot by a few degrees: 1.5–3° on the Plug-in
/// Gait flatfoot subject).
pub const MAX_TILT_DEG: f64 = 10.0;

/// One foot of a model: the body carrying its heel marker, its heel-to-toe direction in its own
/// frame (horizontal at the neutral pose), and the coordinate that pitches it.
#[derive(Clone, Debug, PartialEq)]
pub struct Foot {
    pub body: usize,
    /// Unit heel-to-toe direction, horizontal at the neutral pose (foot frame).
    pub forward: Vector3<f64>,
    pub coordinate: usize,
}

/// One foot levelled.
#[derive(Clone, Debug, PartialEq)]
pub struct FootLevel {
    /// The foot body.
    pub body: usize,
    /// `(coordinate, value)` that levels the foot, averaged over the static frames (rad).
    pub targets: Vec<(usize, f64)>,
    /// The foot's mean pitch from level in the solved static poses, toes up + (deg).
    pub tilt_deg: f64,
}

/// The feet of `model` (`up` its up direction): bodies carrying a marker the role table calls a
/// calcaneus and one it calls a metatarsal head or toe, each with the rotational, unlocked
/// coordinate between it and the nearest ancestor carrying markers that pitches it most at the
/// neutral pose.
pub fn feet(model: &Model, proxy: &ProxyMap, up: &Vector3<f64>) -> Vec<Foot> {
    let roles = RoleTable::shipped();
    let up = up.normalize();
    let has_markers = |b: usize| model.markers.iter().any(|m| m.body == b);
    let role = |m: &crate::model::Marker, what: &str| roles.role_of(&m.name).is_some_and(|(_, w)| w == what);
    let mut ws = Workspace::new(model);
    let y0 = model.default_state();
    forward(model, &y0, &mut ws);
    let mut out = Vec::new();
    for b in 0..model.bodies.len() {
        let heel = model.markers.iter().find(|m| m.body == b && role(m, "calcaneus"));
        let toe = model.markers.iter().find(|m| m.body == b && role(m, "metatarsal head or toe"));
        let (Some(heel), Some(toe)) = (heel, toe) else { continue };
        let along = ws.body_rot[b] * (toe.offset - heel.offset);
        let Some(fwd) = (along - along.dot(&up) * up).try_normalize(1e-9) else { continue };
        let heading = ws.body_rot[b].transpose() * fwd;
        // Candidate coordinates: the joints from the foot up to its nearest marked ancestor.
        let mut coords = Vec::new();
        let mut at = b;
        while let Some(parent) = model.bodies[at].parent {
            for m in &model.motions[model.bodies[at].joint.motions.clone()] {
                if let Some(c) = m.coordinate {
                    let coord = &model.coordinates[c];
                    if !coord.locked && coord.kind == CoordinateKind::Rotational && !coords.contains(&c) {
                        coords.push(c);
                    }
                }
            }
            if has_markers(parent) {
                break;
            }
            at = parent;
        }
        let p0 = proxy.default_proxies();
        let pitch_rate = |c: usize, ws: &mut Workspace| {
            let mut y = proxy.state(&p0);
            y[c] += STEP_RAD;
            forward(model, &y, ws);
            ((ws.body_rot[b] * heading).dot(&up) / STEP_RAD).abs()
        };
        let best = coords.iter().map(|&c| (c, pitch_rate(c, &mut ws))).max_by(|a, b| a.1.total_cmp(&b.1));
        forward(model, &y0, &mut ws);
        if let Some((coordinate, _)) = best.filter(|(_, rate)| *rate > 0.5) {
            out.push(Foot { body: b, forward: heading, coordinate });
        }
    }
    out
}

/// The value of each foot's pitching coordinate that levels it in the static poses `poses`
/// (proxy vectors), `up` the model's up direction (world frame). Empty without feet or poses.
pub fn level_targets(model: &Model, proxy: &ProxyMap, up: &Vector3<f64>, poses: &[Vec<f64>]) -> Vec<FootLevel> {
    let up = up.normalize();
    let feet = feet(model, proxy, &up);
    if feet.is_empty() || poses.is_empty() {
        return Vec::new();
    }
    let mut ws = Workspace::new(model);
    let mut out: Vec<FootLevel> =
        feet.iter().map(|f| FootLevel { body: f.body, targets: vec![(f.coordinate, 0.0)], tilt_deg: 0.0 }).collect();
    for p in poses {
        let mut y = proxy.state(p);
        for (foot, level) in feet.iter().zip(out.iter_mut()) {
            let j = foot.coordinate;
            let mut pitch = |y: &[f64]| {
                forward(model, y, &mut ws);
                (ws.body_rot[foot.body] * foot.forward).dot(&up)
            };
            level.tilt_deg += crate::model::math::asin(pitch(&y).clamp(-1.0, 1.0)).to_degrees();
            for _ in 0..ITERATIONS {
                let r = pitch(&y);
                let keep = y[j];
                y[j] = keep + STEP_RAD;
                let rate = (pitch(&y) - r) / STEP_RAD;
                y[j] = keep;
                if rate.abs() < 1e-6 {
                    break;
                }
                let c = &model.coordinates[j];
                y[j] = (keep - r / rate).clamp(c.range.0, c.range.1);
                if (y[j] - keep).abs() < 1e-10 {
                    break;
                }
            }
            level.targets[0].1 += y[j];
        }
    }
    let n = poses.len() as f64;
    for level in &mut out {
        level.tilt_deg /= n;
        level.targets.iter_mut().for_each(|t| t.1 /= n);
    }
    out
}

/// The feet of a static trial levelled ([`feet_level`]).
#[derive(Clone, Debug)]
pub struct FeetFlat {
    /// The static posture with the levelled feet's coordinates pulled toward level.
    pub posture: StaticPosture,
    /// The feet levelled.
    pub levels: Vec<FootLevel>,
    /// Why a foot was not (pitched beyond [`MAX_TILT_DEG`]).
    pub warnings: Vec<String>,
}

impl FeetFlat {
    /// The levelled feet as the calibration report gives them (names, degrees).
    pub fn report(&self, model: &Model) -> Vec<FootLevelReport> {
        self.levels
            .iter()
            .map(|l| FootLevelReport {
                body: model.bodies[l.body].name.clone(),
                tilt_deg: l.tilt_deg,
                targets: l.targets.iter().map(|&(j, v)| (model.coordinates[j].name.clone(), v.to_degrees())).collect(),
            })
            .collect()
    }
}

/// The static posture with each foot's coordinates pulled toward level in `static_poses`
/// (`static_feet_flat_sd_deg`), the feet pitched less than [`MAX_TILT_DEG`] only; `None` where it
/// does not apply: no static frames, no feet, no up direction, the setting at 0, or an OpenSim
/// Scale setup's static pose.
pub fn feet_level(ctx: &Context, posture: &StaticPosture, static_poses: &[Vec<f64>]) -> Option<FeetFlat> {
    let sd = ctx.settings.static_feet_flat_sd_deg.to_radians();
    if sd <= 0.0 || static_poses.is_empty() || !ctx.static_posture_values.is_empty() {
        return None;
    }
    let found = level_targets(&ctx.model, &ctx.proxy, &ctx.up?, static_poses);
    if found.is_empty() {
        return None;
    }
    let (levels, steep): (Vec<FootLevel>, Vec<FootLevel>) =
        found.into_iter().partition(|l| l.tilt_deg.abs() <= MAX_TILT_DEG);
    let warnings = steep
        .iter()
        .map(|l| {
            format!(
                "static trial: {} is pitched {:+.1}° from level (beyond {MAX_TILT_DEG}°): not levelled (standing on heels or toes? static_feet_flat_sd_deg = 0 leaves every foot as the markers say)",
                ctx.model.bodies[l.body].name, l.tilt_deg
            )
        })
        .collect();
    let mut flat = posture.clone();
    let w = (ctx.settings.prior_noise_sd_m / sd).powi(2);
    for &(j, v) in levels.iter().flat_map(|l| &l.targets) {
        flat.reference[j] = v;
        flat.weights[j] = w;
    }
    Some(FeetFlat { posture: flat, levels, warnings })
}

/// Places each foot's landmarks where the static frames `statics_at` see them with the foot
/// level (the registered poses with the foot's coordinates at the values that level it,
/// [`level_targets`]), as OpenSim's MarkerPlacer places markers on the static
/// pose and Plug-in Gait's "foot flat" defines the foot: a heel marker put higher on the skin
/// than the toe marker then lies higher on the model's foot, instead of tilting it.
/// Only the feet of `feet` (those [`feet_level`] levelled) are placed.
pub fn place_feet_level(
    ctx: &Context,
    feet: &FeetFlat,
    classes: &[MarkerClass],
    seen: &[bool],
    statics_at: &[usize],
    slices: &[&[f64]],
    state: &mut JointState,
) {
    let (model, proxy) = (&ctx.model, &ctx.proxy);
    let Some(up) = ctx.up else { return };
    let poses: Vec<Vec<f64>> = statics_at.iter().map(|&i| state.poses[i].clone()).collect();
    let mut levels = level_targets(model, proxy, &up, &poses);
    levels.retain(|l| feet.levels.iter().any(|k| k.body == l.body));
    let levelled: Vec<Vec<f64>> = poses
        .iter()
        .map(|p| {
            let mut y = proxy.state(p);
            for &(j, v) in levels.iter().flat_map(|l| &l.targets) {
                y[j] = v;
            }
            proxy.proxies_from_state(&y, p)
        })
        .collect();
    let frames: Vec<&[f64]> = statics_at.iter().map(|&i| slices[i]).collect();
    let movable: Vec<bool> = (0..model.markers.len())
        .map(|m| {
            seen[m] && classes[m] == MarkerClass::Anatomical && levels.iter().any(|l| l.body == model.markers[m].body)
        })
        .collect();
    for (m, placed) in place_markers(model, proxy, &frames, &levelled, &movable).into_iter().enumerate() {
        if let Some(p) = placed {
            state.offsets[m] = p;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::Context;

    #[test]
    fn a_pitched_foot_is_levelled_by_its_ankle_angle() {
        let ctx = Context::shipped().expect("shipped");
        let (m, proxy) = (&ctx.model, &ctx.proxy);
        let up = ctx.up.expect("the shipped model has gravity");
        let feet = feet(m, proxy, &up);
        assert_eq!(feet.len(), 2, "{feet:?}");
        assert!(feet.iter().all(|f| m.coordinates[f.coordinate].name.starts_with("ankle_angle")), "{feet:?}");
        // The right thigh 4° forward and its knee bent 8°: the shank leans 4° back; the ankle at 3°.
        let mut y = m.default_state();
        for (name, deg) in [("knee_angle_r", 8.0), ("ankle_angle_r", 3.0), ("hip_flexion_r", 4.0)] {
            y[m.coordinate_index(name).expect(name)] = f64::to_radians(deg);
        }
        let p = proxy.proxies_from_state(&y, &proxy.default_proxies());
        let levels = level_targets(m, proxy, &up, &[p]);
        let right = levels.iter().find(|l| m.bodies[l.body].name == "calcn_r").expect("right foot");
        // The foot pitches by the shank's lean less the ankle's 3°.
        assert!((right.tilt_deg.abs() - 1.0).abs() < 0.2, "{right:?}");
        // Levelled: the ankle takes up the shank's lean.
        let mut yl = y.clone();
        for &(j, v) in &right.targets {
            yl[j] = v;
        }
        let foot = feet.iter().find(|f| f.body == right.body).expect("foot");
        let mut ws = Workspace::new(m);
        forward(m, &yl, &mut ws);
        let pitch = (ws.body_rot[right.body] * foot.forward).dot(&up).asin().to_degrees();
        assert!(pitch.abs() < 0.01, "still pitched {pitch}°: {right:?}");
        assert!((right.targets[0].1.to_degrees() - 4.0).abs() < 0.2, "{right:?}");
    }

    #[test]
    fn a_foot_on_its_toes_is_not_levelled_and_says_so() {
        let ctx = Context::shipped().expect("shipped");
        let (m, proxy) = (&ctx.model, &ctx.proxy);
        let mut y = m.default_state();
        y[m.coordinate_index("ankle_angle_r").expect("ankle")] = f64::to_radians(-20.0);
        y[m.coordinate_index("ankle_angle_l").expect("ankle")] = f64::to_radians(4.0);
        let p = proxy.proxies_from_state(&y, &proxy.default_proxies());
        let posture = StaticPosture::neutral(m, 5f64.to_radians(), 0.01, &[]);
        let flat = feet_level(&ctx, &posture, &[p]).expect("feet");
        let names: Vec<&str> = flat.levels.iter().map(|l| m.bodies[l.body].name.as_str()).collect();
        assert_eq!(names, ["calcn_l"], "{flat:?}");
        assert!(flat.warnings.len() == 1 && flat.warnings[0].contains("calcn_r"), "{:?}", flat.warnings);
        let j = m.coordinate_index("ankle_angle_r").expect("ankle");
        assert_eq!(flat.posture.reference[j], posture.reference[j]);
    }
}
