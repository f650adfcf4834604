//! Pre-solve (METHOD.md, "Pre-solve"): a warm start for hard frames (large rotations, twisted
//! initial guesses, extreme poses, markers back after a gap). The root is placed by a rigid fit
//! of its markers ([`place_root`]), then root-to-leaf Gauss–Seidel sweeps solve one small local
//! subproblem per joint: that joint's pose proxies (and, when asked, its segment's scale proxies)
//! fitted to the markers of the segment and of its children, everything else held at the latest
//! values. Neighbouring subproblems overlap (a child's markers serve its parent's fit and its
//! own). The full trust-region QP then starts from the result. Derivation: `docs/KINEMATICS.md`,
//! "Pre-solve".
//!
//! Each local fit is a damped Gauss–Newton (Levenberg–Marquardt) iteration on the subproblem's
//! columns only, projected onto the step box and the proxy ranges; a step is kept only when it
//! lowers the local objective. All scratch lives in [`Presolver`]: no allocation per iteration.

use super::root::place_root;
use super::settings::SolverSettings;
use super::trqp::FrameSolver;
use crate::kinematics::assembly::{Evaluator, FrameProblem};
use crate::kinematics::cpu::{self, Workspace};
use crate::model::proxy::ProxyKind;

/// One local subproblem: proxies moved and markers fitted.
#[derive(Clone, Debug)]
pub struct Subproblem {
    /// The body whose joint this is.
    pub body: usize,
    /// Proxies moved, in the order of the local columns.
    pub proxies: Vec<usize>,
    /// Markers fitted: on the bodies these proxies move and on those bodies' children.
    pub markers: Vec<usize>,
    /// Entries of `y` driven by these proxies (their tracking terms join the local objective).
    pub ys: Vec<usize>,
    /// The fit is skipped when fewer of `markers` are observed.
    pub min_observed: usize,
    /// Bodies these proxies move, with their descendants (ascending), and every marker on them:
    /// what a local evaluation recomputes ([`cpu::forward_part`]); the rest stays as it is.
    pub bodies: Vec<usize>,
    pub placed: Vec<usize>,
}

/// The local subproblems of a model and the scratch of their fits; one per thread.
#[derive(Clone, Debug)]
pub struct Presolver {
    pub subproblems: Vec<Subproblem>,
    /// Root-to-leaf sweeps per pre-solve.
    pub sweeps: u32,
    /// Damped Gauss–Newton iterations per local fit (at most).
    pub iterations: u32,
    /// A local fit stops once a kept step lowers its objective by less than this fraction.
    pub rel_tol: f64,
    kin: Workspace,
    y: Vec<f64>,
    dphi: Vec<f64>,
    /// Local column of each proxy in the current subproblem (`usize::MAX`: not in it).
    slot: Vec<usize>,
    h: Vec<f64>,
    g: Vec<f64>,
    a: Vec<f64>,
    dp: Vec<f64>,
    rows: Vec<f64>,
    trial: Vec<f64>,
    step_box: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    damping_floor: f64,
}

