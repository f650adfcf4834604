//! Many frames at once on the CPU: the batched evaluation that the GPU backend will mirror.
//! Frames are independent, so they are spread over rayon's pool with one workspace per worker.

use super::assembly::{EvalWorkspace, Evaluator, FrameProblem};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// The Gauss–Newton model of one frame, as returned by [`linearize_batch`].
#[derive(Clone, Debug)]
pub struct FrameModel {
    pub h: DMatrix<f64>,
    pub g: DVector<f64>,
    pub energy: f64,
    /// Model marker positions, `3·marker + axis` (m, world frame).
    pub markers: Vec<f64>,
}

/// `(H, g, E, x̂)` for every frame `f` at proxies `proxies[f]`, in parallel.
pub fn linearize_batch(eval: &Evaluator<'_>, frames: &[FrameProblem<'_>], proxies: &[Vec<f64>]) -> Vec<FrameModel> {
    frames
        .par_iter()
        .zip(proxies.par_iter())
        .map_init(
            || EvalWorkspace::new(eval.model, eval.proxy),
            |ws, (frame, p)| {
                eval.linearize(p, frame, ws);
                FrameModel {
                    h: ws.gn.h.clone(),
                    g: ws.gn.g.clone(),
                    energy: ws.gn.energy,
                    markers: ws.kin.markers.clone(),
                }
            },
        )
        .collect()
}

/// Objective `E` for every frame at its proxies (forward kinematics only), in parallel.
pub fn energy_batch(eval: &Evaluator<'_>, frames: &[FrameProblem<'_>], proxies: &[Vec<f64>]) -> Vec<f64> {
    frames
        .par_iter()
        .zip(proxies.par_iter())
        .map_init(|| EvalWorkspace::new(eval.model, eval.proxy), |ws, (frame, p)| eval.energy(p, frame, ws).0)
        .collect()
}
