//! Synthetic ground truth: a smooth motion of a model at a chosen morphology, observed through
//! seeded, realistic marker errors (Gaussian noise, constant misplacement, low-frequency
//! soft-tissue-like drift, dropouts). Deterministic for a seed.
//!
//! The motion is generated in proxy space, so the truth is exactly representable by the solver's
//! parametrisation (the spine follows its polynomial coupling).

use crate::io::MarkerTrial;
use crate::kinematics::cpu::{self, Workspace};
use crate::model::proxy::{ProxyKind, ProxyMap};
use crate::model::Model;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};

/// What to synthesise. Lengths in metres, angles in radians.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SynthOptions {
    pub frames: usize,
    pub rate_hz: f64,
    pub seed: u64,
    /// Standard deviation of white marker noise per axis (m).
    pub noise_m: f64,
    /// Norm of each marker's constant misplacement on its body (m).
    pub misplace_m: f64,
    /// Amplitude of each marker's slow soft-tissue-like drift (m).
    pub drift_m: f64,
    /// Fraction of samples missing, in runs of a few frames.
    pub dropout: f64,
    /// Scale proxies are drawn uniformly in `1 ± scale_spread`.
    pub scale_spread: f64,
    /// Walking speed along the model's x axis (m/s).
    pub speed_m_s: f64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            frames: 500,
            rate_hz: 100.0,
            seed: 1,
            noise_m: 0.002,
            misplace_m: 0.0,
            drift_m: 0.0,
            dropout: 0.0,
            scale_spread: 0.1,
            speed_m_s: 1.0,
        }
    }
}

/// The truth behind a synthetic trial.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Truth {
    pub model: String,
    pub options: SynthOptions,
    /// Scale proxy values by proxy name.
    pub scales: BTreeMap<String, f64>,
    /// Per-body scale factors `[sx, sy, sz]`.
    pub body_scales: BTreeMap<String, [f64; 3]>,
    pub coordinate_names: Vec<String>,
    /// Coordinates per frame (rad or m), in `coordinate_names` order.
    pub coordinates: Vec<Vec<f64>>,
    pub proxy_names: Vec<String>,
    /// Proxies per frame.
    pub proxies: Vec<Vec<f64>>,
}

/// A synthetic trial and its truth.
pub struct Synthetic {
    pub trial: MarkerTrial,
    pub truth: Truth,
}

/// Smooth band-limited motion of one proxy: a sum of three sinusoids, 0.2–1.2 Hz.
struct Wave {
    center: f64,
    amp: f64,
    parts: [(f64, f64, f64); 3],
}

impl Wave {
    fn at(&self, t: f64) -> f64 {
        let s: f64 = self.parts.iter().map(|(a, f, ph)| a * crate::model::math::sin(TAU * f * t + ph)).sum();
        self.center + self.amp * s
    }
}

/// Synthesises a trial of `model` driven through `proxy`.
pub fn synthesize(model: &Model, proxy: &ProxyMap, opt: &SynthOptions) -> Synthetic {
    synthesize_with(model, proxy, opt, |_, _| {})
}

/// A motion imposed on the generic one ([`synthesize_motion`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Motion {
    /// The generic motion alone: every proxy a sum of slow waves, the model walking forward.
    #[default]
    Walk,
    /// The generic motion with the right shoulder swinging in flexion, 70° about 50° at 4 Hz
    /// (peak ≈ 1,760°/s): a fast arm, for the solver's continuity checks (issue 32).
    FastArm,
}

/// The right shoulder's flexion proxy of `proxy` (`arm_flex_r`), whose swing [`Motion::FastArm`]
/// imposes.
fn fast_arm_proxy(proxy: &ProxyMap) -> Option<usize> {
    proxy.proxies.iter().position(|p| p.name.contains("arm_flex_r"))
}

