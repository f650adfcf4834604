//! Behaviour of the QP backends: BoxQp against clarabel and against the KKT conditions,
//! edge cases of the box (fixed, infinite, degenerate), error reporting, and clarabel's
//! general linear constraints.

use nalgebra::{DMatrix, DVector};
use smocap::solve::qp::{
    BoxQp, BoxQpSettings, ClarabelQp, ClarabelQpSettings, LinearConstraints, QpError, QpProblem, QpSolver, QpStatus,
};

/// SplitMix64: tiny seeded generator so the tests need no RNG API.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[lo, hi)`.
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

struct Owned {
    h: DMatrix<f64>,
    g: DVector<f64>,
    lb: DVector<f64>,
    ub: DVector<f64>,
}

impl Owned {
    fn problem(&self) -> QpProblem<'_> {
        QpProblem { h: &self.h, g: &self.g, lb: &self.lb, ub: &self.ub }
    }
}

/// SPD `H = s (AᵀA/n + 0.05 I)` with `s` spanning two decades.
fn random_spd(rng: &mut Rng, n: usize) -> DMatrix<f64> {
    let a = DMatrix::from_fn(n, n, |_, _| rng.uniform(-1.0, 1.0));
    let s = 10f64.powf(rng.uniform(-1.0, 1.0));
    (a.transpose() * &a / n as f64 + DMatrix::identity(n, n) * 0.05) * s
}

/// Random bounds: 10% fixed, 10% upper only, 10% lower only, 5% free, rest finite boxes.
fn random_problem(rng: &mut Rng, n: usize) -> Owned {
    let h = random_spd(rng, n);
    let scale = h.diagonal().max();
    let g = DVector::from_fn(n, |_, _| rng.uniform(-2.0, 2.0) * scale);
    let (mut lb, mut ub) = (DVector::zeros(n), DVector::zeros(n));
    for i in 0..n {
        let r = rng.uniform(0.0, 1.0);
        let (l, u) = (-rng.uniform(0.0, 1.5), rng.uniform(0.0, 1.5));
        (lb[i], ub[i]) = match r {
            r if r < 0.10 => (l + u, l + u),
            r if r < 0.20 => (f64::NEG_INFINITY, u),
            r if r < 0.30 => (l, f64::INFINITY),
            r if r < 0.35 => (f64::NEG_INFINITY, f64::INFINITY),
            _ => (l, u),
        };
    }
    Owned { h, g, lb, ub }
}

/// Largest violation of the box-QP KKT conditions (projected gradient), relative to `1+‖g‖∞`.
/// A variable within `at_bound` (relative) of a bound counts as on it.
fn kkt_violation_tol(p: &Owned, x: &DVector<f64>, at_bound: f64) -> f64 {
    let grad = &p.h * x + &p.g;
    let mut worst = 0.0_f64;
    for i in 0..x.len() {
        assert!(x[i] >= p.lb[i] && x[i] <= p.ub[i], "x[{i}] = {} outside [{}, {}]", x[i], p.lb[i], p.ub[i]);
        let gi = grad[i];
        let v = if p.lb[i] == p.ub[i] {
            0.0
        } else if x[i] <= p.lb[i] + at_bound * p.lb[i].abs().max(1.0) {
            (-gi).max(0.0)
        } else if x[i] >= p.ub[i] - at_bound * p.ub[i].abs().max(1.0) {
            gi.max(0.0)
        } else {
            gi.abs()
        };
        worst = worst.max(v);
    }
    worst / (1.0 + p.g.amax())
}

/// [`kkt_violation_tol`] with variables exactly on a bound (as BoxQp leaves them).
fn kkt_violation(p: &Owned, x: &DVector<f64>) -> f64 {
    kkt_violation_tol(p, x, 0.0)
}

fn boxqp_solve(p: &Owned) -> (DVector<f64>, f64, QpStatus) {
    let mut x = DVector::zeros(p.g.len());
    let stats = BoxQp::new().solve(&p.problem(), &mut x).expect("boxqp solve");
    (x, stats.objective, stats.status)
}

