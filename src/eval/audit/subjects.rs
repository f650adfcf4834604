//! Synthetic subjects of the leakage audit, with known truth: a morphology (one factor per scale
//! proxy, uniform in `1 ± scale_spread`), markers misplaced on their bodies (constant offsets of
//! `misplace_mm` norm, random direction), soft-tissue-like drift (an offset in the body frame
//! proportional to `sin(q − q_default)` of the coordinate nearest above the marker's body, of
//! `drift_mm` amplitude: smooth and pose-correlated, near zero in the static pose), white
//! noise; a static trial (default pose with slight sway) and a motion trial (the smooth
//! band-limited motion of [`crate::kinematics::synth`]). Neither method is told the misplacement or drift.

use crate::io::MarkerTrial;
use crate::kinematics::cpu::{self, Workspace};
use crate::kinematics::synth::{synthesize, SynthOptions};
use crate::model::proxy::ProxyKind;
use crate::model::{CoordinateKind, Model};
use crate::pipeline::Context;
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// How synthetic subjects are made (lengths in mm as named, frames at 100 Hz).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SubjectSpec {
    pub static_frames: usize,
    pub motion_frames: usize,
    /// Scale factors uniform in `1 ± scale_spread`. Default 0.1.
    pub scale_spread: f64,
    /// Misplacement norm of landmarks (and of every marker unless `tracking_misplace_mm` says
    /// otherwise), uniform in this range (mm). Default 2–12.
    pub misplace_mm: (f64, f64),
    /// Landmarks misplaced along the skin (perpendicular to the direction from their segment's
    /// long axis, as a hand placing a marker on a bony landmark errs) rather than in any
    /// direction. Default false.
    #[serde(default)]
    pub along_skin: bool,
    /// Misplacement norm of tracking markers (wands, clusters), when other than `misplace_mm`.
    #[serde(default)]
    pub tracking_misplace_mm: Option<(f64, f64)>,
    /// Tracking markers turned about their segment's long axis by an angle uniform in this range
    /// (deg, either way): a wand or cluster strapped on at its own angle. Default none.
    #[serde(default)]
    pub tracking_rotation_deg: Option<(f64, f64)>,
    /// Soft-tissue drift amplitude of landmarks (and of every marker unless `tracking_drift_mm`
    /// says otherwise), uniform in this range (mm). Default 3–10.
    pub drift_mm: (f64, f64),
    /// Soft-tissue drift amplitude of tracking markers, when other than `drift_mm`.
    #[serde(default)]
    pub tracking_drift_mm: Option<(f64, f64)>,
    /// The static trial's posture: each coordinate a standing posture holds departs from neutral
    /// by a normal deviate of this standard deviation (deg). Default 0 (exactly neutral).
    #[serde(default)]
    pub static_posture_sd_deg: f64,
    /// The static trial's feet rest flat on the floor: each foot's ankle takes up what the
    /// posture's deviations above it pitch it by, as a standing subject's does (otherwise a
    /// joint's deviation tilts the sole, a stance on heels or toes). Default false.
    #[serde(default)]
    pub static_feet_flat: bool,
    /// White noise per axis (mm). Default 1.
    pub noise_mm: f64,
}

impl SubjectSpec {
    /// Markers as a lab places them on skin: landmarks misplaced 10–20 mm along the skin, wands
    /// and clusters 30–60 mm and turned by 10–20° about their segment, soft tissue moving
    /// landmarks by 3–10 mm and wands by 10–20 mm with the joints, a standing posture 2° from
    /// neutral per joint (legs and trunk; the arms hang at the model's neutral, swaying only, which
    /// `smocap audit` tells both methods as `static_arms = "neutral"`), 1 mm noise.
    pub fn realistic() -> SubjectSpec {
        SubjectSpec {
            misplace_mm: (10.0, 20.0),
            along_skin: true,
            tracking_misplace_mm: Some((30.0, 60.0)),
            tracking_rotation_deg: Some((10.0, 20.0)),
            drift_mm: (3.0, 10.0),
            tracking_drift_mm: Some((10.0, 20.0)),
            static_posture_sd_deg: 2.0,
            static_feet_flat: true,
            ..SubjectSpec::default()
        }
    }
}

impl Default for SubjectSpec {
    fn default() -> Self {
        SubjectSpec {
            static_frames: 100,
            motion_frames: 300,
            scale_spread: 0.1,
            misplace_mm: (2.0, 12.0),
            along_skin: false,
            tracking_misplace_mm: None,
            tracking_rotation_deg: None,
            drift_mm: (3.0, 10.0),
            tracking_drift_mm: None,
            static_posture_sd_deg: 0.0,
            static_feet_flat: false,
            noise_mm: 1.0,
        }
    }
}

