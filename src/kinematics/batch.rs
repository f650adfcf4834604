//! Many frames at once on the CPU, as owned results: convenience wrappers over
//! [`CpuBackend`](super::backend::CpuBackend) for tests and one-off batches.

use super::assembly::{Evaluator, FrameProblem};
pub use super::backend::FrameModel;
use super::backend::{BatchBackend, CpuBackend, EnergyEval};

/// `(H, g, E, x̂)` for every frame `f` at proxies `proxies[f]`, in parallel.
pub fn linearize_batch(eval: &Evaluator<'_>, frames: &[FrameProblem<'_>], proxies: &[Vec<f64>]) -> Vec<FrameModel> {
    let (np, nm) = (eval.proxy.np(), eval.model.markers.len());
    let flat: Vec<f64> = proxies.concat();
    let mut out = vec![FrameModel::new(np, nm); frames.len()];
    CpuBackend::new(eval.clone()).linearize(frames, &flat, &mut out).expect("shapes match by construction");
    out
}

/// Objective `E` for every frame at its proxies (forward kinematics only), in parallel.
pub fn energy_batch(eval: &Evaluator<'_>, frames: &[FrameProblem<'_>], proxies: &[Vec<f64>]) -> Vec<f64> {
    let flat: Vec<f64> = proxies.concat();
    let mut out = vec![EnergyEval::default(); frames.len()];
    CpuBackend::new(eval.clone()).energy(frames, &flat, &mut out).expect("shapes match by construction");
    out.iter().map(|e| e.energy).collect()
}
