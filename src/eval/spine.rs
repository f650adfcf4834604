//! Spine ablation on the shipped model: the lumbar spine driven by three proxies through its
//! polynomial couplings ("poly", the shipped profile), every vertebral coordinate free ("nopoly")
//! and a rigid lumbar column with one 3-DoF joint ("classical"), solved on the same synthetic
//! yoga-like trial. Reports marker RMSE, temporal roughness of each spine coordinate, spatial
//! roughness along the spine, ms/frame and iterations (METHOD.md, "Evaluation").
//!
//! The truth is fair to all three: its spine follows the poly coupling's shares with slowly
//! varying per-level deviations (each level's share of the total angle wanders by
//! ±`deviation` of itself), clipped to the model's per-level ranges; so poly cannot fit it
//! exactly, nopoly can but is weakly observed (one lumbar marker, L3), and classical cannot.

use crate::io::mjcf;
use crate::kinematics::synth::{synthesize_with, SynthOptions, Synthetic};
use crate::model::profile::{Coupling, Profile};
use crate::model::proxy::ProxyKind;
use crate::pipeline::context::{SHIPPED_MODEL, SHIPPED_PROFILE};
use crate::pipeline::results::report::{trial_report, PoseError, ScaleError};
use crate::pipeline::stats::{MeanP50P90, P50P90};
use crate::pipeline::{calibrate_subject, solve_trial_with, Context};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};
use std::path::Path;

/// Lumbar levels of the shipped model, caudal to cranial.
pub const LEVELS: [&str; 6] = ["L5_S1", "L4_L5", "L3_L4", "L2_L3", "L1_L2", "T12_L1"];
/// Motions of each level; the poly proxies are `lumbar_<axis>`.
pub const AXES: [&str; 3] = ["flexion", "bending", "rotation"];

/// The three spine parametrisations compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Variant {
    /// The shipped profile: three proxies drive the 18 level coordinates through polynomials.
    Poly,
    /// The couplings removed: each of the 18 level coordinates is its own proxy.
    Nopoly,
    /// One level free (its three coordinates driven one-to-one by the `lumbar_*` proxies over the
    /// whole-spine ranges), the other five levels fixed at 0.
    Classical,
}

impl Variant {
    pub const ALL: [Variant; 3] = [Variant::Poly, Variant::Nopoly, Variant::Classical];
    pub fn name(self) -> &'static str {
        match self {
            Variant::Poly => "poly",
            Variant::Nopoly => "nopoly",
            Variant::Classical => "classical",
        }
    }
}

/// What to run. Angles in radians, lengths in metres.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SpineOptions {
    pub frames: usize,
    pub rate_hz: f64,
    pub seed: u64,
    /// White marker noise per axis (m). Default 0.002.
    pub noise_m: f64,
    /// Amplitude of each level's deviation from its coupling share, as a fraction of the share.
    /// Default 0.3.
    pub deviation: f64,
    /// The level left free in the classical variant. Default `L3_L4`: the level nearest the
    /// centroid of the flexion shares (1.106 m above the floor at the neutral pose; L3_L4 is at
    /// 1.096 m), flexion being the largest lumbar motion.
    pub classical_level: String,
    /// Times each variant solves the trial (round-robin) for ms/frame. Default 3.
    pub repeats: usize,
}

impl Default for SpineOptions {
    fn default() -> Self {
        SpineOptions {
            frames: 2000,
            rate_hz: 100.0,
            seed: 1,
            noise_m: 0.002,
            deviation: 0.3,
            classical_level: "L3_L4".into(),
            repeats: 3,
        }
    }
}

/// Roughness of the 18 spine coordinates over a trial (deg², mean squared second differences).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Roughness {
    /// Per coordinate: mean over frames of `(q[t+1] − 2q[t] + q[t−1])²` (deg²/frame²).
    pub temporal_deg2: BTreeMap<String, f64>,
    /// Per axis (flexion, bending, rotation): the mean of `temporal_deg2` over the six levels.
    pub temporal_axis_deg2: [f64; 3],
    /// Per axis: mean over frames and the four inner levels of `(q[i+1] − 2q[i] + q[i−1])²`
    /// across levels L5_S1 … T12_L1 (deg²).
    pub spatial_axis_deg2: [f64; 3],
    /// Mean of `spatial_axis_deg2`.
    pub spatial_deg2: f64,
}

