//! Batched evaluation behind one trait: the same batch of frames in, the same `(H, g, E, x̂)` out,
//! whichever backend ran it. The solver and the lane scheduler ([`crate::pipeline::running::lanes`]) only
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

/// Real values where a backend left them: f64 (CPU, f64 shaders) or f32 (f32 shaders, read in
/// place from the mapped read-back buffer).
#[derive(Clone, Copy, Debug)]
pub enum Reals<'a> {
    F32(&'a [f32]),
    F64(&'a [f64]),
}

impl Reals<'_> {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            Reals::F32(v) => v.len(),
            Reals::F64(v) => v.len(),
        }
    }

    /// True when there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Value `i` as f64.
    #[inline]
    pub fn get(&self, i: usize) -> f64 {
        match self {
            Reals::F32(v) => v[i] as f64,
            Reals::F64(v) => v[i],
        }
    }

    /// `out[i] = self[i]` (f64), for `i < out.len()`.
    #[inline]
    pub fn copy_to(&self, out: &mut [f64]) {
        match self {
            Reals::F32(v) => out.iter_mut().zip(v.iter()).for_each(|(o, &x)| *o = x as f64),
            Reals::F64(v) => out.copy_from_slice(&v[..out.len()]),
        }
    }
}

/// `H` of one frame as a backend left it.
#[derive(Clone, Copy, Debug)]
pub enum HessianView<'a> {
    /// Both triangles, `np × np` column-major (CPU backend).
    Full(&'a DMatrix<f64>),
    /// Upper triangle packed column by column: `H[i][j]` (`i ≤ j`) at `j(j+1)/2 + i`, so that
    /// column `j`'s upper part is contiguous (device backends).
    UpperColumns(Reals<'a>),
}

/// Index of `H[i][j]` (`i ≤ j`) in [`HessianView::UpperColumns`].
#[inline]
pub fn upper_index(i: usize, j: usize) -> usize {
    j * (j + 1) / 2 + i
}

impl HessianView<'_> {
    /// Writes both triangles into `h` (`np × np`). From [`HessianView::Full`] this is an exact
    /// copy (the CPU's `H` is kept bit for bit, whatever its rounding asymmetry).
    pub fn write_full(&self, h: &mut DMatrix<f64>) {
        match self {
            HessianView::Full(src) => h.copy_from(src),
            HessianView::UpperColumns(packed) => {
                let np = h.nrows();
                let hs = h.as_mut_slice();
                for j in 0..np {
                    let start = upper_index(0, j);
                    match packed {
                        Reals::F32(v) => {
                            for (o, &x) in hs[j * np..j * np + j + 1].iter_mut().zip(&v[start..start + j + 1]) {
                                *o = x as f64;
                            }
                        }
                        Reals::F64(v) => hs[j * np..j * np + j + 1].copy_from_slice(&v[start..start + j + 1]),
                    }
                }
                for j in 0..np {
                    for i in 0..j {
                        hs[i * np + j] = hs[j * np + i];
                    }
                }
            }
        }
    }
}

/// The Gauss–Newton model of one frame, borrowed from where the backend computed it (a CPU
/// workspace or the mapped read-back buffer): valid only during [`GnSink::take`].
#[derive(Clone, Copy, Debug)]
pub struct GnView<'a> {
    pub energy: f64,
    pub marker_sq_sum: f64,
    pub markers_used: usize,
    /// `g`, length np.
    pub g: Reals<'a>,
    pub h: HessianView<'a>,
    /// Model marker positions `3·marker + axis`, relative to `reference` (m).
    pub markers: Reals<'a>,
    /// Added to `markers` to give world positions (m; zero on the CPU).
    pub reference: [f64; 3],
}

impl GnView<'_> {
    /// Copies the view into owned storage (both triangles of `H`, world marker positions).
    pub fn fill(&self, out: &mut FrameModel) {
        let gn = &mut out.gn;
        gn.energy = self.energy;
        gn.marker_sq_sum = self.marker_sq_sum;
        gn.markers_used = self.markers_used;
        self.g.copy_to(gn.g.as_mut_slice());
        self.h.write_full(&mut gn.h);
        for (j, x) in out.markers.iter_mut().enumerate() {
            *x = self.markers.get(j) + self.reference[j % 3];
        }
    }
}

/// Receives one frame's model from [`BatchBackend::linearize_into`] (the trust-region solver:
/// it reads `H` and `g` where they lie and forms its damped QP from them).
pub trait GnSink: Send {
    fn take(&mut self, view: &GnView<'_>);
}

impl GnSink for FrameModel {
    fn take(&mut self, view: &GnView<'_>) {
        view.fill(self);
    }
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
    /// The model of every frame at its proxies, handed to `sinks[frame]` (in parallel, in no
    /// particular order) while it lies where the backend computed it (a CPU workspace, the
    /// mapped read-back buffer): no per-frame conversion on the way.
    fn linearize_into(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        sinks: &mut [&mut dyn GnSink],
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

    fn linearize_into(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        sinks: &mut [&mut dyn GnSink],
    ) -> Result<(), BackendError> {
        let np = self.eval.proxy.np();
        check_shape(frames.len(), proxies.len(), sinks.len(), np)?;
        let c = self.chunk(frames.len());
        let eval = &self.eval;
        sinks.par_chunks_mut(c).zip(self.workspaces.par_iter_mut()).enumerate().for_each(|(i, (outs, ws))| {
            for (j, o) in outs.iter_mut().enumerate() {
                let f = i * c + j;
                eval.linearize(&proxies[f * np..(f + 1) * np], &frames[f], ws);
                o.take(&GnView {
                    energy: ws.gn.energy,
                    marker_sq_sum: ws.gn.marker_sq_sum,
                    markers_used: ws.gn.markers_used,
                    g: Reals::F64(ws.gn.g.as_slice()),
                    h: HessianView::Full(&ws.gn.h),
                    markers: Reals::F64(&ws.kin.markers),
                    reference: [0.0; 3],
                });
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
