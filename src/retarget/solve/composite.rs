//! The rows of points fixed on bodies (mapped tasks, foot pins, ground rows) summed per subtree
//! before they meet the Jacobian: `H`'s entry of two coordinates on one chain needs only what
//! hangs below the deeper one, as a composite-rigid-body inertia does (Featherstone's CRBA, with
//! weighted points for masses).
//!
//! A coordinate's motion moves a point `x` by `v = v₀ + ω × x'`, `x' = x − c` (`c`: the root
//! body's origin, to keep the sums small; `v₀` the motion of the point at `c`, `ω` its turn).
//! A point row `|W^½ (J_p Δ − e)|²` (weights `W`, 3 × 3) and a turn row `w_r |J_ω Δ − e_r|²` add
//! `v_aᵀ W v_b + w_r ω_a·ω_b` to `H` and `−(v_a·W e + w_r ω_a·e_r)` to `g`; with `[x']` the
//! cross-product matrix that is, per subtree,
//! `H_ab = v₀_a·(A v₀_b − B ω_b) + ω_a·(C ω_b − Bᵀ v₀_b)` and `g_b = −(v₀_b·f + ω_b·τ)`, where
//! `A = Σ W`, `B = Σ W [x']`, `C = Σ ([x']ᵀ W [x'] + w_r I)`, `f = Σ W e` and
//! `τ = Σ (x' × W e + w_r e_r)` over the subtree's rows. Cost: per coordinate one product with
//! its subtree's sums and one 6-dot per ancestor coordinate, instead of every row's chain squared.

use super::Solver;
use nalgebra::{Matrix3, Vector3};

/// The sums of one subtree's rows ([module docs](self)).
#[derive(Clone, Copy, Debug)]
pub(super) struct Composite {
    a: Matrix3<f64>,
    b: Matrix3<f64>,
    c: Matrix3<f64>,
    f: Vector3<f64>,
    tau: Vector3<f64>,
}

impl Composite {
    pub(super) fn zero() -> Composite {
        Composite {
            a: Matrix3::zeros(),
            b: Matrix3::zeros(),
            c: Matrix3::zeros(),
            f: Vector3::zeros(),
            tau: Vector3::zeros(),
        }
    }

    fn add(&mut self, o: &Composite) {
        self.a += o.a;
        self.b += o.b;
        self.c += o.c;
        self.f += o.f;
        self.tau += o.tau;
    }
}

/// A point row's weights: `w I` (tasks, pins) or `w e_z e_zᵀ` (ground rows, height only).
#[derive(Clone, Copy, Debug)]
pub(super) enum Weight {
    Isotropic(f64),
    Height(f64),
}

