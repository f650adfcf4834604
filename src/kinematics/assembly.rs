//! Assembly of one frame's Gauss–Newton model in proxy space (METHOD.md):
//! ```text
//! E   = ½ Σ_m w_m ‖x̂_m(Φ(p)) − x_m‖² + ½ Σ_j w_t,j (y_j − y_ref,j)²
//! J_m = J_y J_Φ
//! H   = J_mᵀ W_m J_m + J_Φᵀ W_t J_Φ          (damping is added by the solver)
//! g   = J_mᵀ W_m r_m + J_Φᵀ W_t e_t
//! ```
//! Weights here are the weights on squared errors (`W = diag(w)`, the square of METHOD.md's
//! square-root weights). Sparsity comes from [`Layout`]: a marker only touches the proxies on its
//! chain, so `H` is accumulated body by body over small index sets. The chain of a body is walked
//! once for all its markers: each contribution to a Jacobian column is `a + w × x` for a point
//! `x` on the body (`w ≠ 0` for rotations only), so the `J_m` rows of a marker are
//! `A_s + W_s × x` plus its own offset's scale terms.

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

/// Folds a second tracking term into the reference of a first one: `w (y − r)² + v (y − t)²`
/// equals `(w + v)(y − r')²` plus a constant, with `r' = (w·r + v·t)/(w + v)`. Sets `reference`
/// to `r'` wherever `v > 0`; the caller uses `weights + other_weights` as the tracking weights.
/// Allocation-free (used per frame).
pub fn fold_tracking_reference(reference: &mut [f64], weights: &[f64], other_ref: &[f64], other_weights: &[f64]) {
    for (j, &v) in other_weights.iter().enumerate() {
        if v > 0.0 {
            let w = weights[j].max(0.0);
            reference[j] = (w * reference[j] + v * other_ref[j]) / (w + v);
        }
    }
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
    /// Scratch: a body's `A_s`, `W_s` (see `linearize`), a marker's compact rows of `J_m`, a
    /// body's `H` block (upper, row-major) and `g` part.
    aw: Vec<f64>,
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
            aw: vec![0.0; 6 * np],
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
        let EvalWorkspace { kin, y, dphi, gn, aw, row, block, gpart } = ws;
        gn.h.as_mut_slice().fill(0.0);
        gn.g.as_mut_slice().fill(0.0);
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
                    self.chain_rows(deps, kin, dphi, aw);
                }
                let rows = &mut row[..3 * ns];
                self.marker_row(deps, kin, dphi, aw, m, rows);
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

    /// The body's chain, once for all its markers, into `aw` (`A_s` then `W_s`, 3 per slot): the
    /// `J_m` row of slot `s` at a point `x` on the body is `A_s + W_s × x` (plus the point's own
    /// offset terms).
    #[inline(always)]
    fn chain_rows(&self, deps: &crate::kinematics::layout::BodyDeps, kin: &Workspace, dphi: &[f64], aw: &mut [f64]) {
        let ns = deps.proxies.len();
        aw[..6 * ns].fill(0.0);
        let (a_s, w_s) = aw[..6 * ns].split_at_mut(3 * ns);
        cpu::chain_contributions(self.model, kin, m_body(self.model, deps), |j, a, wv| {
            for t in self.proxy.y_terms[j].clone() {
                let s = 3 * deps.slot_of_proxy[self.proxy.terms[t].proxy];
                let d = dphi[t];
                for k in 0..3 {
                    a_s[s + k] += a[k] * d;
                    w_s[s + k] += wv[k] * d;
                }
            }
        });
    }

    /// Marker `m`'s compact rows of `J_m` (3 per slot of `deps.proxies`, interleaved by axis) from
    /// its body's [`Evaluator::chain_rows`].
    #[inline(always)]
    fn marker_row(
        &self,
        deps: &crate::kinematics::layout::BodyDeps,
        kin: &Workspace,
        dphi: &[f64],
        aw: &[f64],
        m: usize,
        rows: &mut [f64],
    ) {
        let ns = deps.proxies.len();
        let x = kin.marker(m);
        let (a_s, w_s) = aw[..6 * ns].split_at(3 * ns);
        for s in 0..ns {
            let (a, wv) = (&a_s[3 * s..3 * s + 3], &w_s[3 * s..3 * s + 3]);
            rows[3 * s] = a[0] + wv[1] * x.z - wv[2] * x.y;
            rows[3 * s + 1] = a[1] + wv[2] * x.x - wv[0] * x.z;
            rows[3 * s + 2] = a[2] + wv[0] * x.y - wv[1] * x.x;
        }
        cpu::marker_offset_contributions(self.model, kin, m, |j, v| {
            for t in self.proxy.y_terms[j].clone() {
                let s = 3 * deps.slot_of_proxy[self.proxy.terms[t].proxy];
                let d = dphi[t];
                rows[s] += v.x * d;
                rows[s + 1] += v.y * d;
                rows[s + 2] += v.z * d;
            }
        });
    }

    /// Every observed, weighted marker's compact rows of `J_m` at the last evaluation
    /// ([`Evaluator::energy`] or [`Evaluator::linearize`] of `frame`): `f(m, proxies, rows, ws)`
    /// with `rows` 3 per entry of `proxies` (the proxies that can move the marker), interleaved
    /// by axis, as [`Evaluator::linearize`] forms them. No dense `J_m` is built.
    pub fn marker_rows(
        &self,
        frame: &FrameProblem<'_>,
        ws: &mut EvalWorkspace,
        mut f: impl FnMut(usize, &[usize], &[f64], &Workspace, &[f64]),
    ) {
        let EvalWorkspace { kin, y, dphi, aw, row, .. } = ws;
        for deps in &self.layout.bodies {
            let ns = deps.proxies.len();
            let mut any = false;
            for &m in &deps.markers {
                let obs = &frame.observed[3 * m..3 * m + 3];
                if frame.marker_weights[m] <= 0.0 || obs.iter().any(|v| v.is_nan()) {
                    continue;
                }
                if !any {
                    any = true;
                    self.chain_rows(deps, kin, dphi, aw);
                }
                let rows = &mut row[..3 * ns];
                self.marker_row(deps, kin, dphi, aw, m, rows);
                f(m, &deps.proxies, rows, kin, y);
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

/// The body that the markers of `deps` sit on.
fn m_body(model: &Model, deps: &crate::kinematics::layout::BodyDeps) -> usize {
    model.markers[deps.markers[0]].body
}