impl Presolver {
    /// Subproblems for every non-root joint with free pose proxies, root to leaf; a proxy that
    /// drives several joints (a coupled spine) belongs to its first joint, and its subproblem
    /// fits the markers of every body it moves and of their children. With `with_scales`, each
    /// subproblem also moves the scale proxies of its segment (not yet taken by an earlier one).
    pub fn new(eval: &Evaluator<'_>, settings: &SolverSettings, with_scales: bool) -> Presolver {
        let (model, proxy) = (eval.model, eval.proxy);
        let np = proxy.np();
        let mut taken = vec![false; np];
        let mut subproblems = Vec::new();
        for (b, body) in model.bodies.iter().enumerate() {
            if body.parent.is_none() {
                continue;
            }
            let mut ks = Vec::new();
            let coords = model.motions[body.joint.motions.clone()].iter().filter_map(|mo| mo.coordinate);
            let scales = (0..3).map(|a| model.scale_index(b, a)).filter(|_| with_scales);
            for j in coords.chain(scales) {
                for t in proxy.y_terms[j].clone() {
                    let k = proxy.terms[t].proxy;
                    let is_scale = proxy.proxies[k].kind == ProxyKind::Scale;
                    if !taken[k] && (with_scales || !is_scale) && !ks.contains(&k) {
                        ks.push(k);
                    }
                }
            }
            if ks.is_empty() {
                continue;
            }
            for &k in &ks {
                taken[k] = true;
            }
            let ys: Vec<usize> = (0..proxy.ny())
                .filter(|&j| proxy.y_terms[j].clone().any(|t| ks.contains(&proxy.terms[t].proxy)))
                .collect();
            // Bodies moved directly: their joint or scale depends on these proxies.
            let moved: Vec<usize> = (0..model.nb())
                .filter(|&c| {
                    let bc = &model.bodies[c];
                    let joint = model.motions[bc.joint.motions.clone()].iter().filter_map(|mo| mo.coordinate);
                    let own = (0..3).map(|a| model.scale_index(c, a));
                    joint.chain(own).any(|j| ys.contains(&j))
                })
                .collect();
            let markers = (0..model.markers.len())
                .filter(|&m| {
                    let mb = model.markers[m].body;
                    moved.contains(&mb) || model.bodies[mb].parent.is_some_and(|p| moved.contains(&p))
                })
                .collect();
            let bodies: Vec<usize> =
                (0..model.nb()).filter(|&c| moved.iter().any(|&a| model.is_ancestor(a, c))).collect();
            let placed = (0..model.markers.len()).filter(|&m| bodies.contains(&model.markers[m].body)).collect();
            subproblems.push(Subproblem { body: b, proxies: ks, markers, ys, min_observed: 2, bodies, placed });
        }
        let n = subproblems.iter().map(|s| s.proxies.len()).max().unwrap_or(0);
        let step_box = proxy
            .proxies
            .iter()
            .map(|p| match p.kind {
                ProxyKind::Rotation => settings.step_rotation_rad,
                ProxyKind::Translation => settings.step_translation_m,
                ProxyKind::Scale => settings.step_scale,
            })
            .collect();
        Presolver {
            subproblems,
            sweeps: settings.presolve_sweeps,
            iterations: 10,
            rel_tol: 1e-4,
            kin: Workspace::new(model),
            y: vec![0.0; proxy.ny()],
            dphi: vec![0.0; proxy.terms.len()],
            slot: vec![usize::MAX; np],
            h: vec![0.0; n * n],
            g: vec![0.0; n],
            a: vec![0.0; n * n],
            dp: vec![0.0; n],
            rows: vec![0.0; 3 * n],
            trial: vec![0.0; np],
            step_box,
            lo: proxy.proxies.iter().map(|p| p.range.0).collect(),
            hi: proxy.proxies.iter().map(|p| p.range.1).collect(),
            damping_floor: settings.damping_floor,
        }
    }

    /// The local fits of the cold start's sweeps ([`super::init::cold_start`]): for each joint
    /// of [`Presolver::new`] (pose proxies only, root to leaf), first the markers of its own body
    /// (when at least two are observed, so that they can orient it), then those of its whole
    /// subtree (at least one): a distal segment at a neutral pose would otherwise pull an axial
    /// rotation the wrong way. Each fit stops as the frame solver does (relative decrease below
    /// `rel_decrease_tol`, at most `max_iterations` steps); two sweeps.
    pub fn cold(eval: &Evaluator<'_>, settings: &SolverSettings) -> Presolver {
        let model = eval.model;
        let mut pre = Presolver::new(eval, settings, false);
        for sub in std::mem::take(&mut pre.subproblems) {
            let b = sub.body;
            let own = (0..model.markers.len()).filter(|&m| model.markers[m].body == b).collect();
            let subtree = (0..model.markers.len()).filter(|&m| model.is_ancestor(b, model.markers[m].body)).collect();
            pre.subproblems.push(Subproblem { markers: own, min_observed: 2, ..sub.clone() });
            pre.subproblems.push(Subproblem { markers: subtree, min_observed: 1, ..sub });
        }
        pre.sweeps = 2;
        pre.iterations = settings.max_iterations;
        pre.rel_tol = settings.rel_decrease_tol;
        pre
    }

    /// [`Presolver::sweeps`] root-to-leaf sweeps of local fits of `frame` from `p`, in place
    /// (the root as it is).
    pub fn sweep(&mut self, eval: &Evaluator<'_>, frame: &FrameProblem<'_>, p: &mut [f64]) {
        self.sync(eval, p);
        for _ in 0..self.sweeps {
            for s in 0..self.subproblems.len() {
                self.fit_synced(eval, s, frame, p);
            }
        }
    }

    /// The whole model's kinematics at `p` into the scratch: what each local fit starts from.
    fn sync(&mut self, eval: &Evaluator<'_>, p: &[f64]) {
        eval.proxy.apply(p, &mut self.y, &mut self.dphi);
        cpu::forward(eval.model, &self.y, &mut self.kin);
    }

    /// Pre-solves `frame` from `p` in place: root placement, then [`Presolver::sweeps`]
    /// root-to-leaf sweeps of local fits. `solver` places the root and is left as it was.
    pub fn run(&mut self, eval: &Evaluator<'_>, solver: &mut FrameSolver<'_>, frame: &FrameProblem<'_>, p: &mut [f64]) {
        place_root(solver, frame, p);
        self.sweep(eval, frame, p);
    }

