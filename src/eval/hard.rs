//! The hard synthetic set of the pre-solve evaluation: one subject (the shipped model at seeded
//! scales, from [`crate::kinematics::synth`]) through four kinds of hard frames, each deterministic for a
//! seed. Lengths in metres, angles in radians.
//!
//! - `pirouette`: the base motion with the root turning about the vertical in bursts of up to
//!   3 rev/s, sampled at 60 Hz (up to 18° between frames);
//! - `extreme`: key poses with about half of the bounded pose proxies near an end of their
//!   range (within 5–20 % of it: deep squats, high kicks, full spine flexion, arms overhead),
//!   blended over 0.4 s, 100 Hz;
//! - `dropout`: large key-pose motion (targets anywhere in 10–90 % of each range) while the
//!   markers of a random body and its subtree vanish for 0.2–0.6 s every 0.5 s, 100 Hz;
//! - `twisted`: frames of the base motion solved one by one from twisted initial guesses: the
//!   truth with the root turned 90–180°, or the left and right limbs swapped and the root turned
//!   180°, or every axial rotation proxy at the far end of its range.

use crate::io::MarkerTrial;
use crate::kinematics::cpu::{self, Workspace};
use crate::kinematics::synth::{synthesize, SynthOptions, Synthetic};
use crate::model::proxy::{ProxyKind, ProxyMap};
use crate::model::Model;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::f64::consts::{PI, TAU};

/// One hard case: a trial with its truth, and for `twisted` the initial guess of every frame.
pub struct HardCase {
    pub name: &'static str,
    pub trial: MarkerTrial,
    /// Truth proxies per frame.
    pub truth: Vec<Vec<f64>>,
    /// Initial guesses per frame: the frames are solved independently from these instead of
    /// as a trial.
    pub guesses: Option<Vec<Vec<f64>>>,
}

/// The base motion of the subject (2 mm noise, 100 Hz): what the subject is calibrated on.
pub fn base(model: &Model, proxy: &ProxyMap, frames: usize, seed: u64) -> Synthetic {
    synthesize(model, proxy, &SynthOptions { frames, seed, ..SynthOptions::default() })
}

/// The four hard cases of `frames` frames each for seed `seed`.
pub fn hard_set(model: &Model, proxy: &ProxyMap, frames: usize, seed: u64) -> Vec<HardCase> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_4a2d);
    let heading = heading_proxy(model, proxy);
    let mut cases = Vec::new();

    // Pirouettes: the base motion at 60 Hz, the heading driven by bursts of spinning.
    let spin_base = synthesize(model, proxy, &SynthOptions { frames, seed, rate_hz: 60.0, ..SynthOptions::default() });
    let mut truth = spin_base.truth.proxies.clone();
    if let Some(k) = heading {
        let (mut angle, dir) = (0.0, if rng.random::<bool>() { 1.0 } else { -1.0 });
        for (f, p) in truth.iter_mut().enumerate() {
            // Each 2 s: a 1 s burst whose speed rises and falls as sin², peak 3 rev/s.
            let t = f as f64 / 60.0;
            let phase = t % 2.0;
            let omega = if phase < 1.0 { 3.0 * TAU * (PI * phase).sin().powi(2) } else { 0.0 };
            angle += dir * omega / 60.0;
            p[k] += angle;
        }
    }
    cases.push(case("pirouette", model, proxy, truth, 60.0, &[], &mut rng));

    let base_motion = base(model, proxy, frames, seed);
    // Extreme poses near the ends of the ranges.
    let truth = key_pose_motion(proxy, &base_motion.truth.proxies, 100.0, 0.4, 0.2, &mut rng, |rng| {
        let u = rng.random_range(0.05..0.2);
        if rng.random::<bool>() {
            u
        } else {
            1.0 - u
        }
    });
    cases.push(case("extreme", model, proxy, truth, 100.0, &[], &mut rng));

    // Dropout bursts during large motion.
    let truth =
        key_pose_motion(proxy, &base_motion.truth.proxies, 100.0, 0.5, 0.0, &mut rng, |rng| rng.random_range(0.1..0.9));
    let carriers: Vec<usize> = (0..model.nb())
        .filter(|&b| model.bodies[b].parent.is_some() && model.markers.iter().any(|m| m.body == b))
        .collect();
    let mut gaps = Vec::new();
    let mut f = 20;
    while f < frames {
        let b = carriers[rng.random_range(0..carriers.len())];
        let len = rng.random_range(20..60);
        for (m, mk) in model.markers.iter().enumerate() {
            if model.is_ancestor(b, mk.body) {
                gaps.push((m, f, (f + len).min(frames)));
            }
        }
        f += 50;
    }
    cases.push(case("dropout", model, proxy, truth, 100.0, &gaps, &mut rng));

    // Twisted initial guesses for independent frames of the base motion.
    let truth = base_motion.truth.proxies.clone();
    let guesses = truth.iter().map(|p| twist(proxy, heading, p, &mut rng)).collect();
    let mut c = case("twisted", model, proxy, truth, 100.0, &[], &mut rng);
    c.guesses = Some(guesses);
    cases.push(c);
    cases
}

/// The first rotation proxy of the root joint (the heading of the shipped model, about z).
fn heading_proxy(model: &Model, proxy: &ProxyMap) -> Option<usize> {
    let root = model.bodies.iter().position(|b| b.parent.is_none())?;
    model.motions[model.bodies[root].joint.motions.clone()]
        .iter()
        .filter_map(|mo| mo.coordinate)
        .flat_map(|c| proxy.y_terms[c].clone().map(|t| proxy.terms[t].proxy))
        .find(|&k| proxy.proxies[k].kind == ProxyKind::Rotation)
}

