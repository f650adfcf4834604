//! The per-frame retargeting QP over the robot's coordinates `q` (root pose, hinge joints).
//!
//! Each Gauss–Newton iteration minimises, over the step `Δ`,
//! `Σ_tasks w_p |J_p Δ − e_p|² + w_r |J_ω Δ − e_r|²` (position errors `e_p` in m, orientation
//! errors `e_r = log(R_target R_bodyᵀ)` in rad, world frame)
//! `+ Σ_planted feet w_c (|J_p Δ − e_p|² + |J_ω Δ − e_r|²)` (the foot pinned where it landed, flat)
//! `+ Σ_active w_g (J_z Δ − (m_g − z))²` (sole points below the ground margin `m_g`)
//! `+ Σ_active w_s (nᵀ(J_a − J_b) Δ − (m_s − d))²` (capsule pairs closer than `m_s`)
//! `+ w_t |q + Δ − q_prev|² + w_0 |q + Δ − q_ref|²_joints + μ |Δ|²`,
//! subject to the **hard** box `max(lo, q_prev − v dt) ≤ q + Δ ≤ min(hi, q_prev + v dt)` (joint
//! ranges and velocity limits) with the project's box QP. After the last iteration a sole still
//! below the ground lifts the root by that much (a pure translation: joints untouched).
//! Derivation and weights: `docs/RETARGET.md`.

mod composite;
mod fk;
mod rows;

use super::collide::capsule_distance;
use super::robot::Robot;
use super::targets::{Plan, Targets};
use crate::kinematics::cpu::Workspace;
use crate::solve::qp::{BoxQp, QpProblem, QpSolver};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// Weights (per m² or rad²), margins (m) and iteration counts of the retargeting solve.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct SolveSettings {
    /// `w_t`: temporal smoothness, towards the previous frame.
    pub smoothness: f64,
    /// `w_0`: towards the mapping's reference posture (joints only).
    pub posture: f64,
    /// `μ`: Levenberg damping on the step.
    pub damping: f64,
    /// `w_c`: a planted foot's pin (position and orientation).
    pub contact: f64,
    /// `w_g` and `m_g`: sole points kept above the ground.
    pub ground: f64,
    pub ground_margin: f64,
    /// `w_s` and `m_s`: capsule pairs kept apart.
    pub collision: f64,
    pub collision_margin: f64,
    /// Gauss–Newton iterations per frame, and for the first frame.
    pub iterations: usize,
    pub first_iterations: usize,
    /// Stop iterating once the last step moved no body by more than this (m; a turn counts at
    /// 0.1 m from the body's origin), or the shrinking steps cannot.
    pub tolerance: f64,
}

impl Default for SolveSettings {
    fn default() -> Self {
        SolveSettings {
            smoothness: 2e-3,
            posture: 1e-4,
            damping: 1e-6,
            contact: 2000.0,
            ground: 100.0,
            ground_margin: 0.001,
            collision: 100.0,
            collision_margin: 0.01,
            iterations: 5,
            first_iterations: 40,
            tolerance: 5e-4,
        }
    }
}

/// A planted foot's pin: where its body is held (world, m) and its flat orientation.
#[derive(Clone, Copy, Debug)]
pub struct Pin {
    pub pos: Vector3<f64>,
    pub rot: Matrix3<f64>,
}

/// How far (m) a capsule end may move before the candidate collision pairs are listed again
/// ([`Solver::list_pairs`]): a frame's steps rarely move an end by more.
const LIST_SLACK: f64 = 0.03;

/// How many measured step contractions a frame's first step borrows from
/// ([`Solver::borrowed_contraction`]).
const CONTRACTIONS: usize = 4;

/// The share of the tolerance a borrowed contraction's estimate must stay under (the estimate
/// is another frame's).
const BORROWED_MARGIN: f64 = 0.5;

/// The distance (m) from a body's origin at which its turn counts as motion in the convergence
/// test ([`SolveSettings::tolerance`]): a link's size.
const BODY_RADIUS: f64 = 0.1;