/// One subject: its trials and its truth.
pub struct SyntheticSubject {
    pub static_trial: MarkerTrial,
    pub motion: MarkerTrial,
    /// True proxies of the motion frames (scale entries: the morphology).
    pub truth_proxies: Vec<Vec<f64>>,
    /// True coordinates of the motion frames (rad or m).
    pub truth_q: Vec<Vec<f64>>,
}

/// The coordinate that drives a marker's drift: the first rotational coordinate of the joint of
/// its body or of the nearest ancestor whose joint has one.
fn drift_coordinate(model: &Model, body: usize) -> Option<usize> {
    let mut b = Some(body);
    while let Some(i) = b {
        let j = &model.bodies[i].joint;
        let c = model.motions[j.motions.clone()]
            .iter()
            .filter_map(|m| m.coordinate)
            .find(|&c| model.coordinates[c].kind == CoordinateKind::Rotational && !model.coordinates[c].locked);
        if c.is_some() {
            return c;
        }
        b = model.bodies[i].parent;
    }
    None
}

fn unit(rng: &mut ChaCha8Rng, normal: &Normal<f64>) -> [f64; 3] {
    let v: [f64; 3] = [0; 3].map(|_| normal.sample(rng));
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-12);
    v.map(|c| c / n)
}

/// Per body, the unit direction of its long axis in its frame: toward its first child's joint, else
/// toward the centroid of its markers, else the body's z axis.
fn long_axes(model: &Model) -> Vec<Vector3<f64>> {
    (0..model.bodies.len())
        .map(|b| {
            let child =
                model.bodies.iter().find(|c| c.parent == Some(b)).map(|c| c.joint.parent_offset.translation.vector);
            let markers: Vec<Vector3<f64>> = model.markers.iter().filter(|m| m.body == b).map(|m| m.offset).collect();
            let centroid = (!markers.is_empty()).then(|| markers.iter().sum::<Vector3<f64>>() / markers.len() as f64);
            child
                .filter(|v| v.norm() > 1e-6)
                .or(centroid.filter(|v| v.norm() > 1e-6))
                .map_or(Vector3::z(), |v| v.normalize())
        })
        .collect()
}