/// Clarabel as a test oracle: tolerances tighter than the defaults, because interior-point
/// iterates approach weakly active bounds only like `√gap`.
fn oracle_settings() -> ClarabelQpSettings {
    ClarabelQpSettings {
        tol_gap_abs: 1e-13,
        tol_gap_rel: 1e-13,
        tol_feas: 1e-12,
        tol_ktratio: 1e-10,
        ..Default::default()
    }
}

fn clarabel_solve(p: &Owned) -> (DVector<f64>, f64) {
    let mut x = DVector::zeros(p.g.len());
    let stats = ClarabelQp::new(oracle_settings()).solve(&p.problem(), &mut x).expect("clarabel solve");
    assert_eq!(stats.status, QpStatus::Solved);
    (x, stats.objective)
}

fn assert_close(a: &DVector<f64>, b: &DVector<f64>, tol: f64, what: &str) {
    for i in 0..a.len() {
        let err = (a[i] - b[i]).abs() / b[i].abs().max(1.0);
        assert!(err <= tol, "{what}: component {i}: {} vs {} (err {err:e})", a[i], b[i]);
    }
}

#[test]
fn boxqp_matches_clarabel_on_random_problems() {
    let mut rng = Rng(0x5eed);
    let mut box_solver = BoxQp::new();
    let mut ipm = ClarabelQp::new(oracle_settings());
    for n in 1..=60 {
        for _ in 0..3 {
            let p = random_problem(&mut rng, n);
            let mut xb = DVector::zeros(n);
            let sb = box_solver.solve(&p.problem(), &mut xb).expect("boxqp");
            let mut xc = DVector::zeros(n);
            let sc = ipm.solve(&p.problem(), &mut xc).expect("clarabel");
            assert_eq!(sb.status, QpStatus::Solved, "n = {n}");
            assert_eq!(sc.status, QpStatus::Solved, "n = {n}");
            assert!(kkt_violation(&p, &xb) <= 1e-9, "n = {n}: boxqp KKT {:e}", kkt_violation(&p, &xb));
            assert_close(&xb, &xc, 1e-6, &format!("n = {n}"));
            let fc = p.problem().objective(&xc);
            assert!((sb.objective - fc).abs() <= 1e-9 * fc.abs().max(1.0), "n = {n}: {} vs {fc}", sb.objective);
            // Interior-point iterates stop short of weakly active bounds: count them as active.
            let kc = kkt_violation_tol(&p, &xc, 1e-6);
            assert!(kc <= 1e-6, "n = {n}: clarabel KKT {kc:e}");
        }
    }
}

#[test]
fn boxqp_interior_optimum_equals_newton_solution() {
    let mut rng = Rng(1);
    for (n, inf) in [(1, false), (7, false), (40, true)] {
        let h = random_spd(&mut rng, n);
        let g = DVector::from_fn(n, |_, _| rng.uniform(-1.0, 1.0));
        let expected = h.clone().cholesky().expect("spd").solve(&(-&g));
        let wide = if inf { f64::INFINITY } else { 10.0 * expected.amax() + 1.0 };
        let p = Owned { h, g, lb: DVector::from_element(n, -wide), ub: DVector::from_element(n, wide) };
        let (x, f, status) = boxqp_solve(&p);
        assert_eq!(status, QpStatus::Solved);
        assert_close(&x, &expected, 1e-10, "interior optimum");
        assert!((f - p.problem().objective(&expected)).abs() <= 1e-12 * f.abs().max(1.0));
        // Also with no constraint rows at all for clarabel when the bounds are infinite.
        let (xc, _) = clarabel_solve(&p);
        assert_close(&xc, &expected, 1e-7, "clarabel interior optimum");
    }
}