    /// Fits subproblem `s` in place (a few damped Gauss–Newton steps); skipped when fewer than
    /// [`Subproblem::min_observed`] of its markers are observed.
    pub fn fit(&mut self, eval: &Evaluator<'_>, s: usize, frame: &FrameProblem<'_>, p: &mut [f64]) {
        self.sync(eval, p);
        self.fit_synced(eval, s, frame, p);
    }

    /// [`Presolver::fit`] with the scratch's kinematics at `p` ([`Presolver::sync`]); leaves them
    /// at the fitted `p`. Each evaluation recomputes only the subproblem's bodies and markers.
    fn fit_synced(&mut self, eval: &Evaluator<'_>, s: usize, frame: &FrameProblem<'_>, p: &mut [f64]) {
        let observed = self.subproblems[s]
            .markers
            .iter()
            .filter(|&&m| frame.marker_weights[m] > 0.0 && !frame.observed[3 * m].is_nan())
            .count();
        if observed < self.subproblems[s].min_observed {
            return;
        }
        self.enter(s);
        let n = self.subproblems[s].proxies.len();
        let mut lambda = 1e-3;
        let mut e0 = self.local_model(eval, s, frame, p);
        // Whether the scratch's kinematics are at `p` (not at a rejected trial point).
        let mut at_p = true;
        for _ in 0..self.iterations {
            let mut accepted = false;
            while lambda < 1e8 {
                // (H + λ·diag(max(H_kk, floor))) Δ = −g, projected on the step box and ranges.
                self.a[..n * n].copy_from_slice(&self.h[..n * n]);
                for i in 0..n {
                    self.a[i * n + i] += lambda * self.h[i * n + i].max(self.damping_floor);
                    self.dp[i] = -self.g[i];
                }
                if !cholesky_solve(&mut self.a[..n * n], n, &mut self.dp[..n]) {
                    lambda *= 4.0;
                    continue;
                }
                self.trial.copy_from_slice(p);
                for (i, &k) in self.subproblems[s].proxies.iter().enumerate() {
                    let d = self.dp[i].clamp(-self.step_box[k], self.step_box[k]);
                    self.trial[k] = (p[k] + d).clamp(self.lo[k], self.hi[k]);
                }
                let e1 = self.local_energy(eval, s, frame);
                at_p = e1 < e0;
                if e1 < e0 {
                    p.copy_from_slice(&self.trial);
                    let rel = (e0 - e1) / e0.max(f64::MIN_POSITIVE);
                    lambda = (lambda / 3.0).max(1e-9);
                    accepted = rel > self.rel_tol;
                    break;
                }
                lambda *= 4.0;
            }
            if !accepted {
                break;
            }
            e0 = self.local_model(eval, s, frame, p);
        }
        if !at_p {
            let sub = &self.subproblems[s];
            eval.proxy.apply(p, &mut self.y, &mut self.dphi);
            cpu::forward_part(eval.model, &self.y, &mut self.kin, &sub.bodies, &sub.placed);
        }
        self.leave(s);
    }

    fn enter(&mut self, s: usize) {
        for (i, &k) in self.subproblems[s].proxies.iter().enumerate() {
            self.slot[k] = i;
        }
    }

    fn leave(&mut self, s: usize) {
        for &k in &self.subproblems[s].proxies {
            self.slot[k] = usize::MAX;
        }
    }

