//! The embedded synthetic dataset: subjects of the shipped model, each with a static trial and
//! motion trials cut from one continuous synthetic motion (so a subject keeps its morphology and
//! marker misplacement across trials). Deterministic for a seed.

use super::config::SyntheticSpec;
use crate::io::{trc, MarkerTrial};
use crate::kinematics::synth::{synthesize_with, SynthOptions};
use crate::model::proxy::ProxyKind;
use crate::pipeline::Context;
use std::f64::consts::TAU;
use std::path::Path;

/// Frames `a..b` of `t`, times starting at 0.
fn cut(t: &MarkerTrial, a: usize, b: usize) -> MarkerTrial {
    let w = 3 * t.n_markers();
    let t0 = t.times[a];
    MarkerTrial {
        labels: t.labels.clone(),
        rate_hz: t.rate_hz,
        times: t.times[a..b].iter().map(|x| x - t0).collect(),
        frame_numbers: (1..=(b - a) as i64).collect(),
        positions: t.positions[a * w..b * w].to_vec(),
        source_units: t.source_units.clone(),
        warnings: Vec::new(),
    }
}

/// Writes the dataset under `root` as `subjNN/static.trc` (standing) and `subjNN/walkNN.trc` (mm), unless
/// `root/.complete` says it was written with the same spec. Runs that generate one root at once
/// (shards of one archive started together) take turns on `root/.generate.lock`: one writes,
/// the others then find it complete.
pub fn generate(spec: &SyntheticSpec, root: &Path) -> anyhow::Result<()> {
    spec.validate().map_err(anyhow::Error::msg)?;
    let stamp = format!("{spec:?}");
    let marker = root.join(".complete");
    if std::fs::read_to_string(&marker).is_ok_and(|s| s == stamp) {
        return Ok(());
    }
    std::fs::create_dir_all(root)?;
    let lock =
        std::fs::OpenOptions::new().create(true).truncate(false).write(true).open(root.join(".generate.lock"))?;
    lock.lock()?;
    if std::fs::read_to_string(&marker).is_ok_and(|s| s == stamp) {
        return Ok(());
    }
    let ctx = Context::shipped()?;
    for s in 0..spec.subjects {
        let n = spec.frames.max(1);
        let opt = SynthOptions {
            frames: n * (spec.trials + 1),
            seed: spec.seed.wrapping_mul(1000).wrapping_add(s as u64),
            misplace_m: 0.005,
            ..SynthOptions::default()
        };
        // The static trial stands: every pose proxy at its neutral value, swaying by ≤ 0.6°.
        let (neutral, rate) = (ctx.proxy.default_proxies(), opt.rate_hz);
        let kinds: Vec<(ProxyKind, (f64, f64))> = ctx.proxy.proxies.iter().map(|p| (p.kind, p.range)).collect();
        let standing = |t: f64, p: &mut [f64]| {
            if t * rate < n as f64 - 0.5 {
                for (k, v) in p.iter_mut().enumerate() {
                    let (kind, (lo, hi)) = kinds[k];
                    match kind {
                        ProxyKind::Scale => {}
                        ProxyKind::Rotation => {
                            *v = (neutral[k] + 0.01 * crate::model::math::sin(TAU * (0.2 + 0.05 * (k % 7) as f64) * t))
                                .clamp(lo, hi)
                        }
                        ProxyKind::Translation => *v = neutral[k],
                    }
                }
            }
        };
        let syn = synthesize_with(&ctx.model, &ctx.proxy, &opt, standing);
        let dir = root.join(format!("subj{:02}", s + 1));
        std::fs::create_dir_all(&dir)?;
        for k in 0..=spec.trials {
            let name = if k == 0 { "static.trc".to_string() } else { format!("walk{k:02}.trc") };
            trc::write_trc(&dir.join(name), &cut(&syn.trial, k * n, (k + 1) * n), "mm")?;
        }
    }
    std::fs::write(marker, stamp)?;
    Ok(())
}