#[test]
fn boxqp_all_active_optimum_is_a_corner() {
    let mut rng = Rng(2);
    let n = 12;
    let h = random_spd(&mut rng, n);
    // Gradient dominates every row of H over the box, so the minimiser is the corner -sign(g).
    let push = 10.0 * h.abs().row_sum().max();
    let g = DVector::from_fn(n, |i, _| if i % 3 == 0 { push } else { -push });
    let p = Owned { h, g, lb: DVector::from_element(n, -1.0), ub: DVector::from_element(n, 1.0) };
    let (x, _, status) = boxqp_solve(&p);
    assert_eq!(status, QpStatus::Solved);
    for i in 0..n {
        assert_eq!(x[i], if i % 3 == 0 { -1.0 } else { 1.0 });
    }
}

#[test]
fn boxqp_keeps_fixed_variables_fixed() {
    let mut rng = Rng(3);
    let n = 10;
    let mut p = random_problem(&mut rng, n);
    for i in (0..n).step_by(2) {
        p.lb[i] = 0.3 * i as f64 - 1.0;
        p.ub[i] = p.lb[i];
    }
    let (x, f, _) = boxqp_solve(&p);
    for i in (0..n).step_by(2) {
        assert_eq!(x[i], p.lb[i]);
    }
    let (xc, fc) = clarabel_solve(&p);
    assert_close(&x, &xc, 1e-6, "fixed");
    assert!((f - fc).abs() <= 1e-9 * fc.abs().max(1.0));
}

#[test]
fn boxqp_handles_one_sided_and_infinite_bounds() {
    let mut rng = Rng(4);
    let n = 20;
    let mut p = random_problem(&mut rng, n);
    for i in 0..n {
        match i % 3 {
            0 => p.lb[i] = f64::NEG_INFINITY,
            1 => p.ub[i] = f64::INFINITY,
            _ => (p.lb[i], p.ub[i]) = (f64::NEG_INFINITY, f64::INFINITY),
        }
    }
    let (x, f, status) = boxqp_solve(&p);
    assert_eq!(status, QpStatus::Solved);
    assert!(kkt_violation(&p, &x) <= 1e-9);
    let (xc, fc) = clarabel_solve(&p);
    assert_close(&x, &xc, 1e-6, "infinite bounds");
    assert!((f - fc).abs() <= 1e-9 * fc.abs().max(1.0));
}

#[test]
fn boxqp_solves_singular_hessian_made_well_posed_by_bounds() {
    let mut rng = Rng(5);
    for (n, rank) in [(2, 1), (6, 3), (30, 10)] {
        let b = DMatrix::from_fn(n, rank, |_, _| rng.uniform(-1.0, 1.0));
        let h = &b * b.transpose();
        let g = DVector::from_fn(n, |_, _| rng.uniform(-1.0, 1.0));
        let lb = DVector::from_fn(n, |_, _| -rng.uniform(0.5, 1.0));
        let ub = DVector::from_fn(n, |_, _| rng.uniform(0.5, 1.0));
        let p = Owned { h, g, lb, ub };
        let (x, f, status) = boxqp_solve(&p);
        assert_eq!(status, QpStatus::Solved, "n = {n}");
        // The minimiser need not be unique: compare optimal values and check KKT.
        assert!(kkt_violation(&p, &x) <= 1e-8, "n = {n}: KKT {:e}", kkt_violation(&p, &x));
        let (_, fc) = clarabel_solve(&p);
        assert!((f - fc).abs() <= 1e-8 * fc.abs().max(1.0), "n = {n}: {f} vs {fc}");
    }
}

