//! Assembly of one frame's Gauss–Newton model in proxy space (METHOD.md):
//! ```text
//! E   = ½ Σ_m w_m ‖x̂_m(Φ(p)) − x_m‖² + ½ Σ_j w_t,j (y_j − y_ref,j)²
//! J_m = J_y J_Φ
//! H   = J_mᵀ W_m J_m + J_Φᵀ W_t J_Φ          (damping is added by the solver)
//! g   = J_mᵀ W_m r_m + J_Φᵀ W_t e_t
//! ```
//! Weights here are the weights on squared errors (`W = diag(w)`, the square of METHOD.md's
//! square-root weights). Sparsity comes from [`Layout`]: a marker only touches the proxies on its
//! chain, so `H` is accumulated marker by marker over small index sets.

use super::{cpu, Layout, Workspace};
use crate::model::proxy::ProxyMap;
use crate::model::Model;
use nalgebra::{DMatrix, DVector};

/// The data of one frame's objective.
#[derive(Clone, Copy, Debug)]
pub struct FrameProblem<'a> {
    /// Observed marker positions, `3·marker + axis`, world frame (m); NaN marks a gap.
    pub observed: &'a [f64],
    /// Weight of each marker's squared error; 0 excludes it.
    pub marker_weights: &'a [f64],
    /// Tracking reference `y_ref` (length ny).
    pub tracking_ref: &'a [f64],
    /// Weight of each `(y_j − y_ref,j)²` (length ny); 0 for none.
    pub tracking_weights: &'a [f64],
}

/// Gauss–Newton model of one frame at the current proxies.
#[derive(Clone, Debug)]
pub struct GaussNewton {
    /// `H` (np × np, symmetric, both triangles filled).
    pub h: DMatrix<f64>,
    /// `g` (np).
    pub g: DVector<f64>,
    /// Objective `E`.
    pub energy: f64,
    /// Σ over used markers of the squared distance (m²), unweighted.
    pub marker_sq_sum: f64,
    /// Number of markers observed and weighted.
    pub markers_used: usize,
}

impl GaussNewton {
    /// Marker RMSE (m): `sqrt(mean squared distance)` over used markers, as OpenSim reports it.
    pub fn rmse(&self) -> f64 {
        if self.markers_used == 0 {
            f64::NAN
        } else {
            (self.marker_sq_sum / self.markers_used as f64).sqrt()
        }
    }
}

/// Everything one evaluation needs besides the (shared, immutable) model data.
#[derive(Clone, Debug)]
pub struct EvalWorkspace {
    pub kin: Workspace,
    /// `y = Φ(p)` of the last evaluation.
    pub y: Vec<f64>,
    /// `J_Φ` non-zeros, one per proxy-map term.
    pub dphi: Vec<f64>,
    pub gn: GaussNewton,
    /// Scratch: a marker's compact rows of `J_y` and `J_m`, a body's `H` block (upper,
    /// row-major) and `g` part.
    jy_rows: Vec<f64>,
    row: Vec<f64>,
    block: Vec<f64>,
    gpart: Vec<f64>,
}

impl EvalWorkspace {
    pub fn new(model: &Model, proxy: &ProxyMap) -> EvalWorkspace {
        let np = proxy.np();
        EvalWorkspace {
            kin: Workspace::new(model),
            y: vec![0.0; model.ny()],
            dphi: vec![0.0; proxy.terms.len()],
            gn: GaussNewton {
                h: DMatrix::zeros(np, np),
                g: DVector::zeros(np),
                energy: 0.0,
                marker_sq_sum: 0.0,
                markers_used: 0,
            },
            jy_rows: vec![0.0; 3 * model.ny()],
            row: vec![0.0; 3 * np],
            block: vec![0.0; np * np],
            gpart: vec![0.0; np],
        }
    }
}

/// The immutable inputs of every evaluation: model, proxy map and their sparsity.
#[derive(Clone, Debug)]
pub struct Evaluator<'m> {
    pub model: &'m Model,
    pub proxy: &'m ProxyMap,
    pub layout: Layout,
}