/// Bounded pose proxies move between key poses (each at `pick(rng)` of its range), blended
/// with a cosine over `blend_s` and held `hold_s`; other proxies follow `base`.
fn key_pose_motion(
    proxy: &ProxyMap,
    base: &[Vec<f64>],
    rate_hz: f64,
    blend_s: f64,
    hold_s: f64,
    rng: &mut ChaCha8Rng,
    mut pick: impl FnMut(&mut ChaCha8Rng) -> f64,
) -> Vec<Vec<f64>> {
    let bounded: Vec<usize> = (0..proxy.np())
        .filter(|&k| {
            let px = &proxy.proxies[k];
            px.kind != ProxyKind::Scale && px.range.0.is_finite() && px.range.1.is_finite() && px.range.1 > px.range.0
        })
        .collect();
    let mut key = |rng: &mut ChaCha8Rng, from: &[f64]| -> Vec<f64> {
        let mut p = from.to_vec();
        for &k in &bounded {
            let (lo, hi) = proxy.proxies[k].range;
            p[k] = if rng.random::<bool>() { lo + pick(rng) * (hi - lo) } else { from[k] };
        }
        p
    };
    let period = ((blend_s + hold_s) * rate_hz).round().max(1.0) as usize;
    let blend = (blend_s * rate_hz).round().max(1.0) as usize;
    let mut from = key(rng, &base[0]);
    let mut to = key(rng, &from);
    let mut out = Vec::with_capacity(base.len());
    for (f, b) in base.iter().enumerate() {
        let i = f % period;
        if i == 0 && f > 0 {
            from = to;
            to = key(rng, &from);
        }
        let w = if i >= blend { 1.0 } else { 0.5 - 0.5 * (PI * i as f64 / blend as f64).cos() };
        let mut p = b.clone();
        for &k in &bounded {
            p[k] = from[k] + w * (to[k] - from[k]);
        }
        out.push(p);
    }
    out
}

/// A twisted initial guess from the truth `p` (one of three kinds, chosen at random).
fn twist(proxy: &ProxyMap, heading: Option<usize>, p: &[f64], rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut g = p.to_vec();
    let turn = |g: &mut Vec<f64>, a: f64| {
        if let Some(k) = heading {
            g[k] += a;
        }
    };
    match rng.random_range(0..3) {
        0 => {
            let a = rng.random_range(0.5 * PI..PI);
            turn(&mut g, if rng.random::<bool>() { a } else { -a });
        }
        1 => {
            // Mirrored: left and right limbs swapped, facing the other way.
            for (k, px) in proxy.proxies.iter().enumerate() {
                if px.kind == ProxyKind::Scale {
                    continue;
                }
                if let Some(stem) = px.name.strip_suffix("_r") {
                    if let Some(l) = proxy.proxy_index(&format!("{stem}_l")) {
                        g[k] = p[l];
                        g[l] = p[k];
                    }
                }
            }
            turn(&mut g, PI);
        }
        _ => {
            // Axial rotations at the far end of their ranges.
            for (k, px) in proxy.proxies.iter().enumerate() {
                let axial = ["rotation", "rot", "pro_sup"].iter().any(|s| px.name.contains(s));
                let (lo, hi) = px.range;
                if px.kind == ProxyKind::Rotation && axial && lo.is_finite() && hi.is_finite() {
                    g[k] = if p[k] > 0.5 * (lo + hi) { lo + 0.05 * (hi - lo) } else { hi - 0.05 * (hi - lo) };
                }
            }
        }
    }
    for (k, px) in proxy.proxies.iter().enumerate() {
        g[k] = g[k].clamp(px.range.0, px.range.1);
    }
    g
}

/// Observes `truth` (2 mm white noise; `gaps` as `(marker, from, to)` frame ranges missing).
fn case(
    name: &'static str,
    model: &Model,
    proxy: &ProxyMap,
    truth: Vec<Vec<f64>>,
    rate_hz: f64,
    gaps: &[(usize, usize, usize)],
    rng: &mut ChaCha8Rng,
) -> HardCase {
    let nm = model.markers.len();
    let normal = Normal::new(0.0, 0.002).expect("noise");
    let mut ws = Workspace::new(model);
    let mut y = vec![0.0; proxy.ny()];
    let mut dphi = vec![0.0; proxy.terms.len()];
    let mut positions = Vec::with_capacity(truth.len() * nm * 3);
    for p in &truth {
        proxy.apply(p, &mut y, &mut dphi);
        cpu::forward(model, &y, &mut ws);
        positions.extend(ws.markers.iter().map(|x| x + normal.sample(rng)));
    }
    for &(m, a, b) in gaps {
        for f in a..b {
            positions[(f * nm + m) * 3..(f * nm + m) * 3 + 3].fill(f64::NAN);
        }
    }
    let n = truth.len();
    let trial = MarkerTrial {
        labels: model.markers.iter().map(|m| m.name.clone()).collect(),
        rate_hz,
        times: (0..n).map(|f| f as f64 / rate_hz).collect(),
        frame_numbers: (1..=n as i64).collect(),
        positions,
        source_units: "m".into(),
        warnings: Vec::new(),
    };
    HardCase { name, trial, truth, guesses: None }
}