/// Per-thread scratch of the solve; nothing is allocated per frame once built.
pub struct Solver<'a> {
    robot: &'a Robot,
    plan: &'a Plan,
    pub settings: SolveSettings,
    pub ws: Workspace,
    y: Vec<f64>,
    /// The specialised forward kinematics when the robot takes it ([`fk`]), and per motion at
    /// the last [`Solver::forward`]: world axis, a world point on it (m) and rate `f'σ`.
    fast: Option<fk::Fast>,
    axes: Vec<Vector3<f64>>,
    origins: Vec<Vector3<f64>>,
    rates: Vec<f64>,
    h: DMatrix<f64>,
    g: DVector<f64>,
    lb: DVector<f64>,
    ub: DVector<f64>,
    dx: DVector<f64>,
    /// The previous iteration's step.
    last_dx: DVector<f64>,
    /// Body origins and orientations before the last step.
    moved_from: Vec<Vector3<f64>>,
    turned_from: Vec<Matrix3<f64>>,
    qp: BoxQp,
    /// Point Jacobian scratch: columns touched, and per column the position / angular parts.
    cols: Vec<usize>,
    jp: Vec<Vector3<f64>>,
    jr: Vec<Vector3<f64>>,
    /// A gathered single row (collision pairs): its columns and entries (dense, by column).
    row_cols: Vec<usize>,
    row: Vec<f64>,
    /// Per body: the coordinate-driven motions on its chain, `(motion, coordinate, rotation?)`
    /// (each robot coordinate drives one motion: hinges and the free joint).
    chains: Vec<Vec<(usize, usize, bool)>>,
    /// Per body, where its own joint's motions start in its chain.
    own: Vec<usize>,
    /// The point rows' sums per body, then per subtree ([`composite`]), about `centre` (m), and
    /// per motion its turn and the motion of the point at `centre`.
    composites: Vec<composite::Composite>,
    centre: Vector3<f64>,
    spatial: Vec<(Vector3<f64>, Vector3<f64>)>,
    /// Capsule ends in world (m), refreshed each iteration, and each capsule's bounding sphere
    /// (centre, radius).
    ends: Vec<(Vector3<f64>, Vector3<f64>)>,
    bounds: Vec<(Vector3<f64>, f64)>,
    /// Each capsule's bounding-sphere radius (m), and its axis-aligned box (world, lowest and
    /// highest corner, m) at the last [`Solver::forward`].
    radii: Vec<f64>,
    boxes: Vec<(Vector3<f64>, Vector3<f64>)>,
    /// The pairs that may come within the collision margin ([`Solver::list_pairs`]), in pair
    /// order, and the capsule ends when they were listed.
    listed: Vec<usize>,
    listed_at: Vec<(Vector3<f64>, Vector3<f64>)>,
    /// Capsule pairs that came within the margin in this frame: their rows stay (pushing out, or
    /// holding the distance) for the frame's remaining iterations, so that a task pulling back
    /// in cannot make the rows flicker on and off between iterations.
    sticky: Vec<bool>,
    /// A ground or collision row came on in the last assembly.
    activated: bool,
    /// [`Solver::closest_pair`] at the end of the last frame.
    closest: f64,
    /// The last measured contractions of the steps (`ρ`, a step over the one before it), newest
    /// first: their largest estimates what a frame's first step leaves to come
    /// ([`Solver::borrowed_contraction`]).
    contractions: [f64; CONTRACTIONS],
    /// Frames ended after their first step on a borrowed contraction since the last measured one.
    unmeasured: usize,
    /// Per capsule end (2 per capsule) of a foot: came below the ground margin in this frame;
    /// its row stays (lifting, or holding it at the margin) for the frame's remaining iterations.
    grounded: Vec<bool>,
}