    /// Local Gauss–Newton model of subproblem `s` at `p`: `H` (row-major, n × n) and `g` of
    /// `E_s = ½ Σ_{m ∈ M_s} w_m ‖x̂_m − x_m‖² + ½ Σ_{j ∈ Y_s} w_t,j (y_j − y_ref,j)²` over the
    /// subproblem's proxies; returns `E_s`.
    fn local_model(&mut self, eval: &Evaluator<'_>, s: usize, frame: &FrameProblem<'_>, p: &[f64]) -> f64 {
        let (model, proxy) = (eval.model, eval.proxy);
        let sub = &self.subproblems[s];
        let n = sub.proxies.len();
        proxy.apply(p, &mut self.y, &mut self.dphi);
        cpu::forward_part(model, &self.y, &mut self.kin, &sub.bodies, &sub.placed);
        self.h[..n * n].fill(0.0);
        self.g[..n].fill(0.0);
        let mut e = 0.0;
        for &m in &sub.markers {
            let w = frame.marker_weights[m];
            let obs = &frame.observed[3 * m..3 * m + 3];
            if w <= 0.0 || obs.iter().any(|v| v.is_nan()) {
                continue;
            }
            let rows = &mut self.rows[..3 * n];
            rows.fill(0.0);
            let (slot, dphi) = (&self.slot, &self.dphi);
            cpu::marker_contributions(model, &self.kin, m, |j, v| {
                for t in proxy.y_terms[j].clone() {
                    let i = slot[proxy.terms[t].proxy];
                    if i != usize::MAX {
                        let d = dphi[t];
                        rows[3 * i] += v.x * d;
                        rows[3 * i + 1] += v.y * d;
                        rows[3 * i + 2] += v.z * d;
                    }
                }
            });
            let r: [f64; 3] = std::array::from_fn(|a| self.kin.markers[3 * m + a] - obs[a]);
            e += 0.5 * w * (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
            for i in 0..n {
                let ci = &rows[3 * i..3 * i + 3];
                self.g[i] += w * (ci[0] * r[0] + ci[1] * r[1] + ci[2] * r[2]);
                for k in 0..n {
                    let ck = &rows[3 * k..3 * k + 3];
                    self.h[i * n + k] += w * (ci[0] * ck[0] + ci[1] * ck[1] + ci[2] * ck[2]);
                }
            }
        }
        for &j in &sub.ys {
            let w = frame.tracking_weights[j];
            if w <= 0.0 {
                continue;
            }
            let ej = self.y[j] - frame.tracking_ref[j];
            e += 0.5 * w * ej * ej;
            for t in proxy.y_terms[j].clone() {
                let i = self.slot[proxy.terms[t].proxy];
                if i == usize::MAX {
                    continue;
                }
                self.g[i] += w * self.dphi[t] * ej;
                for u in proxy.y_terms[j].clone() {
                    let k = self.slot[proxy.terms[u].proxy];
                    if k != usize::MAX {
                        self.h[i * n + k] += w * self.dphi[t] * self.dphi[u];
                    }
                }
            }
        }
        e
    }

    /// `E_s` at `self.trial`.
    fn local_energy(&mut self, eval: &Evaluator<'_>, s: usize, frame: &FrameProblem<'_>) -> f64 {
        let sub = &self.subproblems[s];
        eval.proxy.apply(&self.trial, &mut self.y, &mut self.dphi);
        cpu::forward_part(eval.model, &self.y, &mut self.kin, &sub.bodies, &sub.placed);
        let mut e = 0.0;
        for &m in &sub.markers {
            let w = frame.marker_weights[m];
            let obs = &frame.observed[3 * m..3 * m + 3];
            if w <= 0.0 || obs.iter().any(|v| v.is_nan()) {
                continue;
            }
            e += 0.5 * w * (0..3).map(|a| (self.kin.markers[3 * m + a] - obs[a]).powi(2)).sum::<f64>();
        }
        for &j in &sub.ys {
            let w = frame.tracking_weights[j];
            if w > 0.0 {
                e += 0.5 * w * (self.y[j] - frame.tracking_ref[j]).powi(2);
            }
        }
        e
    }

    /// The local model of subproblem `s` at `p`: `(H row-major n × n, g, E_s)`, for tests and
    /// inspection (copies; not for the hot path).
    pub fn local_gauss_newton(
        &mut self,
        eval: &Evaluator<'_>,
        s: usize,
        frame: &FrameProblem<'_>,
        p: &[f64],
    ) -> (Vec<f64>, Vec<f64>, f64) {
        self.sync(eval, p);
        self.enter(s);
        let e = self.local_model(eval, s, frame, p);
        self.leave(s);
        let n = self.subproblems[s].proxies.len();
        (self.h[..n * n].to_vec(), self.g[..n].to_vec(), e)
    }
}

/// Solves `A x = b` for symmetric positive definite `A` (row-major n × n, overwritten by its
/// Cholesky factor); `b` becomes `x`. False when `A` is not positive definite.
fn cholesky_solve(a: &mut [f64], n: usize, b: &mut [f64]) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d <= 0.0 || !d.is_finite() {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut v = a[i * n + j];
            for k in 0..j {
                v -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = v / d;
        }
    }
    for i in 0..n {
        let mut v = b[i];
        for k in 0..i {
            v -= a[i * n + k] * b[k];
        }
        b[i] = v / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut v = b[i];
        for k in i + 1..n {
            v -= a[k * n + i] * b[k];
        }
        b[i] = v / a[i * n + i];
    }
    true
}

/// The outlier threshold of METHOD.md: `median + 6·MAD` of `values` (NaNs ignored), with the raw
/// median absolute deviation (not scaled by 1.4826: "exceeds the median by 6 MADs"). NaN when
/// there are no values.
pub fn outlier_threshold(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    let med = super::median(&mut v);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - med).abs()).collect();
    med + 6.0 * super::median(&mut dev)
}