/// [`synthesize`] with `motion` imposed; `None` where the model lacks what it moves (a model
/// without an `arm_flex_r` proxy for [`Motion::FastArm`]).
pub fn synthesize_motion(model: &Model, proxy: &ProxyMap, opt: &SynthOptions, motion: Motion) -> Option<Synthetic> {
    match motion {
        Motion::Walk => Some(synthesize(model, proxy, opt)),
        Motion::FastArm => {
            let k = fast_arm_proxy(proxy)?;
            let (mid, amp, hz) = (50f64.to_radians(), 70f64.to_radians(), 4.0);
            Some(synthesize_with(model, proxy, opt, |t, p| p[k] = mid + amp * (TAU * hz * t).sin()))
        }
    }
}

/// As [`synthesize`], with `shape(t, p)` called on each frame's proxies (time `t` in s) after the
/// generic motion is drawn, to impose a motion of one's own on some proxies (a trot, a yoga
/// sequence). The random streams do not depend on `shape`, so the rest of the trial (scales,
/// other proxies, marker errors) is the same as [`synthesize`]'s for the seed.
pub fn synthesize_with(
    model: &Model,
    proxy: &ProxyMap,
    opt: &SynthOptions,
    mut shape: impl FnMut(f64, &mut [f64]),
) -> Synthetic {
    let mut rng = ChaCha8Rng::seed_from_u64(opt.seed);
    let np = proxy.np();
    let default = proxy.default_proxies();
    let mut waves = Vec::with_capacity(np);
    let mut fixed = vec![None; np];
    for (k, px) in proxy.proxies.iter().enumerate() {
        let parts = [0, 1, 2].map(|i| {
            let w = [0.6, 0.3, 0.1][i];
            (w, rng.random_range(0.2..1.2), rng.random_range(0.0..TAU))
        });
        let (lo, hi) = px.range;
        let (center, amp) = match px.kind {
            ProxyKind::Scale => {
                fixed[k] = Some(rng.random_range(1.0 - opt.scale_spread..=1.0 + opt.scale_spread).clamp(lo, hi));
                (0.0, 0.0)
            }
            kind => {
                // Unbounded motion amplitude, and the largest span the range may use (rad or m).
                let (free_amp, cap) = if kind == ProxyKind::Rotation { (0.15, PI) } else { (0.03, 0.2) };
                match (lo.is_finite(), hi.is_finite()) {
                    // Stay inside the central part of the range.
                    (true, true) => {
                        (default[k].clamp(lo + 0.3 * (hi - lo), hi - 0.3 * (hi - lo)), 0.25 * (hi - lo).min(cap))
                    }
                    // One finite end: keep the wave on its side of it.
                    (true, false) => {
                        let c = default[k].max(lo + 2.0 * free_amp);
                        (c, free_amp.min(0.8 * (c - lo)))
                    }
                    (false, true) => {
                        let c = default[k].min(hi - 2.0 * free_amp);
                        (c, free_amp.min(0.8 * (hi - c)))
                    }
                    (false, false) => (default[k], free_amp),
                }
            }
        };
        waves.push(Wave { center, amp, parts });
    }
    // Walk forward along x when the model has a root translation named like one.
    let walk = proxy
        .proxies
        .iter()
        .position(|p| p.kind == ProxyKind::Translation && (p.name.ends_with("_tx") || p.name.ends_with("tx")));

    let nm = model.markers.len();
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    let misplace: Vec<[f64; 3]> = (0..nm)
        .map(|_| {
            let v: [f64; 3] = [0; 3].map(|_| normal.sample(&mut rng));
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-12);
            v.map(|c| c / n * opt.misplace_m)
        })
        .collect();
    let drift: Vec<[(f64, f64); 3]> =
        (0..nm).map(|_| [0; 3].map(|_| (rng.random_range(0.1..0.5), rng.random_range(0.0..TAU)))).collect();

    let mut moved = model.clone();
    for (m, mk) in moved.markers.iter_mut().enumerate() {
        for a in 0..3 {
            mk.offset[a] += misplace[m][a];
        }
    }
    let mut ws = Workspace::new(model);
    let mut dphi = vec![0.0; proxy.terms.len()];
    let mut y = vec![0.0; proxy.ny()];
    let mut positions = Vec::with_capacity(opt.frames * nm * 3);
    let mut truth_q = Vec::with_capacity(opt.frames);
    let mut truth_p = Vec::with_capacity(opt.frames);
    let mut gap_left = vec![0usize; nm];
    let mean_gap = 8.0;
    for f in 0..opt.frames {
        let t = f as f64 / opt.rate_hz;
        let p: Vec<f64> = (0..np).map(|k| fixed[k].unwrap_or_else(|| waves[k].at(t))).collect();
        let mut p = p;
        if let Some(k) = walk {
            let (lo, hi) = proxy.proxies[k].range;
            p[k] = (default[k] + opt.speed_m_s * t + 0.02 * waves[k].at(t)).clamp(lo, hi);
        }
        shape(t, &mut p);
        proxy.apply(&p, &mut y, &mut dphi);
        cpu::forward(&moved, &y, &mut ws);
        for m in 0..nm {
            let missing = if gap_left[m] > 0 {
                gap_left[m] -= 1;
                true
            } else if opt.dropout > 0.0 && rng.random::<f64>() < opt.dropout / mean_gap {
                gap_left[m] = rng.random_range(1..(2 * mean_gap as usize));
                true
            } else {
                false
            };
            for a in 0..3 {
                let (fq, ph) = drift[m][a];
                let v = ws.markers[3 * m + a]
                    + opt.drift_m * crate::model::math::sin(TAU * fq * t + ph)
                    + opt.noise_m * normal.sample(&mut rng);
                positions.push(if missing { f64::NAN } else { v });
            }
        }
        truth_q.push(y[..model.nq()].to_vec());
        truth_p.push(p);
    }
    let y0 = proxy.state(&truth_p.first().cloned().unwrap_or(default));
    let truth = Truth {
        model: model.name.clone(),
        options: opt.clone(),
        scales: proxy.proxies.iter().zip(&fixed).filter_map(|(px, v)| v.map(|v| (px.name.clone(), v))).collect(),
        body_scales: model
            .bodies
            .iter()
            .enumerate()
            .map(|(b, body)| (body.name.clone(), [0, 1, 2].map(|a| y0[model.scale_index(b, a)])))
            .collect(),
        coordinate_names: model.coordinates.iter().map(|c| c.name.clone()).collect(),
        coordinates: truth_q,
        proxy_names: proxy.proxies.iter().map(|p| p.name.clone()).collect(),
        proxies: truth_p,
    };
    let trial = MarkerTrial {
        labels: model.markers.iter().map(|m| m.name.clone()).collect(),
        rate_hz: opt.rate_hz,
        times: (0..opt.frames).map(|f| f as f64 / opt.rate_hz).collect(),
        frame_numbers: (1..=opt.frames as i64).collect(),
        positions,
        source_units: "m".into(),
        warnings: Vec::new(),
    };
    Synthetic { trial, truth }
}