#[test]
fn boxqp_handles_ill_conditioned_and_rank_deficient_hessians() {
    // Eigenvalues spread over up to 12 decades, every other problem of half rank (then all
    // bounds finite so that the problem stays bounded below).
    let mut rng = Rng(10);
    for trial in 0..120 {
        let n = 2 + trial % 40;
        let rank = if trial % 2 == 0 { n } else { n / 2 };
        let decades = rng.uniform(0.0, 12.0);
        let q = DMatrix::from_fn(n, n, |_, _| rng.uniform(-1.0, 1.0)).qr().q();
        let eig = DVector::from_fn(n, |i, _| if i < rank { 10f64.powf(-decades * i as f64 / n as f64) } else { 0.0 });
        let h = &q * DMatrix::from_diagonal(&eig) * q.transpose();
        let g = DVector::from_fn(n, |_, _| rng.uniform(-1.0, 1.0));
        let open = |rng: &mut Rng, v: f64| {
            if rank == n && rng.uniform(0.0, 1.0) < 0.1 {
                v
            } else {
                v.signum() * rng.uniform(0.0, 2.0)
            }
        };
        let lb = DVector::from_fn(n, |_, _| open(&mut rng, f64::NEG_INFINITY));
        let ub = DVector::from_fn(n, |_, _| open(&mut rng, f64::INFINITY));
        let p = Owned { h, g, lb, ub };
        let (x, f, status) = boxqp_solve(&p);
        assert_eq!(status, QpStatus::Solved, "trial {trial}");
        let kkt = kkt_violation(&p, &x);
        assert!(kkt <= 1e-8, "trial {trial}: KKT {kkt:e}");
        let (_, fc) = clarabel_solve(&p);
        assert!(f <= fc + 1e-9 * fc.abs().max(1.0), "trial {trial}: {f} vs clarabel {fc}");
    }
}

#[test]
fn boxqp_zero_gradient_at_a_bound_is_optimal() {
    // x1 sits on its lower bound with zero gradient there (degenerate complementarity).
    let h = DMatrix::from_row_slice(3, 3, &[2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    let g = DVector::from_vec(vec![-1.0, 0.0, 1.0]);
    let p = Owned { h, g, lb: DVector::from_vec(vec![-1.0, 0.0, -1.0]), ub: DVector::from_element(3, 1.0) };
    for warm in [vec![0.0, 0.0, 0.0], vec![0.9, 0.7, 0.9], vec![-5.0, -5.0, 5.0]] {
        let mut x = DVector::from_vec(warm);
        let stats = BoxQp::new().solve(&p.problem(), &mut x).expect("solve");
        assert_eq!(stats.status, QpStatus::Solved);
        assert_close(&x, &DVector::from_vec(vec![0.5, 0.0, -1.0]), 1e-12, "degenerate");
    }
}

#[test]
fn boxqp_projects_warm_start_from_outside_the_box() {
    let mut rng = Rng(6);
    let p = random_problem(&mut rng, 25);
    let (cold, _, _) = boxqp_solve(&p);
    for warm in [1e3, -1e3, f64::NAN, f64::MAX, f64::NEG_INFINITY] {
        let mut x = DVector::from_element(25, warm);
        BoxQp::new().solve(&p.problem(), &mut x).expect("solve");
        assert_close(&x, &cold, 1e-9, "warm start");
    }
    // Wrong-length warm start: replaced, not a panic.
    let mut x = DVector::zeros(3);
    BoxQp::new().solve(&p.problem(), &mut x).expect("solve");
    assert_close(&x, &cold, 1e-9, "short warm start");
}

#[test]
fn boxqp_reuses_workspace_across_sizes() {
    let mut rng = Rng(7);
    let mut solver = BoxQp::with_capacity(8);
    for n in [8, 3, 30, 1, 30, 12] {
        let p = random_problem(&mut rng, n);
        let mut x = DVector::zeros(n);
        solver.solve(&p.problem(), &mut x).expect("solve");
        assert!(kkt_violation(&p, &x) <= 1e-9, "n = {n}");
    }
}

#[test]
fn boxqp_reports_indefinite_or_unbounded_problems() {
    let inf = DVector::from_element(2, f64::INFINITY);
    let cases = [
        // Indefinite.
        (DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]), DVector::from_vec(vec![0.0, 1.0])),
        // PSD, singular, objective linear and decreasing along the unbounded x1 axis.
        (DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 0.0]), DVector::from_vec(vec![1.0, 1.0])),
    ];
    for (h, g) in cases {
        let p = Owned { h, g, lb: -&inf, ub: inf.clone() };
        let mut x = DVector::zeros(2);
        let r = BoxQp::new().solve(&p.problem(), &mut x);
        assert!(matches!(r, Err(QpError::NotPositiveDefinite { pivot: 1, .. })), "{r:?}");
        let r = ClarabelQp::new(ClarabelQpSettings::default()).solve(&p.problem(), &mut x);
        assert!(r.is_err(), "clarabel: {r:?}");
    }
}