impl<'a> Solver<'a> {
    pub fn new(robot: &'a Robot, plan: &'a Plan, settings: SolveSettings) -> Solver<'a> {
        let n = robot.model.nq();
        Solver {
            robot,
            plan,
            settings,
            ws: Workspace::new(&robot.model),
            y: Vec::with_capacity(robot.model.ny()),
            fast: fk::Fast::new(&robot.model),
            axes: vec![Vector3::zeros(); robot.model.motions.len()],
            origins: vec![Vector3::zeros(); robot.model.motions.len()],
            rates: vec![1.0; robot.model.motions.len()],
            h: DMatrix::zeros(n, n),
            g: DVector::zeros(n),
            lb: DVector::zeros(n),
            ub: DVector::zeros(n),
            dx: DVector::zeros(n),
            last_dx: DVector::zeros(n),
            moved_from: vec![Vector3::zeros(); robot.model.nb()],
            turned_from: vec![Matrix3::zeros(); robot.model.nb()],
            qp: {
                let mut qp = BoxQp::with_capacity(n);
                qp.symmetric = true;
                qp
            },
            cols: Vec::with_capacity(n),
            jp: vec![Vector3::zeros(); n],
            jr: vec![Vector3::zeros(); n],
            row_cols: Vec::with_capacity(n),
            row: vec![0.0; n],
            chains: rows::chain_motions(&robot.model),
            own: (0..robot.model.nb())
                .map(|b| robot.model.bodies[b].parent.map_or(0, |p| rows::chain_motions_len(&robot.model, p)))
                .collect(),
            composites: vec![composite::Composite::zero(); robot.model.nb()],
            centre: Vector3::zeros(),
            spatial: vec![(Vector3::zeros(), Vector3::zeros()); robot.model.motions.len()],
            ends: vec![(Vector3::zeros(), Vector3::zeros()); robot.capsules.len()],
            bounds: vec![(Vector3::zeros(), 0.0); robot.capsules.len()],
            radii: robot.capsules.iter().map(|c| 0.5 * (c.b - c.a).norm() + c.radius).collect(),
            boxes: vec![(Vector3::zeros(), Vector3::zeros()); robot.capsules.len()],
            listed: Vec::with_capacity(robot.pairs.len()),
            // Far away: the first forward kinematics lists the pairs.
            listed_at: vec![(Vector3::repeat(f64::INFINITY), Vector3::zeros()); robot.capsules.len()],
            sticky: vec![false; robot.pairs.len()],
            activated: false,
            closest: f64::INFINITY,
            contractions: [f64::INFINITY; CONTRACTIONS],
            unmeasured: 0,
            grounded: vec![false; 2 * robot.capsules.len()],
        }
    }

    pub fn robot(&self) -> &'a Robot {
        self.robot
    }
    pub fn plan(&self) -> &'a Plan {
        self.plan
    }
    /// Motion `k` at the last [`Solver::forward`]: world axis, a world point on it (m), and its
    /// rate `f'σ`.
    #[inline]
    fn motion(&self, k: usize) -> (Vector3<f64>, Vector3<f64>, f64) {
        (self.axes[k], self.origins[k], self.rates[k])
    }

    /// Capsule ends in world (m) at the last [`Solver::forward`].
    pub fn ends(&self) -> &[(Vector3<f64>, Vector3<f64>)] {
        &self.ends
    }

    /// Forward kinematics of `q` into `self.ws`, and the capsules' world ends.
    pub fn forward(&mut self, q: &[f64]) {
        match &self.fast {
            Some(f) => f.forward(q, &mut self.ws, &mut self.axes, &mut self.origins),
            None => {
                self.robot.state(q, &mut self.y);
                let (axes, origins, rates) = (&mut self.axes, &mut self.origins, &mut self.rates);
                fk::general(&self.robot.model, &self.y, &mut self.ws, axes, origins, rates);
            }
        }
        let mut moved = 0.0_f64;
        for (k, c) in self.robot.capsules.iter().enumerate() {
            let (r, p) = (&self.ws.body_rot[c.body], &self.ws.body_pos[c.body]);
            let e = (p + r * c.a, p + r * c.b);
            let at = &self.listed_at[k];
            moved = moved.max((e.0 - at.0).norm_squared()).max((e.1 - at.1).norm_squared());
            let r = Vector3::repeat(c.radius);
            self.boxes[k] = (e.0.inf(&e.1) - r, e.0.sup(&e.1) + r);
            self.ends[k] = e;
            self.bounds[k] = ((e.0 + e.1) * 0.5, self.radii[k]);
        }
        if moved > LIST_SLACK * LIST_SLACK {
            self.list_pairs();
        }
    }

    /// Lists the pairs whose bounding spheres are within the collision margin plus twice
    /// [`LIST_SLACK`] (and those with rows held this frame), and where the capsules stand: until
    /// a capsule end moves by more than the slack, no other pair can come within the margin.
    fn list_pairs(&mut self) {
        let reach = self.settings.collision_margin + 2.0 * LIST_SLACK;
        self.listed.clear();
        for (p, &(i, j)) in self.robot.pairs.iter().enumerate() {
            let ((bi, ri), (bj, rj)) = (self.bounds[i], self.bounds[j]);
            if self.sticky[p] || (bi - bj).norm_squared() <= (ri + rj + reach).powi(2) {
                self.listed.push(p);
            }
        }
        self.listed_at.copy_from_slice(&self.ends);
    }

    /// Solves frame `i` in place in `q` (warm start on entry). `prev`: the previous frame's
    /// solution and the time step (s); `pins`: per foot. Returns the iterations used.
    pub fn frame(
        &mut self,
        t: &Targets,
        i: usize,
        q: &mut [f64],
        prev: Option<(&[f64], f64)>,
        pins: &[Option<Pin>],
    ) -> usize {
        let iterations = if prev.is_some() { self.settings.iterations } else { self.settings.first_iterations };
        self.sticky.fill(false);
        self.grounded.fill(false);
        // Each run of iterations ends with the forward kinematics of its result.
        let mut used = self.iterate(t, i, q, prev, pins, iterations, 1.0);
        self.closest = self.closest_pair();
        if self.closest < 0.0 {
            // Still overlapping where the penalty balanced the tasks: the collision rows a
            // hundred times stiffer for as many iterations again.
            used += self.iterate(t, i, q, prev, pins, iterations, 100.0);
            self.closest = self.closest_pair();
        }
        let lift = self.lowest_sole().min(0.0);
        if lift < 0.0 {
            q[2] -= lift;
            self.forward(q);
            self.closest = self.closest_pair();
        }
        used
    }

    /// The smallest signed distance (m) between two capsules that may collide, among those whose
    /// bounding spheres and boxes touch (`+∞` when none do: then no pair overlaps).
    pub fn closest_pair(&self) -> f64 {
        let mut best = f64::INFINITY;
        for &p in &self.listed {
            let (i, j) = self.robot.pairs[p];
            let ((bi, ri), (bj, rj)) = (self.bounds[i], self.bounds[j]);
            if (bi - bj).norm_squared() <= (ri + rj).powi(2) && !self.apart(i, j, 0.0) {
                best = best.min(self.pair_distance(i, j).0);
            }
        }
        best
    }

    /// Whether the boxes of capsules `i` and `j` lie more than `m` (m) apart along an axis: then
    /// so do the capsules, and their distance need not be computed (a margin of 1e-12 m keeps
    /// that true of the computed distance).
    #[inline]
    fn apart(&self, i: usize, j: usize, m: f64) -> bool {
        let ((lo_i, hi_i), (lo_j, hi_j)) = (&self.boxes[i], &self.boxes[j]);
        let gap = (lo_i - hi_j).sup(&(lo_j - hi_i)).max();
        gap > m + 1e-12
    }

    /// [`Solver::closest_pair`] at the end of the last [`Solver::frame`].
    pub fn frame_closest(&self) -> f64 {
        self.closest
    }

    /// Signed distance (m) between capsules `i` and `j` at the last [`Solver::forward`], and
    /// their closest axis points (world).
    pub fn pair_distance(&self, i: usize, j: usize) -> (f64, Vector3<f64>, Vector3<f64>) {
        let (ci, cj) = (&self.robot.capsules[i], &self.robot.capsules[j]);
        let (ei, ej) = (&self.ends[i], &self.ends[j]);
        capsule_distance((&ei.0, &ei.1, ci.radius), (&ej.0, &ej.1, cj.radius))
    }

    /// Up to `n` Gauss–Newton iterations (collision weight × `stiffer`); the iterations used.
    #[allow(clippy::too_many_arguments)]
    fn iterate(
        &mut self,
        t: &Targets,
        i: usize,
        q: &mut [f64],
        prev: Option<(&[f64], f64)>,
        pins: &[Option<Pin>],
        n: usize,
        stiffer: f64,
    ) -> usize {
        let base = self.settings.collision;
        self.settings.collision = base * stiffer;
        let (mut used, mut last) = (0, f64::INFINITY);
        loop {
            self.forward(q);
            if used > 0 {
                // Converged when the last step moved no body by more than the tolerance, or
                // when the steps still to come cannot: shrinking by `ρ`, they add up to
                // `step ρ / (1 − ρ)`.
                let (step, tol) = (self.body_motion(), self.settings.tolerance);
                if last.is_finite() {
                    // Measured: remembered for the next frames' first steps.
                    self.contractions.rotate_right(1);
                    self.contractions[0] = step / last;
                    self.unmeasured = 0;
                }
                let small = |rho: f64, tol: f64| rho < 0.5 && step * rho / (1.0 - rho) < tol;
                let settled = if last.is_finite() {
                    small(step / last, tol)
                } else {
                    // After the first step: on a contraction borrowed from the last frames, with
                    // a margin.
                    step >= tol && self.borrowed_contraction().is_some_and(|rho| small(rho, BORROWED_MARGIN * tol))
                };
                if used == n || step < tol || settled {
                    self.unmeasured += usize::from(used == 1 && settled);
                    break;
                }
                last = step;
                self.last_dx.copy_from(&self.dx);
            }
            self.moved_from.copy_from_slice(&self.ws.body_pos);
            self.turned_from.copy_from_slice(&self.ws.body_rot);
            used += 1;
            self.assemble(t, i, q, prev, pins);
            self.dx.fill(0.0);
            let problem = QpProblem { h: &self.h, g: &self.g, lb: &self.lb, ub: &self.ub };
            if self.qp.solve(&problem, &mut self.dx).is_err() {
                break;
            }
            // A step reversing the last one (`Δ_k ≈ ρ Δ_{k−1}`, `ρ < 0`: Gauss–Newton
            // overshooting, as near a straightened knee) is shortened to `Δ_k / (1 − ρ)`, where
            // the oscillation's limit lies (Aitken); the box is convex, so the step stays in it.
            // Not when a ground or collision row came on: the problem changed, the step is new.
            if used > 1 {
                let rho = self.dx.dot(&self.last_dx) / self.last_dx.norm_squared();
                if rho < 0.0 && !self.activated {
                    self.dx /= 1.0 - rho;
                }
            }
            for (qj, d) in q.iter_mut().zip(self.dx.iter()) {
                *qj += d;
            }
        }
        self.settings.collision = base;
        used
    }

    /// After a frame's first step, `ρ` is not measured yet: the largest of the last
    /// [`CONTRACTIONS`] measured (the steps of neighbouring frames contract alike), unless a
    /// ground or collision row came on or is to come on (the problem changed), or
    /// [`CONTRACTIONS`] frames in a row already ended on a borrowed one (one is measured again).
    fn borrowed_contraction(&self) -> Option<f64> {
        if self.unmeasured >= CONTRACTIONS || self.activated || self.rows_to_come() {
            return None;
        }
        Some(self.contractions.iter().fold(0.0_f64, |m, &r| m.max(r)))
    }

    /// Whether a ground or collision row not yet held would come on at the last
    /// [`Solver::forward`]: a foot's capsule end below the ground margin, or a listed pair within
    /// the collision margin.
    fn rows_to_come(&self) -> bool {
        let (mg, ms) = (self.settings.ground_margin, self.settings.collision_margin);
        for (k, c) in self.robot.capsules.iter().enumerate() {
            if self.plan.feet.iter().any(|f| f.robot_body == c.body) {
                let (a, b) = self.ends[k];
                let low = |z: f64, e: usize| z - c.radius < mg && !self.grounded[2 * k + e];
                if low(a.z, 0) || low(b.z, 1) {
                    return true;
                }
            }
        }
        self.listed.iter().any(|&p| {
            let (i, j) = self.robot.pairs[p];
            let ((bi, ri), (bj, rj)) = (self.bounds[i], self.bounds[j]);
            !self.sticky[p]
                && (bi - bj).norm_squared() <= (ri + rj + ms).powi(2)
                && !self.apart(i, j, ms)
                && self.pair_distance(i, j).0 < ms
        })
    }

    /// How far the last step moved the bodies (m): the largest over bodies of the origin's
    /// displacement plus the turn (rad) times [`BODY_RADIUS`].
    fn body_motion(&self) -> f64 {
        let ws = &self.ws;
        let moved = ws.body_pos.iter().zip(&self.moved_from).zip(ws.body_rot.iter().zip(&self.turned_from));
        moved.fold(0.0, |m, ((p, p0), (r, r0))| {
            // |R − R₀|_F = 2√2 sin(θ/2) ≈ √2 θ.
            m.max((p - p0).norm() + BODY_RADIUS * (r - r0).norm() * std::f64::consts::FRAC_1_SQRT_2)
        })
    }

    /// Lowest point of any foot's capsules above the ground (m).
    pub fn lowest_sole(&self) -> f64 {
        self.plan.feet.iter().map(|f| self.lowest_of(f.robot_body)).fold(f64::INFINITY, f64::min)
    }

    /// Lowest point of body `b`'s capsules above the ground (m; `+∞` without capsules), at the
    /// last [`Solver::forward`].
    pub fn lowest_of(&self, b: usize) -> f64 {
        self.robot
            .capsules
            .iter()
            .zip(&self.ends)
            .filter(|(c, _)| c.body == b)
            .map(|(c, (p, q))| p.z.min(q.z) - c.radius)
            .fold(f64::INFINITY, f64::min)
    }
}