/// Subject `index` of the audit with base seed `seed` (deterministic).
pub fn subject(ctx: &Context, spec: &SubjectSpec, seed: u64, index: usize) -> SyntheticSubject {
    let s = seed.wrapping_mul(7919).wrapping_add(index as u64);
    let (model, proxy) = (&ctx.model, &ctx.proxy);
    let motion = synthesize(
        model,
        proxy,
        &SynthOptions {
            frames: spec.motion_frames,
            seed: s,
            noise_m: 0.0,
            scale_spread: spec.scale_spread,
            ..SynthOptions::default()
        },
    );
    let truth_proxies = motion.truth.proxies;
    let mut rng = ChaCha8Rng::seed_from_u64(s ^ 0x5eed_a0d1);
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    let nm = model.markers.len();
    let tracking: Vec<bool> = ctx.marker_classes().iter().map(|c| *c == crate::model::MarkerClass::Tracking).collect();
    let axes = long_axes(model);
    let misplace: Vec<[f64; 3]> = (0..nm)
        .map(|m| {
            let range =
                if tracking[m] { spec.tracking_misplace_mm.unwrap_or(spec.misplace_mm) } else { spec.misplace_mm };
            let n = rng.random_range(range.0..=range.1) * 1e-3;
            let mut d = Vector3::from(unit(&mut rng, &normal));
            let o = model.markers[m].offset;
            let u = axes[model.markers[m].body];
            if spec.along_skin && !tracking[m] {
                // Tangent to the skin: no component along the radial direction from the axis.
                let radial = o - u * o.dot(&u);
                if radial.norm() > 1e-6 {
                    let r = radial.normalize();
                    d -= r * d.dot(&r);
                    d = d.try_normalize(1e-12).unwrap_or_else(|| u.cross(&r).normalize());
                }
            }
            let mut moved = o + d * n;
            if let (true, Some((lo, hi))) = (tracking[m], spec.tracking_rotation_deg) {
                let angle = rng.random_range(lo..=hi).to_radians() * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                moved = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(u), angle) * moved;
            }
            (moved - o).into()
        })
        .collect();
    let drift: Vec<([f64; 3], Option<usize>)> = model
        .markers
        .iter()
        .enumerate()
        .map(|(m, mk)| {
            let range = if tracking[m] { spec.tracking_drift_mm.unwrap_or(spec.drift_mm) } else { spec.drift_mm };
            let a = rng.random_range(range.0..=range.1) * 1e-3;
            (unit(&mut rng, &normal).map(|c| c * a), drift_coordinate(model, mk.body))
        })
        .collect();
    // Static: the default pose at the subject's morphology, swaying by ≤ 0.01 rad.
    let p_motion0 = truth_proxies.first().cloned().unwrap_or_else(|| proxy.default_proxies());
    let default = proxy.default_proxies();
    let sway: Vec<(f64, f64)> =
        (0..proxy.np()).map(|_| (rng.random_range(0.1..0.5), rng.random_range(0.0..TAU))).collect();
    // A standing posture: each proxy of a coordinate the posture holds a little off neutral.
    let held = crate::solve::prior::StaticPosture::held_coordinates(model);
    let stance: Vec<f64> = (0..proxy.np())
        .map(|k| {
            let holds = proxy.proxies[k].kind == ProxyKind::Rotation
                && proxy.terms.iter().any(|t| t.proxy == k && held.get(t.y_index).copied().unwrap_or(false));
            if holds && spec.static_posture_sd_deg > 0.0 {
                spec.static_posture_sd_deg.to_radians() * normal.sample(&mut rng)
            } else {
                0.0
            }
        })
        .collect();
    let static_p: Vec<Vec<f64>> = (0..spec.static_frames)
        .map(|f| {
            let t = f as f64 / 100.0;
            (0..proxy.np())
                .map(|k| {
                    let px = &proxy.proxies[k];
                    match px.kind {
                        ProxyKind::Scale => p_motion0[k],
                        ProxyKind::Rotation => {
                            (default[k] + stance[k] + 0.01 * (TAU * sway[k].0 * t + sway[k].1).sin())
                                .clamp(px.range.0, px.range.1)
                        }
                        ProxyKind::Translation => default[k],
                    }
                })
                .collect()
        })
        .collect();
    // Feet flat: each foot's ankle levels it in the frame's pose.
    let static_p: Vec<Vec<f64>> = match (spec.static_feet_flat, ctx.up) {
        (true, Some(up)) => static_p
            .into_iter()
            .map(|p| {
                let mut y = proxy.state(&p);
                for &(j, v) in
                    crate::pipeline::calibration::feet_flat::level_targets(model, proxy, &up, std::slice::from_ref(&p))
                        .iter()
                        .flat_map(|l| &l.targets)
                {
                    y[j] = v;
                }
                proxy.proxies_from_state(&y, &p)
            })
            .collect(),
        _ => static_p,
    };
    let q_default: Vec<f64> = model.coordinates.iter().map(|c| c.default).collect();
    let render = |ps: &[Vec<f64>], rng: &mut ChaCha8Rng| -> (MarkerTrial, Vec<Vec<f64>>) {
        let mut moved = model.clone();
        let mut ws = Workspace::new(model);
        let mut y = vec![0.0; proxy.ny()];
        let mut dphi = vec![0.0; proxy.terms.len()];
        let mut positions = Vec::with_capacity(ps.len() * nm * 3);
        let mut qs = Vec::with_capacity(ps.len());
        for p in ps {
            proxy.apply(p, &mut y, &mut dphi);
            for (m, mk) in moved.markers.iter_mut().enumerate() {
                let (d, c) = drift[m];
                let w = c.map_or(0.0, |c| (y[c] - q_default[c]).sin());
                for a in 0..3 {
                    mk.offset[a] = model.markers[m].offset[a] + misplace[m][a] + w * d[a];
                }
            }
            cpu::forward(&moved, &y, &mut ws);
            positions.extend(ws.markers[..3 * nm].iter().map(|v| v + spec.noise_mm * 1e-3 * normal.sample(rng)));
            qs.push(y[..model.nq()].to_vec());
        }
        let n = ps.len();
        let trial = MarkerTrial {
            labels: model.markers.iter().map(|m| m.name.clone()).collect(),
            rate_hz: 100.0,
            times: (0..n).map(|f| f as f64 / 100.0).collect(),
            frame_numbers: (1..=n as i64).collect(),
            positions,
            source_units: "m".into(),
            warnings: Vec::new(),
        };
        (trial, qs)
    };
    let (static_trial, _) = render(&static_p, &mut rng);
    let (motion, truth_q) = render(&truth_proxies, &mut rng);
    SyntheticSubject { static_trial, motion, truth_proxies, truth_q }
}
