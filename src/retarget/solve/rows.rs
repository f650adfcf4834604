//! The least-squares rows of the per-frame QP (`H`, both triangles, and `g`), one function per
//! kind: mapped tasks and foot pins, ground rows (points on bodies, summed per subtree:
//! [`super::composite`]), collision rows, and the diagonal terms with the hard bounds
//! (`docs/RETARGET.md` §4).

use super::composite::Weight;
use super::{rot_error, Pin, Solver};
use crate::retarget::targets::Targets;
use nalgebra::Vector3;

impl Solver<'_> {
    pub(super) fn assemble(
        &mut self,
        t: &Targets,
        i: usize,
        q: &[f64],
        prev: Option<(&[f64], f64)>,
        pins: &[Option<Pin>],
    ) {
        // Both triangles: the QP reads the upper one, and factors from the lower one's columns.
        self.h.as_mut_slice().fill(0.0);
        self.activated = false;
        self.g.fill(0.0);
        self.start_points();
        for k in 0..self.plan.tasks.len() {
            let task = &self.plan.tasks[k];
            let (b, wp, wr) = (task.robot_body, task.w_pos, task.w_rot);
            let x = self.ws.body_pos[b];
            let ep = t.pos[i][k] - x;
            let er = if wr > 0.0 { rot_error(&t.rot[i][k], &self.ws.body_rot[b]) } else { Vector3::zeros() };
            self.add_point(b, &x, Weight::Isotropic(wp), &ep, wr, &er);
        }
        for (f, pin) in self.plan.feet.iter().zip(pins) {
            if let Some(pin) = pin {
                let (b, w) = (f.robot_body, self.settings.contact);
                let x = self.ws.body_pos[b];
                let er = rot_error(&pin.rot, &self.ws.body_rot[b]);
                self.add_point(b, &x, Weight::Isotropic(w), &(pin.pos - x), w, &er);
            }
        }
        self.add_ground();
        self.add_points();
        self.add_collisions();
        self.add_diagonal(q, prev);
    }

    /// Fills `cols`, `jp`, `jr` with the Jacobian of world point `x` fixed on body `b`: a
    /// rotation of rate `f'` about world axis `ω` through `o` moves it by `f' ω × (x − o)` and
    /// turns it by `f' ω`; a translation moves it by `f' σ ω` ([`cpu::chain_contributions`]
    /// without the scale columns, which the robot does not have).
    pub(super) fn point_jacobian(&mut self, b: usize, x: &Vector3<f64>) {
        self.cols.clear();
        for &(k, j, rotation) in &self.chains[b] {
            let (axis, origin, rate) = self.motion(k);
            let w = axis * rate;
            self.cols.push(j);
            if rotation {
                self.jp[j] = w.cross(&(x - origin));
                self.jr[j] = w;
            } else {
                self.jp[j] = w;
                self.jr[j] = Vector3::zeros();
            }
        }
    }

    /// Starts gathering a single row `r` (`w (r · Δ − e)²`, [`Self::add_gathered_row`]).
    fn start_row(&mut self) {
        self.row_cols.clear();
    }

    /// Adds `n · jp[j]` over the columns in `cols` to the row being gathered.
    fn gather_row(&mut self, n: &Vector3<f64>) {
        for &j in &self.cols {
            if !self.row_cols.contains(&j) {
                self.row_cols.push(j);
                self.row[j] = 0.0;
            }
            self.row[j] += n.dot(&self.jp[j]);
        }
    }

    /// `w (r · Δ − e)²` with the gathered row `r` (both triangles of `H`).
    fn add_gathered_row(&mut self, w: f64, e: f64) {
        let n = self.g.len();
        let h = self.h.as_mut_slice();
        for (ia, &a) in self.row_cols.iter().enumerate() {
            let ra = w * self.row[a];
            self.g[a] -= ra * e;
            for &b in &self.row_cols[ia..] {
                let v = ra * self.row[b];
                h[a.max(b) * n + a.min(b)] += v;
                if a != b {
                    h[a.min(b) * n + a.max(b)] += v;
                }
            }
        }
    }

    /// Rows lifting foot capsule ends that are below the ground margin.
    fn add_ground(&mut self) {
        let (m, w) = (self.settings.ground_margin, self.settings.ground);
        for k in 0..self.robot.capsules.len() {
            let c = &self.robot.capsules[k];
            if !self.plan.feet.iter().any(|f| f.robot_body == c.body) {
                continue;
            }
            let (body, r) = (c.body, c.radius);
            for (e, end) in [self.ends[k].0, self.ends[k].1].into_iter().enumerate() {
                let gap = end.z - r;
                if gap < m || self.grounded[2 * k + e] {
                    self.activated |= !self.grounded[2 * k + e];
                    self.grounded[2 * k + e] = true;
                    let none = Vector3::zeros();
                    self.add_point(body, &end, Weight::Height(w), &Vector3::new(0.0, 0.0, m - gap), 0.0, &none);
                }
            }
        }
    }

    /// Rows pushing apart capsule pairs closer than the collision margin: the closest points'
    /// relative motion along their normal, `nᵀ(J_a − J_b) Δ ≥ m_s − d`.
    fn add_collisions(&mut self) {
        let (m, w) = (self.settings.collision_margin, self.settings.collision);
        for l in 0..self.listed.len() {
            let p = self.listed[l];
            let (i, j) = self.robot.pairs[p];
            let ((bi, ri), (bj, rj)) = (self.bounds[i], self.bounds[j]);
            if !self.sticky[p] && ((bi - bj).norm_squared() > (ri + rj + m).powi(2) || self.apart(i, j, m)) {
                continue;
            }
            let (d, pa, pb) = self.pair_distance(i, j);
            if (d >= m && !self.sticky[p]) || (pa - pb).norm() < 1e-9 {
                continue;
            }
            self.activated |= !self.sticky[p];
            self.sticky[p] = true;
            let push = (m - d).max(0.0);
            let n = (pa - pb).normalize();
            let (bi, bj) = (self.robot.capsules[i].body, self.robot.capsules[j].body);
            // One row, nᵀ(J_a − J_b): the coordinates both points share (root, waist) cancel.
            self.start_row();
            self.point_jacobian(bi, &pa);
            self.gather_row(&n);
            self.point_jacobian(bj, &pb);
            self.gather_row(&(-n));
            self.add_gathered_row(w, push);
        }
    }

    /// Smoothness, posture and damping on the diagonal, and the hard bounds.
    fn add_diagonal(&mut self, q: &[f64], prev: Option<(&[f64], f64)>) {
        let s = &self.settings;
        let model = &self.robot.model;
        for j in 0..model.nq() {
            self.h[(j, j)] += s.damping;
            let (lo, hi) = model.coordinates[j].range;
            let (mut lo, mut hi) = (lo, hi);
            if let Some((qp, dt)) = prev {
                self.h[(j, j)] += s.smoothness;
                self.g[j] += s.smoothness * (q[j] - qp[j]);
                let v = self.robot.velocity[j] * dt;
                lo = lo.max(qp[j] - v);
                hi = hi.min(qp[j] + v);
            }
            if j >= 6 {
                self.h[(j, j)] += s.posture;
                self.g[j] += s.posture * (q[j] - self.plan.reference[j]);
            }
            self.lb[j] = lo - q[j];
            self.ub[j] = hi - q[j];
        }
    }
}

/// Per body, the coordinate-driven motions of its chain (root first).
pub(super) fn chain_motions(model: &crate::model::Model) -> Vec<Vec<(usize, usize, bool)>> {
    (0..model.nb())
        .map(|b| {
            model
                .chain(b)
                .iter()
                .flat_map(|&a| model.bodies[a].joint.motions.clone())
                .filter_map(|k| {
                    let m = &model.motions[k];
                    m.coordinate.map(|c| (k, c, m.kind == crate::model::MotionKind::Rotation))
                })
                .collect()
        })
        .collect()
}

/// How many coordinate-driven motions body `b`'s chain has ([`chain_motions`]).
pub(super) fn chain_motions_len(model: &crate::model::Model, b: usize) -> usize {
    let driven =
        |a: &usize| model.bodies[*a].joint.motions.clone().filter(|&k| model.motions[k].coordinate.is_some()).count();
    model.chain(b).iter().map(driven).sum()
}