/// `log(R_target R_bodyᵀ)`: the world rotation vector taking the body to the target (rad).
pub fn rot_error(target: &Matrix3<f64>, body: &Matrix3<f64>) -> Vector3<f64> {
    Rotation3::from_matrix_unchecked(target * body.transpose()).scaled_axis()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::retarget::shipped;
    use rand::{RngExt, SeedableRng};

    /// A random in-range G1 posture (root anywhere near the origin).
    pub(super) fn posture(robot: &Robot, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<f64> {
        robot
            .model
            .coordinates
            .iter()
            .map(|c| {
                let (lo, hi) = (c.range.0.max(-1.0), c.range.1.min(1.0));
                lo + (hi - lo) * rng.random_range(0.1..0.9)
            })
            .collect()
    }

    /// The shipped G1 and a plan with no tasks, for a [`Solver`] with default settings.
    pub(super) fn g1() -> (Robot, Plan) {
        let (_, robot) = shipped("g1").unwrap().unwrap();
        let plan = Plan {
            tasks: vec![],
            feet: vec![],
            reference: vec![0.0; robot.model.nq()],
            leg_ratio: 1.0,
            robot_root_height: 0.8,
            human_root_height: 0.9,
        };
        (robot, plan)
    }

    #[test]
    fn point_jacobians_match_finite_differences_of_forward_kinematics() {
        let (robot, plan) = g1();
        let mut s = Solver::new(&robot, &plan, SolveSettings::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        // Not smaller: the rotation log's angle (an arccos) loses digits near zero.
        let h = 1e-4;
        for _ in 0..5 {
            let q = posture(&robot, &mut rng);
            for b in [robot.body("left_wrist_yaw_link").unwrap(), robot.body("right_ankle_roll_link").unwrap()] {
                s.forward(&q);
                let local = Vector3::new(0.03, -0.02, 0.05);
                let (r0, p0) = (s.ws.body_rot[b], s.ws.body_pos[b]);
                let x = p0 + r0 * local;
                s.point_jacobian(b, &x);
                let (cols, jp, jr) = (s.cols.clone(), s.jp.clone(), s.jr.clone());
                for j in 0..robot.model.nq() {
                    // Central differences: x and log(R R₀ᵀ) at q ± h e_j.
                    let mut at = |step: f64| {
                        let mut qh = q.clone();
                        qh[j] += step;
                        s.forward(&qh);
                        (s.ws.body_pos[b] + s.ws.body_rot[b] * local, rot_error(&s.ws.body_rot[b], &r0))
                    };
                    let ((xp, rp), (xm, rm)) = (at(h), at(-h));
                    let (dp, dr) = ((xp - xm) / (2.0 * h), (rp - rm) / (2.0 * h));
                    let (ap, ar) =
                        if cols.contains(&j) { (jp[j], jr[j]) } else { (Vector3::zeros(), Vector3::zeros()) };
                    assert!((dp - ap).norm() < 1e-5, "position column {j}: fd {dp:?} vs {ap:?}");
                    assert!((dr - ar).norm() < 1e-5, "rotation column {j}: fd {dr:?} vs {ar:?}");
                }
            }
        }
    }

    #[test]
    fn collision_rows_move_capsules_apart_at_the_rate_their_normal_predicts() {
        let (robot, plan) = g1();
        let mut s = Solver::new(&robot, &plan, SolveSettings::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let h = 1e-7;
        let distance = |s: &Solver, (i, j): (usize, usize)| s.pair_distance(i, j);
        for _ in 0..5 {
            let q = posture(&robot, &mut rng);
            for &pair in robot.pairs.iter().step_by(37) {
                s.forward(&q);
                let (d, pa, pb) = distance(&s, pair);
                let n = (pa - pb).normalize();
                let mut rate = vec![0.0; robot.model.nq()];
                s.point_jacobian(robot.capsules[pair.0].body, &pa);
                for &c in &s.cols {
                    rate[c] += n.dot(&s.jp[c]);
                }
                s.point_jacobian(robot.capsules[pair.1].body, &pb);
                for &c in &s.cols {
                    rate[c] -= n.dot(&s.jp[c]);
                }
                for (j, r) in rate.iter().enumerate() {
                    let mut qh = q.clone();
                    qh[j] += h;
                    s.forward(&qh);
                    let fd = (distance(&s, pair).0 - d) / h;
                    assert!((fd - r).abs() < 1e-4, "pair {pair:?} column {j}: fd {fd} vs {r}");
                }
            }
        }
    }
}