impl<'m> Evaluator<'m> {
    pub fn new(model: &'m Model, proxy: &'m ProxyMap) -> Evaluator<'m> {
        Evaluator { model, proxy, layout: Layout::new(model, proxy) }
    }

    /// Objective at `p` (forward kinematics only). Returns `(E, Σ‖r‖², markers used)`.
    pub fn energy(&self, p: &[f64], frame: &FrameProblem<'_>, ws: &mut EvalWorkspace) -> (f64, f64, usize) {
        self.proxy.apply(p, &mut ws.y, &mut ws.dphi);
        cpu::forward(self.model, &ws.y, &mut ws.kin);
        let (mut e, mut sq, mut used) = (0.0, 0.0, 0);
        for (m, &w) in frame.marker_weights.iter().enumerate() {
            let obs = &frame.observed[3 * m..3 * m + 3];
            if w <= 0.0 || obs[0].is_nan() || obs[1].is_nan() || obs[2].is_nan() {
                continue;
            }
            let d2: f64 = (0..3).map(|a| (ws.kin.markers[3 * m + a] - obs[a]).powi(2)).sum();
            e += 0.5 * w * d2;
            sq += d2;
            used += 1;
        }
        for (j, &w) in frame.tracking_weights.iter().enumerate() {
            if w > 0.0 {
                e += 0.5 * w * (ws.y[j] - frame.tracking_ref[j]).powi(2);
            }
        }
        (e, sq, used)
    }

    /// Gauss–Newton model `(H, g, E)` at `p` into `ws.gn`.
    pub fn linearize(&self, p: &[f64], frame: &FrameProblem<'_>, ws: &mut EvalWorkspace) {
        let (energy, sq, used) = self.energy(p, frame, ws);
        let EvalWorkspace { kin, y, dphi, gn, jy_rows, row, block, gpart } = ws;
        gn.h.fill(0.0);
        gn.g.fill(0.0);
        gn.energy = energy;
        gn.marker_sq_sum = sq;
        gn.markers_used = used;
        for deps in &self.layout.bodies {
            let ns = deps.proxies.len();
            let blk = &mut block[..ns * ns];
            let gp = &mut gpart[..ns];
            let mut any = false;
            for &m in &deps.markers {
                let w = frame.marker_weights[m];
                let obs = &frame.observed[3 * m..3 * m + 3];
                if w <= 0.0 || obs.iter().any(|v| v.is_nan()) {
                    continue;
                }
                if !any {
                    blk.fill(0.0);
                    gp.fill(0.0);
                    any = true;
                }
                // Compact rows of J_y over this body's ys, then of J_m = J_y J_Φ over its proxies.
                let nys = deps.ys.len();
                let jr = &mut jy_rows[..3 * nys];
                jr.fill(0.0);
                cpu::marker_contributions(self.model, kin, m, |j, v| {
                    let i = 3 * deps.y_slot[j];
                    jr[i] += v.x;
                    jr[i + 1] += v.y;
                    jr[i + 2] += v.z;
                });
                let rows = &mut row[..3 * ns];
                rows.fill(0.0);
                for &(t, yi, slot) in &deps.terms {
                    let d = dphi[t];
                    rows[3 * slot] += jr[3 * yi] * d;
                    rows[3 * slot + 1] += jr[3 * yi + 1] * d;
                    rows[3 * slot + 2] += jr[3 * yi + 2] * d;
                }
                // H_S += w Σ_a c_a c_aᵀ (upper triangle), g_S += w Σ_a c_a r_a; rows interleaved by axis.
                let r = [kin.markers[3 * m] - obs[0], kin.markers[3 * m + 1] - obs[1], kin.markers[3 * m + 2] - obs[2]];
                for i in 0..ns {
                    let ci = [w * rows[3 * i], w * rows[3 * i + 1], w * rows[3 * i + 2]];
                    gp[i] += ci[0] * r[0] + ci[1] * r[1] + ci[2] * r[2];
                    for (h, cj) in blk[i * ns + i..(i + 1) * ns].iter_mut().zip(rows[3 * i..3 * ns].chunks_exact(3)) {
                        *h += ci[0] * cj[0] + ci[1] * cj[1] + ci[2] * cj[2];
                    }
                }
            }
            if any {
                // Scatter the block into both triangles of H (column-major, np × np).
                let np = gn.g.len();
                let hs = gn.h.as_mut_slice();
                for (i, &ki) in deps.proxies.iter().enumerate() {
                    gn.g[ki] += gp[i];
                    hs[ki * np + ki] += blk[i * ns + i];
                    for (&kj, &v) in deps.proxies[i + 1..].iter().zip(&blk[i * ns + i + 1..(i + 1) * ns]) {
                        hs[kj * np + ki] += v;
                        hs[ki * np + kj] += v;
                    }
                }
            }
        }
        // Tracking term J_Φᵀ W_t J_Φ, J_Φᵀ W_t e_t (both triangles).
        for (j, &w) in frame.tracking_weights.iter().enumerate() {
            if w <= 0.0 {
                continue;
            }
            let e = y[j] - frame.tracking_ref[j];
            let terms = self.proxy.y_terms[j].clone();
            for t in terms.clone() {
                let kt = self.proxy.terms[t].proxy;
                gn.g[kt] += w * dphi[t] * e;
                for u in terms.clone() {
                    gn.h[(kt, self.proxy.terms[u].proxy)] += w * dphi[t] * dphi[u];
                }
            }
        }
    }

    /// Dense `J_m = J_y J_Φ` (3M × np) at the last evaluation, for inspection and tests.
    pub fn marker_jacobian(&self, ws: &EvalWorkspace) -> DMatrix<f64> {
        let nx = ws.kin.jy_t.ncols();
        let mut jm = DMatrix::zeros(nx, self.proxy.np());
        for (t, term) in self.proxy.terms.iter().enumerate() {
            for r in 0..nx {
                jm[(r, term.proxy)] += ws.kin.jy_t[(term.y_index, r)] * ws.dphi[t];
            }
        }
        jm
    }
}