impl Solver<'_> {
    /// Starts a new sum of point rows (the root body's origin as `c`).
    pub(super) fn start_points(&mut self) {
        self.centre = self.ws.body_pos[0];
        self.composites.fill(Composite::zero());
    }

    /// Adds the rows of world point `x` on body `b`: weights `w` on its position error `e` (m),
    /// and `wr` on its body's turn error `er` (rad).
    pub(super) fn add_point(
        &mut self,
        b: usize,
        x: &Vector3<f64>,
        w: Weight,
        e: &Vector3<f64>,
        wr: f64,
        er: &Vector3<f64>,
    ) {
        let x = x - self.centre;
        let s = &mut self.composites[b];
        match w {
            Weight::Isotropic(0.0) | Weight::Height(0.0) => {}
            Weight::Isotropic(w) => {
                // [x']ᵀ[x'] = |x'|² I − x' x'ᵀ.
                let xx = x * x.transpose();
                s.a += Matrix3::from_diagonal_element(w);
                s.b += x.cross_matrix() * w;
                s.c += (Matrix3::from_diagonal_element(x.norm_squared()) - xx) * w;
                let we = e * w;
                s.f += we;
                s.tau += x.cross(&we);
            }
            Weight::Height(w) => {
                // e_zᵀ [x'] = (−x'_y, x'_x, 0): the row of the height's turn rates.
                let u = Vector3::new(-x.y, x.x, 0.0);
                s.a[(2, 2)] += w;
                for k in 0..3 {
                    s.b[(2, k)] += w * u[k];
                }
                s.c += u * u.transpose() * w;
                let we = Vector3::new(0.0, 0.0, w * e.z);
                s.f += we;
                s.tau += x.cross(&we);
            }
        }
        if wr > 0.0 {
            s.c += Matrix3::from_diagonal_element(wr);
            s.tau += er * wr;
        }
    }

    /// Sums the subtrees (bodies are stored parents first) and adds their rows to `H` (both
    /// triangles) and `g`.
    pub(super) fn add_points(&mut self) {
        let model = &self.robot.model;
        for b in (1..model.nb()).rev() {
            if let Some(p) = model.bodies[b].parent {
                let s = self.composites[b];
                self.composites[p].add(&s);
            }
        }
        // Each motion's (turn, motion of the point at c).
        for (k, m) in model.motions.iter().enumerate() {
            let (axis, origin, rate) = self.motion(k);
            let w = axis * rate;
            self.spatial[k] = match m.kind {
                crate::model::MotionKind::Rotation => (w, w.cross(&(self.centre - origin))),
                crate::model::MotionKind::Translation => (Vector3::zeros(), w),
            };
        }
        let n = self.g.len();
        let h = self.h.as_mut_slice();
        for b in 0..model.nb() {
            let chain = &self.chains[b];
            let s = &self.composites[b];
            for p in self.own[b]..chain.len() {
                let (k, j, rotation) = chain[p];
                let (om, v0) = self.spatial[k];
                let (fv, fw) = match rotation {
                    true => (s.a * v0 - s.b * om, s.c * om - s.b.tr_mul(&v0)),
                    false => (s.a * v0, -s.b.tr_mul(&v0)),
                };
                self.g[j] -= v0.dot(&s.f) + om.dot(&s.tau);
                for &(ka, ja, _) in &chain[..=p] {
                    let (oma, v0a) = self.spatial[ka];
                    let v = v0a.dot(&fv) + oma.dot(&fw);
                    h[j.max(ja) * n + j.min(ja)] += v;
                    if ja != j {
                        h[j.min(ja) * n + j.max(ja)] += v;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{g1, posture};
    use super::super::{SolveSettings, Solver};
    use super::*;
    use nalgebra::{DMatrix, DVector};
    use rand::{RngExt, SeedableRng};

    #[test]
    fn subtree_sums_give_the_rows_of_the_point_jacobians() {
        let (robot, plan) = g1();
        let mut s = Solver::new(&robot, &plan, SolveSettings::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = robot.model.nq();
        let names = ["pelvis", "left_wrist_yaw_link", "right_ankle_roll_link", "torso_link", "left_knee_link"];
        let bodies: Vec<usize> = names.iter().map(|b| robot.body(b).unwrap()).collect();
        for _ in 0..5 {
            let mut q = posture(&robot, &mut rng);
            q[..3].copy_from_slice(&[3.0, -2.0, 0.8]);
            s.forward(&q);
            let mut v =
                || Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            // (body, point, weights, position error, turn weight, turn error)
            let rows: Vec<_> = bodies
                .iter()
                .enumerate()
                .map(|(k, &b)| {
                    let x = s.ws.body_pos[b] + 0.05 * v();
                    let w = if k == 2 { Weight::Height(100.0) } else { Weight::Isotropic(0.5 + k as f64) };
                    (b, x, w, 0.01 * v(), if k % 2 == 0 { 0.3 } else { 0.0 }, 0.01 * v())
                })
                .collect();
            s.h.fill(0.0);
            s.g.fill(0.0);
            s.start_points();
            for &(b, x, w, e, wr, er) in &rows {
                s.add_point(b, &x, w, &e, wr, &er);
            }
            s.add_points();
            let (mut h, mut g) = (DMatrix::<f64>::zeros(n, n), DVector::<f64>::zeros(n));
            for &(b, x, w, e, wr, er) in &rows {
                let wm = match w {
                    Weight::Isotropic(w) => Matrix3::from_diagonal_element(w),
                    Weight::Height(w) => Matrix3::from_diagonal(&Vector3::new(0.0, 0.0, w)),
                };
                s.point_jacobian(b, &x);
                for &i in &s.cols {
                    g[i] -= s.jp[i].dot(&(wm * e)) + wr * s.jr[i].dot(&er);
                    for &j in &s.cols {
                        h[(i, j)] += s.jp[i].dot(&(wm * s.jp[j])) + wr * s.jr[i].dot(&s.jr[j]);
                    }
                }
            }
            let scale = h.amax();
            assert!((&s.h - &h).amax() < 1e-12 * scale, "H differs by {:e}", (&s.h - &h).amax());
            assert!((&s.g - &g).amax() < 1e-12 * g.amax().max(1.0), "g differs by {:e}", (&s.g - &g).amax());
        }
    }
}