/// A periodic gait for [`synthesize_with`]: every bounded rotational proxy for which
/// `phase_of(name)` gives a phase `φ` (rad) swings as `c + a·sin(2π·f·t + φ)` with amplitude
/// `a = 0.15·(hi − lo)` about the proxy's default (the neutral pose), moved inward where needed to stay
/// in the range (`c ∈ [lo + a, hi − a]`), replacing the generic motion; the other proxies keep
/// theirs. For a trot, the diagonal limbs share a phase and the two diagonals are
/// half a cycle apart (see `tests/models_dog.rs`).
pub fn periodic_gait(
    proxy: &ProxyMap,
    freq_hz: f64,
    phase_of: impl Fn(&str) -> Option<f64>,
) -> impl FnMut(f64, &mut [f64]) {
    let swings: Vec<(usize, f64, f64, f64)> = proxy
        .proxies
        .iter()
        .enumerate()
        .filter(|(_, p)| p.kind == ProxyKind::Rotation && p.range.0.is_finite() && p.range.1.is_finite())
        .filter_map(|(k, p)| {
            let a = 0.15 * (p.range.1 - p.range.0);
            phase_of(&p.name).map(|ph| (k, p.default.clamp(p.range.0 + a, p.range.1 - a), a, ph))
        })
        .collect();
    move |t: f64, p: &mut [f64]| {
        for &(k, mid, amp, ph) in &swings {
            p[k] = mid + amp * crate::model::math::sin(TAU * freq_hz * t + ph);
        }
    }
}