fn solvers() -> Vec<Box<dyn QpSolver>> {
    vec![Box::new(BoxQp::new()), Box::new(ClarabelQp::new(ClarabelQpSettings::default()))]
}

#[test]
fn solvers_reject_dimension_mismatch() {
    let h = DMatrix::identity(3, 3);
    let (g3, g2) = (DVector::zeros(3), DVector::zeros(2));
    let (b3, b2) = (DVector::from_element(3, 1.0), DVector::from_element(2, 1.0));
    let bad = [
        QpProblem { h: &h, g: &g2, lb: &(-&b3), ub: &b3 },
        QpProblem { h: &h, g: &g3, lb: &(-&b2), ub: &b3 },
        QpProblem { h: &h, g: &g3, lb: &(-&b3), ub: &b2 },
    ];
    let h_rect = DMatrix::zeros(3, 2);
    let rect = QpProblem { h: &h_rect, g: &g3, lb: &(-&b3), ub: &b3 };
    for mut s in solvers() {
        for p in bad.iter().chain([&rect]) {
            let mut x = DVector::zeros(3);
            assert!(matches!(s.solve(p, &mut x), Err(QpError::Dimensions { .. })), "{}", s.name());
        }
    }
    // Constraint matrix with the wrong number of columns.
    let cons = LinearConstraints { a: DMatrix::zeros(1, 2), lo: DVector::zeros(1), hi: DVector::zeros(1) };
    let mut s = ClarabelQp::with_constraints(cons, ClarabelQpSettings::default());
    let p = QpProblem { h: &h, g: &g3, lb: &(-&b3), ub: &b3 };
    assert!(s.solve(&p, &mut DVector::zeros(3)).is_err());
}

#[test]
fn solvers_reject_inconsistent_or_non_finite_data() {
    let h = DMatrix::identity(2, 2);
    let g = DVector::zeros(2);
    let lb = DVector::from_vec(vec![0.0, 2.0]);
    let ub = DVector::from_vec(vec![1.0, 1.0]);
    let nan_b = DVector::from_vec(vec![0.0, f64::NAN]);
    let one = DVector::from_element(2, 1.0);
    let mut h_nan = h.clone();
    h_nan[(0, 1)] = f64::NAN;
    let g_inf = DVector::from_vec(vec![f64::INFINITY, 0.0]);
    for mut s in solvers() {
        let mut x = DVector::zeros(2);
        let r = s.solve(&QpProblem { h: &h, g: &g, lb: &lb, ub: &ub }, &mut x);
        assert!(matches!(r, Err(QpError::InconsistentBounds { index: 1, .. })), "{r:?}");
        let r = s.solve(&QpProblem { h: &h, g: &g, lb: &nan_b, ub: &one }, &mut x);
        assert!(matches!(r, Err(QpError::InconsistentBounds { index: 1, .. })), "{r:?}");
        let r = s.solve(&QpProblem { h: &h_nan, g: &g, lb: &(-&one), ub: &one }, &mut x);
        assert!(matches!(r, Err(QpError::NonFinite { what: "h", .. })), "{r:?}");
        let r = s.solve(&QpProblem { h: &h, g: &g_inf, lb: &(-&one), ub: &one }, &mut x);
        assert!(matches!(r, Err(QpError::NonFinite { what: "g", .. })), "{r:?}");
    }
}

