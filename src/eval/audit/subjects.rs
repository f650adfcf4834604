//! Synthetic subjects of the leakage audit, with known truth: a morphology (one factor per scale
//! proxy, uniform in `1 ± scale_spread`), markers misplaced on their bodies (constant offsets of
//! `misplace_mm` norm, random direction), soft-tissue-like drift (an offset in the body frame
//! proportional to `sin(q − q_default)` of the coordinate nearest above the marker's body, of
//! `drift_mm` amplitude: smooth and pose-correlated, near zero in the static pose), white
//! noise; a static trial (default pose with slight sway) and a motion trial (the smooth
//! band-limited motion of [`crate::synth`]). Neither method is told the misplacement or drift.

use crate::io::MarkerTrial;
use crate::kinematics::cpu::{self, Workspace};
use crate::model::proxy::ProxyKind;
use crate::model::{CoordinateKind, Model};
use crate::pipeline::Context;
use crate::synth::{synthesize, SynthOptions};
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
    /// Marker misplacement norm, uniform in this range (mm). Default 2–12.
    pub misplace_mm: (f64, f64),
    /// Soft-tissue drift amplitude, uniform in this range (mm). Default 3–10.
    pub drift_mm: (f64, f64),
    /// White noise per axis (mm). Default 1.
    pub noise_mm: f64,
}

impl Default for SubjectSpec {
    fn default() -> Self {
        SubjectSpec {
            static_frames: 100,
            motion_frames: 300,
            scale_spread: 0.1,
            misplace_mm: (2.0, 12.0),
            drift_mm: (3.0, 10.0),
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
    let misplace: Vec<[f64; 3]> = (0..nm)
        .map(|_| {
            let n = rng.random_range(spec.misplace_mm.0..=spec.misplace_mm.1) * 1e-3;
            unit(&mut rng, &normal).map(|c| c * n)
        })
        .collect();
    let drift: Vec<([f64; 3], Option<usize>)> = model
        .markers
        .iter()
        .map(|m| {
            let a = rng.random_range(spec.drift_mm.0..=spec.drift_mm.1) * 1e-3;
            (unit(&mut rng, &normal).map(|c| c * a), drift_coordinate(model, m.body))
        })
        .collect();
    // Static: the default pose at the subject's morphology, swaying by ≤ 0.01 rad.
    let p_motion0 = truth_proxies.first().cloned().unwrap_or_else(|| proxy.default_proxies());
    let default = proxy.default_proxies();
    let sway: Vec<(f64, f64)> =
        (0..proxy.np()).map(|_| (rng.random_range(0.1..0.5), rng.random_range(0.0..TAU))).collect();
    let static_p: Vec<Vec<f64>> = (0..spec.static_frames)
        .map(|f| {
            let t = f as f64 / 100.0;
            (0..proxy.np())
                .map(|k| {
                    let px = &proxy.proxies[k];
                    match px.kind {
                        ProxyKind::Scale => p_motion0[k],
                        ProxyKind::Rotation => {
                            (default[k] + 0.01 * (TAU * sway[k].0 * t + sway[k].1).sin()).clamp(px.range.0, px.range.1)
                        }
                        ProxyKind::Translation => default[k],
                    }
                })
                .collect()
        })
        .collect();
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
