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
    /// `J_mᵀ` (np × 3M).
    pub jm_t: DMatrix<f64>,
    pub gn: GaussNewton,
    v: Vec<f64>,
}

impl EvalWorkspace {
    pub fn new(model: &Model, proxy: &ProxyMap) -> EvalWorkspace {
        let np = proxy.np();
        EvalWorkspace {
            kin: Workspace::new(model),
            y: vec![0.0; model.ny()],
            dphi: vec![0.0; proxy.terms.len()],
            jm_t: DMatrix::zeros(np, 3 * model.markers.len()),
            gn: GaussNewton { h: DMatrix::zeros(np, np), g: DVector::zeros(np), energy: 0.0, marker_sq_sum: 0.0, markers_used: 0 },
            v: vec![0.0; np],
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
        cpu::jacobian(self.model, &self.layout, &mut ws.kin);
        let EvalWorkspace { kin, y, dphi, jm_t, gn, v } = ws;
        gn.h.fill(0.0);
        gn.g.fill(0.0);
        gn.energy = energy;
        gn.marker_sq_sum = sq;
        gn.markers_used = used;
        let lay = &self.layout;
        for (m, &w) in frame.marker_weights.iter().enumerate() {
            let obs = &frame.observed[3 * m..3 * m + 3];
            let props = &lay.marker_proxies[m];
            for a in 0..3 {
                let col = 3 * m + a;
                for &k in props {
                    jm_t[(k, col)] = 0.0;
                }
                for &t in &lay.marker_terms[m] {
                    let term = &self.proxy.terms[t];
                    jm_t[(term.proxy, col)] += kin.jy_t[(term.y_index, col)] * dphi[t];
                }
            }
            if w <= 0.0 || obs[0].is_nan() || obs[1].is_nan() || obs[2].is_nan() {
                continue;
            }
            for a in 0..3 {
                let col = 3 * m + a;
                let r = kin.markers[col] - obs[a];
                for (i, &k) in props.iter().enumerate() {
                    v[i] = w * jm_t[(k, col)];
                }
                for (i, &ki) in props.iter().enumerate() {
                    let vi = v[i];
                    gn.g[ki] += vi * r;
                    if vi == 0.0 {
                        continue;
                    }
                    let jrow = jm_t.column(col);
                    for &kj in &props[i..] {
                        gn.h[(ki, kj)] += vi * jrow[kj];
                    }
                }
            }
        }
        // Tracking term J_Φᵀ W_t J_Φ, J_Φᵀ W_t e_t.
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
                    let ku = self.proxy.terms[u].proxy;
                    if ku >= kt {
                        gn.h[(kt, ku)] += w * dphi[t] * dphi[u];
                    }
                }
            }
        }
        // Mirror the upper triangle.
        let np = gn.h.nrows();
        for c in 0..np {
            for r in (c + 1)..np {
                gn.h[(r, c)] = gn.h[(c, r)];
            }
        }
    }
}