#[test]
fn clarabel_honours_general_linear_constraints() {
    // min ½‖x − c‖², c = (1, −1), s.t. |x0 − x1| ≤ 0.5  →  x = (0.25, −0.25).
    let h = DMatrix::identity(2, 2);
    let g = DVector::from_vec(vec![-1.0, 1.0]);
    let wide = DVector::from_element(2, 10.0);
    let p = QpProblem { h: &h, g: &g, lb: &(-&wide), ub: &wide };
    let band = LinearConstraints {
        a: DMatrix::from_row_slice(1, 2, &[1.0, -1.0]),
        lo: DVector::from_element(1, -0.5),
        hi: DVector::from_element(1, 0.5),
    };
    let mut s = ClarabelQp::with_constraints(band, ClarabelQpSettings::default());
    let mut x = DVector::zeros(2);
    let stats = s.solve(&p, &mut x).expect("solve");
    assert_eq!(stats.status, QpStatus::Solved);
    assert_close(&x, &DVector::from_vec(vec![0.25, -0.25]), 1e-7, "band");
    assert!((stats.objective - p.objective(&x)).abs() <= 1e-12);

    // Equality x0 + x1 = 1 and x0 ≤ 0.2 (one-sided, infinite lower side) → x = (0.2, 0.8).
    let cons = LinearConstraints {
        a: DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 0.0]),
        lo: DVector::from_vec(vec![1.0, f64::NEG_INFINITY]),
        hi: DVector::from_vec(vec![1.0, 0.2]),
    };
    s.set_constraints(Some(cons));
    let g0 = DVector::zeros(2);
    s.solve(&QpProblem { h: &h, g: &g0, lb: &(-&wide), ub: &wide }, &mut x).expect("solve");
    assert_close(&x, &DVector::from_vec(vec![0.2, 0.8]), 1e-7, "equality");
}

#[test]
fn clarabel_reused_across_updates_matches_fresh_solver() {
    let mut rng = Rng(8);
    let n = 15;
    let base = random_problem(&mut rng, n);
    let mut reused = ClarabelQp::new(oracle_settings());
    for k in 0..6 {
        // Same bound pattern with new data, except k = 3 which changes the pattern (rebuild).
        let mut p = random_problem(&mut rng, n);
        for i in 0..n {
            let (l, u) = (base.lb[i], base.ub[i]);
            let shift = rng.uniform(-0.2, 0.2);
            (p.lb[i], p.ub[i]) = if k == 3 { (f64::NEG_INFINITY, u + shift.abs()) } else { (l + shift, u + shift) };
        }
        let mut x = DVector::zeros(n);
        reused.solve(&p.problem(), &mut x).expect("reused");
        let (xf, _) = clarabel_solve(&p);
        assert_close(&x, &xf, 1e-6, &format!("update {k}"));
        let (xb, _, _) = boxqp_solve(&p);
        assert_close(&x, &xb, 1e-6, &format!("update {k} vs boxqp"));
    }
}

#[test]
fn boxqp_reports_iteration_cap_with_a_feasible_point() {
    let mut rng = Rng(9);
    let p = random_problem(&mut rng, 30);
    let settings = BoxQpSettings { max_iterations: 1, ..Default::default() };
    let mut x = DVector::zeros(30);
    let stats = BoxQp::with_settings(settings).solve(&p.problem(), &mut x).expect("solve");
    assert_eq!(stats.status, QpStatus::MaxIterations);
    assert_eq!(stats.iterations, 1);
    assert!((0..30).all(|i| x[i] >= p.lb[i] && x[i] <= p.ub[i]));
    assert!((stats.objective - p.problem().objective(&x)).abs() <= 1e-9 * stats.objective.abs().max(1.0));
}

#[test]
fn settings_round_trip_through_serde_with_documented_defaults() {
    let b: BoxQpSettings = serde_json::from_str("{}").expect("defaults");
    assert_eq!(b.max_iterations, BoxQpSettings::default().max_iterations);
    let text = serde_json::to_string(&BoxQpSettings { armijo: 0.2, ..b }).expect("serialise");
    let back: BoxQpSettings = serde_json::from_str(&text).expect("parse");
    assert_eq!(back.armijo, 0.2);
    let c: ClarabelQpSettings = serde_json::from_str(r#"{"tol_feas": 1e-9}"#).expect("partial");
    assert_eq!(c.tol_feas, 1e-9);
    assert_eq!(c.max_iterations, ClarabelQpSettings::default().max_iterations);
    assert!(!c.verbose);
}
