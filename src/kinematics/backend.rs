//! Batched evaluation behind one trait: the same batch of frames in, the same `(H, g, E, x̂)` out,
//! whichever backend ran it. The solver and the lane scheduler ([`crate::pipeline::lanes`]) only
//! see [`BatchBackend`]; [`CpuBackend`] (rayon, f64, the reference) and
//! [`WgpuBackend`](super::wgpu::WgpuBackend) (compute shaders, f32) implement it.

use super::assembly::{EvalWorkspace, Evaluator, FrameProblem, GaussNewton};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// The Gauss–Newton model of one frame and its model marker positions.
#[derive(Clone, Debug)]
pub struct FrameModel {
    /// `H` (both triangles), `g`, `E` and the marker error statistics.
    pub gn: GaussNewton,
    /// Model marker positions, `3·marker + axis` (m, world frame).
    pub markers: Vec<f64>,
}

impl FrameModel {
    /// Zeroed storage for `np` proxies and `nm` markers.
    pub fn new(np: usize, nm: usize) -> FrameModel {
        FrameModel {
            gn: GaussNewton {
                h: DMatrix::zeros(np, np),
                g: DVector::zeros(np),
                energy: 0.0,
                marker_sq_sum: 0.0,
                markers_used: 0,
            },
            markers: vec![0.0; 3 * nm],
        }
    }
}

/// The objective of one frame at one point (forward kinematics only).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnergyEval {
    /// `E`.
    pub energy: f64,
    /// Σ over used markers of the squared distance (m²), unweighted.
    pub marker_sq_sum: f64,
    /// Markers observed and weighted.
    pub markers_used: usize,
}

/// Why a batch could not be evaluated (only device backends fail).
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    #[error("no wgpu adapter: {0}")]
    NoAdapter(String),
    #[error("wgpu adapter '{adapter}': {message}")]
    Device { adapter: String, message: String },
    #[error("batch shape: {0}")]
    Shape(String),
}

/// A batched evaluator bound to one (model, proxy map). `proxies` holds the proxies of every frame
/// back to back (`frame · np + k`); `out` has one entry per frame.
pub trait BatchBackend: Send {
    /// Short name for reports ("cpu", "wgpu").
    fn name(&self) -> &'static str;
    /// Device description for run metadata (adapter name and driver for wgpu).
    fn device(&self) -> String;
    /// `(H, g, E, x̂)` of every frame at its proxies.
    fn linearize(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        out: &mut [FrameModel],
    ) -> Result<(), BackendError>;
    /// `E` (and marker statistics) of every frame at its proxies.
    fn energy(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        out: &mut [EnergyEval],
    ) -> Result<(), BackendError>;
}

/// `dst = src` without allocating (the derived `clone_from` reallocates).
pub fn copy_gn(dst: &mut GaussNewton, src: &GaussNewton) {
    dst.h.copy_from(&src.h);
    dst.g.copy_from(&src.g);
    dst.energy = src.energy;
    dst.marker_sq_sum = src.marker_sq_sum;
    dst.markers_used = src.markers_used;
}

/// Checks that `proxies` and `out` fit `frames`.
pub(crate) fn check_shape(frames: usize, proxies: usize, out: usize, np: usize) -> Result<(), BackendError> {
    if proxies != frames * np || out != frames {
        return Err(BackendError::Shape(format!(
            "{frames} frames need {} proxies and {frames} outputs, got {proxies} and {out}",
            frames * np
        )));
    }
    Ok(())
}

/// The reference backend: [`Evaluator`] on rayon's pool, one preallocated workspace per chunk.
pub struct CpuBackend<'m> {
    eval: Evaluator<'m>,
    workspaces: Vec<EvalWorkspace>,
}

impl<'m> CpuBackend<'m> {
    /// A backend for `eval`'s model, with one workspace per thread of the current rayon pool.
    pub fn new(eval: Evaluator<'m>) -> CpuBackend<'m> {
        let n = rayon::current_num_threads().max(1);
        let workspaces = (0..n).map(|_| EvalWorkspace::new(eval.model, eval.proxy)).collect();
        CpuBackend { eval, workspaces }
    }

    /// Frames per chunk so that every workspace gets one chunk.
    fn chunk(&self, n: usize) -> usize {
        n.div_ceil(self.workspaces.len()).max(1)
    }
}

impl BatchBackend for CpuBackend<'_> {
    fn name(&self) -> &'static str {
        "cpu"
    }

    fn device(&self) -> String {
        format!("cpu: {} rayon threads, f64", self.workspaces.len())
    }

    fn linearize(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        out: &mut [FrameModel],
    ) -> Result<(), BackendError> {
        let np = self.eval.proxy.np();
        check_shape(frames.len(), proxies.len(), out.len(), np)?;
        let c = self.chunk(frames.len());
        let eval = &self.eval;
        out.par_chunks_mut(c).zip(self.workspaces.par_iter_mut()).enumerate().for_each(|(i, (outs, ws))| {
            for (j, o) in outs.iter_mut().enumerate() {
                let f = i * c + j;
                eval.linearize(&proxies[f * np..(f + 1) * np], &frames[f], ws);
                copy_gn(&mut o.gn, &ws.gn);
                o.markers.clone_from(&ws.kin.markers);
            }
        });
        Ok(())
    }

    fn energy(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        out: &mut [EnergyEval],
    ) -> Result<(), BackendError> {
        let np = self.eval.proxy.np();
        check_shape(frames.len(), proxies.len(), out.len(), np)?;
        let c = self.chunk(frames.len());
        let eval = &self.eval;
        out.par_chunks_mut(c).zip(self.workspaces.par_iter_mut()).enumerate().for_each(|(i, (outs, ws))| {
            for (j, o) in outs.iter_mut().enumerate() {
                let f = i * c + j;
                let (energy, marker_sq_sum, markers_used) = eval.energy(&proxies[f * np..(f + 1) * np], &frames[f], ws);
                *o = EnergyEval { energy, marker_sq_sum, markers_used };
            }
        });
        Ok(())
    }
}