/// One variant's results.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct VariantReport {
    pub variant: Variant,
    /// Pose proxies (degrees of freedom) in all, and of the lumbar spine.
    pub pose_proxies: usize,
    pub spine_proxies: usize,
    pub marker_rmse_mm: MeanP50P90,
    /// One thread, one lane (frames warm-started in sequence), calibration excluded; over the
    /// frames of all repeats.
    pub ms_per_frame: P50P90,
    pub iterations: P50P90,
    /// All moved rotational coordinates against the truth.
    pub pose_error_deg: Option<PoseError>,
    pub scale_error_pct: Option<ScaleError>,
    /// RMSE of the 18 spine coordinates against the truth (deg).
    pub spine_error_deg: f64,
    /// Per axis: RMSE of the total pelvis-to-thorax angle (sum over levels) against the truth (deg).
    pub total_angle_error_deg: [f64; 3],
    pub roughness: Roughness,
}

/// The whole ablation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SpineReport {
    pub options: SpineOptions,
    /// Roughness of the true spine motion, for reference.
    pub truth: Roughness,
    pub variants: Vec<VariantReport>,
}

/// Errors running the ablation.
#[derive(Debug, thiserror::Error)]
pub enum SpineError {
    #[error("shipped model: {0}")]
    Model(#[from] crate::io::mjcf::MjcfError),
    #[error("shipped profile: {0}")]
    Profile(#[from] crate::model::profile::ProfileError),
    #[error(transparent)]
    Context(#[from] crate::pipeline::ContextError),
    #[error(transparent)]
    Trial(#[from] crate::pipeline::TrialError),
    #[error("the shipped profile has no coupling '{0}' over the six lumbar levels")]
    MissingCoupling(String),
    #[error("classical level '{0}' is not a lumbar level (L5_S1, L4_L5, L3_L4, L2_L3, L1_L2, T12_L1)")]
    BadLevel(String),
}

fn coordinate(level: &str, axis: &str) -> String {
    format!("{level}_{axis}")
}

/// The shipped profile's coupling of `axis` (`lumbar_<axis>`), checked to cover the six levels.
fn coupling<'a>(base: &'a Profile, axis: &str) -> Result<&'a Coupling, SpineError> {
    let name = format!("lumbar_{axis}");
    base.couplings
        .iter()
        .find(|c| c.proxy == name && c.coordinates.iter().cloned().eq(LEVELS.iter().map(|l| coordinate(l, axis))))
        .ok_or(SpineError::MissingCoupling(name))
}

/// The profile of `variant`, derived from the shipped (poly) profile `base`; everything but the
/// lumbar couplings (scale groups, marker weights, settings) is kept.
pub fn variant_profile(base: &Profile, variant: Variant, classical_level: &str) -> Result<Profile, SpineError> {
    let mut p = base.clone();
    let lumbar: Vec<Coupling> = AXES.iter().map(|a| coupling(base, a).cloned()).collect::<Result<_, _>>()?;
    let is_lumbar = |c: &Coupling| lumbar.iter().any(|l| l.proxy == c.proxy);
    match variant {
        Variant::Poly => {}
        Variant::Nopoly => p.couplings.retain(|c| !is_lumbar(c)),
        Variant::Classical => {
            if !LEVELS.contains(&classical_level) {
                return Err(SpineError::BadLevel(classical_level.into()));
            }
            p.couplings.retain(|c| !is_lumbar(c));
            for (axis, l) in AXES.iter().zip(&lumbar) {
                p.couplings.push(Coupling {
                    proxy: l.proxy.clone(),
                    range: l.range,
                    coordinates: vec![coordinate(classical_level, axis)],
                    coefficients: vec![vec![0.0, 1.0]],
                });
                for level in LEVELS.iter().filter(|&&lv| lv != classical_level) {
                    p.fixed.insert(coordinate(level, axis), 0.0);
                }
            }
        }
    }
    Ok(p)
}

/// Key poses of the yoga-like sequence: total lumbar (flexion, bending, rotation), rad. Forward
/// fold, back bend, side bends, twists and combined revolved poses near the proxy ranges'
/// ends (flexion −0.5…1.2, bending ±0.65, rotation ±0.45).
const POSES: [[f64; 3]; 9] = [
    [0.0, 0.0, 0.0],
    [1.1, 0.0, 0.0],
    [-0.45, 0.0, 0.0],
    [0.15, 0.6, 0.0],
    [0.15, -0.6, 0.0],
    [0.2, 0.0, 0.4],
    [0.2, 0.0, -0.4],
    [0.8, 0.3, -0.35],
    [0.8, -0.3, 0.35],
];

/// Total lumbar angles at time `t` (s): each pose held 0.5 s, then a 1.5 s cosine transition to
/// the next, cycling.
fn yoga_totals(t: f64) -> [f64; 3] {
    let (hold, move_s) = (0.5, 1.5);
    let period = hold + move_s;
    let k = (t / period).floor() as usize;
    let within = t - k as f64 * period;
    let (a, b) = (POSES[k % POSES.len()], POSES[(k + 1) % POSES.len()]);
    let w = if within < hold { 0.0 } else { 0.5 - 0.5 * (PI * (within - hold) / move_s).cos() };
    [0, 1, 2].map(|i| a[i] + w * (b[i] - a[i]))
}

/// The yoga-like trial: the generic synthetic motion of the shipped model (no walking) with the
/// lumbar levels set by [`yoga_totals`] through the poly couplings' polynomials plus per-level
/// deviations. `ctx` must leave the 18 level coordinates free (the nopoly variant).
pub fn yoga_trial(ctx: &Context, base: &Profile, opt: &SpineOptions) -> Result<Synthetic, SpineError> {
    let couplings: Vec<Coupling> = AXES.iter().map(|a| coupling(base, a).cloned()).collect::<Result<_, _>>()?;
    let mut rng = ChaCha8Rng::seed_from_u64(opt.seed ^ 0x5b1e_5b1e);
    // Per axis and level: proxy index, coupling polynomial, deviation frequency (Hz) and phase.
    let mut levels = Vec::new();
    for (a, c) in couplings.iter().enumerate() {
        for (name, coefs) in c.coordinates.iter().zip(&c.coefficients) {
            let k = ctx.proxy.proxy_index(name).ok_or_else(|| SpineError::MissingCoupling(name.clone()))?;
            levels.push((a, k, coefs.clone(), rng.random_range(0.05..0.25), rng.random_range(0.0..TAU)));
        }
    }
    let synth = SynthOptions {
        frames: opt.frames,
        rate_hz: opt.rate_hz,
        seed: opt.seed,
        noise_m: opt.noise_m,
        speed_m_s: 0.0,
        ..SynthOptions::default()
    };
    let proxies = &ctx.proxy.proxies;
    Ok(synthesize_with(&ctx.model, &ctx.proxy, &synth, |t, p| {
        let total = yoga_totals(t);
        for (a, k, coefs, f, ph) in &levels {
            let x = total[*a];
            let poly: f64 = coefs.iter().rev().fold(0.0, |acc, c| acc * x + c);
            let share = coefs.get(1).copied().unwrap_or(0.0);
            let v = poly + opt.deviation * share * x * (TAU * f * t + ph).sin();
            p[*k] = v.clamp(proxies[*k].range.0, proxies[*k].range.1);
        }
    }))
}

/// Roughness of spine histories `q[frame][axis][level]` (rad).
pub fn roughness(q: &[[[f64; 6]; 3]]) -> Roughness {
    let d2 = |a: f64, b: f64, c: f64| (a - 2.0 * b + c).to_degrees().powi(2);
    let mut temporal_deg2 = BTreeMap::new();
    let mut temporal_axis_deg2 = [0.0; 3];
    let mut spatial_axis_deg2 = [0.0; 3];
    for a in 0..3 {
        for l in 0..6 {
            let v: Vec<f64> = q.windows(3).map(|w| d2(w[0][a][l], w[1][a][l], w[2][a][l])).collect();
            let m = crate::pipeline::stats::mean(&v);
            temporal_axis_deg2[a] += m / 6.0;
            temporal_deg2.insert(coordinate(LEVELS[l], AXES[a]), m);
        }
        let v: Vec<f64> = q.iter().flat_map(|f| f[a].windows(3).map(|w| d2(w[0], w[1], w[2]))).collect();
        spatial_axis_deg2[a] = crate::pipeline::stats::mean(&v);
    }
    Roughness {
        temporal_deg2,
        temporal_axis_deg2,
        spatial_deg2: spatial_axis_deg2.iter().sum::<f64>() / 3.0,
        spatial_axis_deg2,
    }
}

/// The spine coordinates of state `y` as `[axis][level]`.
fn spine_of(ctx: &Context, y: &[f64]) -> [[f64; 6]; 3] {
    [0, 1, 2].map(|a| {
        [0, 1, 2, 3, 4, 5].map(|l| {
            let j = ctx.model.coordinate_index(&coordinate(LEVELS[l], AXES[a])).expect("lumbar coordinate");
            y[j]
        })
    })
}

/// Runs the ablation on the shipped model.
pub fn run(opt: &SpineOptions) -> Result<SpineReport, SpineError> {
    let model = mjcf::parse_mjcf(SHIPPED_MODEL, "models/fullbody.xml")?;
    let base = Profile::parse(SHIPPED_PROFILE, Path::new("models/fullbody.toml"))?;
    let ctx_of = |v: Variant| -> Result<Context, SpineError> {
        let p = variant_profile(&base, v, &opt.classical_level)?;
        let name = format!("models/fullbody.toml ({})", v.name());
        Ok(Context::new(model.clone(), p, &name, "shipped:models/fullbody.xml".into())?)
    };
    let nopoly = ctx_of(Variant::Nopoly)?;
    let s = yoga_trial(&nopoly, &base, opt)?;
    let truth_q: Vec<[[f64; 6]; 3]> = s.truth.coordinates.iter().map(|q| spine_of(&nopoly, q)).collect();
    let mut setups = Vec::new();
    for v in Variant::ALL {
        let ctx = if v == Variant::Nopoly { nopoly.clone() } else { ctx_of(v)? };
        let cal = calibrate_subject(&ctx, &[("yoga", &s.trial)])?;
        setups.push((v, ctx, cal));
    }
    // Solves are deterministic; the repeats only pool frame times, taken round-robin over the
    // variants so that a change in machine load affects them alike.
    let mut results: Vec<Option<crate::pipeline::TrialResult>> = vec![None; setups.len()];
    let mut times: Vec<Vec<f64>> = vec![Vec::new(); setups.len()];
    for _ in 0..opt.repeats.max(1) {
        for (i, (_, ctx, cal)) in setups.iter().enumerate() {
            let r = solve_trial_with(ctx, "yoga", &s.trial, cal, 1, 1, None)?;
            times[i].extend(r.frame_seconds.iter().map(|t| t * 1e3));
            results[i].get_or_insert(r);
        }
    }
    let mut variants = Vec::new();
    for ((v, ctx, _), (r, ms)) in setups.iter().zip(results.into_iter().zip(&times)) {
        let r = r.expect("solved at least once");
        let tr = trial_report(ctx, &r, Some(&s.truth));
        let q: Vec<[[f64; 6]; 3]> = r.proxies.iter().map(|p| spine_of(ctx, &ctx.proxy.state(p))).collect();
        let (mut se, mut te) = (0.0, [0.0; 3]);
        for (est, tru) in q.iter().zip(&truth_q) {
            for a in 0..3 {
                for l in 0..6 {
                    se += (est[a][l] - tru[a][l]).to_degrees().powi(2);
                }
                te[a] += (est[a].iter().sum::<f64>() - tru[a].iter().sum::<f64>()).to_degrees().powi(2);
            }
        }
        let n = q.len().max(1) as f64;
        let is_spine = |name: &str| name.starts_with("lumbar_") || LEVELS.iter().any(|l| name.starts_with(l));
        variants.push(VariantReport {
            variant: *v,
            pose_proxies: ctx.proxy.proxies.iter().filter(|p| p.kind != ProxyKind::Scale).count(),
            spine_proxies: ctx.proxy.proxies.iter().filter(|p| is_spine(&p.name)).count(),
            marker_rmse_mm: tr.marker_rmse_mm.expect("solved trial"),
            ms_per_frame: P50P90::of(ms),
            iterations: tr.iterations.expect("solved trial"),
            pose_error_deg: tr.pose_error_deg,
            scale_error_pct: tr.scale_error_pct,
            spine_error_deg: (se / (18.0 * n)).sqrt(),
            total_angle_error_deg: te.map(|e| (e / n).sqrt()),
            roughness: roughness(&q),
        });
    }
    Ok(SpineReport { options: opt.clone(), truth: roughness(&truth_q), variants })
}

/// The acceptance tests on a report: `(statement, holds)` for poly's marker RMSE within
/// +1 mm of classical's (mean), spatial roughness below nopoly's, and median ms/frame within
/// 1.5× classical's.
pub fn acceptance(r: &SpineReport) -> Vec<(String, bool)> {
    let get = |v: Variant| r.variants.iter().find(|x| x.variant == v);
    let (Some(p), Some(n), Some(c)) = (get(Variant::Poly), get(Variant::Nopoly), get(Variant::Classical)) else {
        return Vec::new();
    };
    vec![
        (
            format!(
                "poly marker RMSE {:.2} mm ≤ classical {:.2} mm + 1 mm",
                p.marker_rmse_mm.mean, c.marker_rmse_mm.mean
            ),
            p.marker_rmse_mm.mean <= c.marker_rmse_mm.mean + 1.0,
        ),
        (
            format!(
                "poly spatial roughness {:.4} deg² < nopoly {:.4} deg²",
                p.roughness.spatial_deg2, n.roughness.spatial_deg2
            ),
            p.roughness.spatial_deg2 < n.roughness.spatial_deg2,
        ),
        (
            format!("poly {:.3} ms/frame ≤ 1.5 × classical {:.3} ms/frame", p.ms_per_frame.p50, c.ms_per_frame.p50),
            p.ms_per_frame.p50 <= 1.5 * c.ms_per_frame.p50,
        ),
    ]
}
