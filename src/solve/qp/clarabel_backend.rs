//! [`QpSolver`] backed by the interior-point solver clarabel.
//!
//! Conic form: `min ½ xᵀ P x + qᵀ x` s.t. `A x + s = b`, `s ∈ K`, with `P` = upper triangle of
//! `H` (stored densely, structural zeros kept), `q = g`, and the rows of `A`, in this order:
//! - `ZeroConeT`: `x_i = lb_i` for fixed variables (`lb_i == ub_i`), `a_k x = lo_k` for
//!   equality constraints (`lo_k == hi_k`);
//! - `NonnegativeConeT`: `x_i ≤ ub_i`, `−x_i ≤ −lb_i`, `a_k x ≤ hi_k`, `−a_k x ≤ −lo_k` for
//!   each finite side (infinite sides are dropped).
//!
//! The solver object is kept and its data overwritten with `update_P`/`update_q`/`update_b`
//! while the size and the pattern of finite bounds are unchanged; otherwise it is rebuilt.
//! Presolve is disabled so that updates stay legal. The equilibration computed at build time is
//! reused for updated data (clarabel's documented behaviour).
//!
//! Interior-point methods cannot use a warm start: the `x` passed in is ignored (only
//! overwritten with the solution).

use super::{LinearConstraints, QpError, QpProblem, QpSolver, QpStats, QpStatus};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DataUpdateError, DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus, SupportedConeT,
    ZeroConeT,
};
use nalgebra::DVector;
use serde::{Deserialize, Serialize};

const BACKEND: &str = "clarabel";

/// Clarabel knobs exposed here; everything else keeps clarabel's defaults (with `verbose`
/// and `presolve_enable` off).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default)]
pub struct ClarabelQpSettings {
    /// Interior-point iteration cap. Default 200.
    pub max_iterations: u32,
    /// Absolute duality-gap tolerance. Default 1e-10 (clarabel: 1e-8).
    pub tol_gap_abs: f64,
    /// Relative duality-gap tolerance. Default 1e-10 (clarabel: 1e-8).
    pub tol_gap_rel: f64,
    /// Primal/dual feasibility tolerance. Default 1e-10 (clarabel: 1e-8).
    pub tol_feas: f64,
    /// κ/τ tolerance. Default 1e-8 (clarabel: 1e-6).
    pub tol_ktratio: f64,
    /// Print clarabel's iteration log. Default false.
    pub verbose: bool,
}

impl Default for ClarabelQpSettings {
    fn default() -> Self {
        Self {
            max_iterations: 200,
            tol_gap_abs: 1e-10,
            tol_gap_rel: 1e-10,
            tol_feas: 1e-10,
            tol_ktratio: 1e-8,
            verbose: false,
        }
    }
}

impl ClarabelQpSettings {
    fn to_clarabel(&self) -> DefaultSettings<f64> {
        DefaultSettings {
            max_iter: self.max_iterations,
            tol_gap_abs: self.tol_gap_abs,
            tol_gap_rel: self.tol_gap_rel,
            tol_feas: self.tol_feas,
            tol_ktratio: self.tol_ktratio,
            verbose: self.verbose,
            presolve_enable: false,
            input_sparse_dropzeros: false,
            ..DefaultSettings::default()
        }
    }
}

/// Which sides of `lo ≤ v ≤ hi` are present.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sides {
    None,
    Lower,
    Upper,
    Both,
    Equal,
}

impl Sides {
    fn of(lo: f64, hi: f64) -> Self {
        match (lo.is_finite(), hi.is_finite()) {
            _ if lo == hi => Sides::Equal,
            (true, true) => Sides::Both,
            (true, false) => Sides::Lower,
            (false, true) => Sides::Upper,
            (false, false) => Sides::None,
        }
    }
}

/// One row of `A`: `sign · x_i` (`Var`) or `sign · a_k x` (`Con`); `b = hi` for `sign > 0`,
/// `−lo` otherwise (equal for equality rows).
#[derive(Clone, Copy, Debug)]
enum Row {
    Var(usize, f64),
    Con(usize, f64),
}

/// Clarabel solver plus the structure it was built for.
struct Built {
    solver: DefaultSolver<f64>,
    var_sides: Vec<Sides>,
    rows: Vec<Row>,
}

/// Interior-point QP backend (see the module docs). Supports general linear constraints.
pub struct ClarabelQp {
    /// Solver knobs; a change takes effect at the next rebuild.
    pub settings: ClarabelQpSettings,
    constraints: Option<LinearConstraints>,
    built: Option<Built>,
    sides: Vec<Sides>,
    p_vals: Vec<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
}

impl ClarabelQp {
    /// Box constraints only.
    pub fn new(settings: ClarabelQpSettings) -> Self {
        Self {
            settings,
            constraints: None,
            built: None,
            sides: Vec::new(),
            p_vals: Vec::new(),
            q: Vec::new(),
            b: Vec::new(),
        }
    }

    /// Box constraints plus `constraints` (checked against the problem at each solve).
    pub fn with_constraints(constraints: LinearConstraints, settings: ClarabelQpSettings) -> Self {
        Self { constraints: Some(constraints), ..Self::new(settings) }
    }

    /// Replaces the general constraints (forces a rebuild at the next solve).
    pub fn set_constraints(&mut self, constraints: Option<LinearConstraints>) {
        self.constraints = constraints;
        self.built = None;
    }

    fn check_constraints(&self, n: usize) -> Result<(), QpError> {
        let Some(c) = &self.constraints else {
            return Ok(());
        };
        let m = c.a.nrows();
        if c.a.ncols() != n || c.lo.len() != m || c.hi.len() != m {
            let status = format!(
                "constraints have A {}x{}, lo {}, hi {} for {n} variables",
                m,
                c.a.ncols(),
                c.lo.len(),
                c.hi.len()
            );
            return Err(QpError::Backend { backend: BACKEND, status });
        }
        if let Some(index) = c.a.iter().position(|v| !v.is_finite()) {
            return Err(QpError::NonFinite { what: "a", index });
        }
        for (k, (&lo, &hi)) in c.lo.iter().zip(c.hi.iter()).enumerate() {
            if lo.is_nan() || hi.is_nan() || lo > hi || lo == f64::INFINITY || hi == f64::NEG_INFINITY {
                return Err(QpError::Infeasible(format!("constraint {k} has bounds [{lo}, {hi}]")));
            }
        }
        Ok(())
    }

    /// Row list: equality rows first (count returned), then inequality rows.
    fn rows(&self) -> (Vec<Row>, usize) {
        let con_sides: Vec<Sides> = match &self.constraints {
            Some(c) => c.lo.iter().zip(c.hi.iter()).map(|(&l, &h)| Sides::of(l, h)).collect(),
            None => Vec::new(),
        };
        let mut rows = Vec::new();
        rows.extend(self.sides.iter().enumerate().filter(|(_, s)| **s == Sides::Equal).map(|(i, _)| Row::Var(i, 1.0)));
        rows.extend(con_sides.iter().enumerate().filter(|(_, s)| **s == Sides::Equal).map(|(k, _)| Row::Con(k, 1.0)));
        let n_eq = rows.len();
        let push_ineq = |rows: &mut Vec<Row>, s: Sides, make: &dyn Fn(f64) -> Row| {
            if matches!(s, Sides::Upper | Sides::Both) {
                rows.push(make(1.0));
            }
            if matches!(s, Sides::Lower | Sides::Both) {
                rows.push(make(-1.0));
            }
        };
        for (i, &s) in self.sides.iter().enumerate() {
            push_ineq(&mut rows, s, &|sign| Row::Var(i, sign));
        }
        for (k, &s) in con_sides.iter().enumerate() {
            push_ineq(&mut rows, s, &|sign| Row::Con(k, sign));
        }
        (rows, n_eq)
    }

    fn build(&mut self, problem: &QpProblem<'_>) -> Result<(), QpError> {
        let n = problem.g.len();
        let (rows, n_eq) = self.rows();
        fill_data(problem, self.constraints.as_ref(), &rows, &mut self.p_vals, &mut self.q, &mut self.b);
        let colptr_p: Vec<usize> = (0..=n).map(|j| j * (j + 1) / 2).collect();
        let rowval_p: Vec<usize> = (0..n).flat_map(|j| 0..=j).collect();
        let p = CscMatrix::new(n, n, colptr_p, rowval_p, self.p_vals.clone());

        let (mut colptr, mut rowval, mut nzval) = (vec![0], Vec::new(), Vec::new());
        for j in 0..n {
            for (r, row) in rows.iter().enumerate() {
                let v = match *row {
                    Row::Var(i, s) if i == j => s,
                    Row::Var(..) => continue,
                    Row::Con(k, s) => match &self.constraints {
                        Some(c) => s * c.a[(k, j)],
                        None => continue,
                    },
                };
                rowval.push(r);
                nzval.push(v);
            }
            colptr.push(rowval.len());
        }
        let a = CscMatrix::new(rows.len(), n, colptr, rowval, nzval);
        let mut cones: Vec<SupportedConeT<f64>> = Vec::with_capacity(2);
        if n_eq > 0 {
            cones.push(ZeroConeT(n_eq));
        }
        if rows.len() > n_eq {
            cones.push(NonnegativeConeT(rows.len() - n_eq));
        }
        let solver = DefaultSolver::new(&p, &self.q, &a, &self.b, &cones, self.settings.to_clarabel())
            .map_err(|e| QpError::Backend { backend: BACKEND, status: e.to_string() })?;
        self.built = Some(Built { solver, var_sides: self.sides.clone(), rows });
        Ok(())
    }
}

impl QpSolver for ClarabelQp {
    fn set_linear_constraints(&mut self, constraints: Option<LinearConstraints>) -> Result<(), QpError> {
        self.set_constraints(constraints);
        Ok(())
    }

    fn name(&self) -> &'static str {
        BACKEND
    }

    fn solve(&mut self, problem: &QpProblem<'_>, x: &mut DVector<f64>) -> Result<QpStats, QpError> {
        let n = problem.validate()?;
        self.check_constraints(n)?;
        if x.len() != n {
            *x = DVector::zeros(n);
        }
        self.sides.clear();
        self.sides.extend(problem.lb.iter().zip(problem.ub.iter()).map(|(&l, &u)| Sides::of(l, u)));

        match self.built.as_mut() {
            Some(b) if b.var_sides == self.sides => {
                fill_data(problem, self.constraints.as_ref(), &b.rows, &mut self.p_vals, &mut self.q, &mut self.b);
                let err = |e: DataUpdateError| QpError::Backend { backend: BACKEND, status: e.to_string() };
                b.solver.update_P(&self.p_vals).map_err(err)?;
                b.solver.update_q(&self.q).map_err(err)?;
                b.solver.update_b(&self.b).map_err(err)?;
            }
            _ => self.build(problem)?,
        }
        let Some(built) = self.built.as_mut() else {
            return Err(QpError::Backend { backend: BACKEND, status: "solver not built".into() });
        };
        built.solver.solve();
        let sol = &built.solver.solution;
        let status = match sol.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => QpStatus::Solved,
            SolverStatus::MaxIterations | SolverStatus::MaxTime => QpStatus::MaxIterations,
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                return Err(QpError::Infeasible(format!("clarabel status {:?}", sol.status)));
            }
            other => {
                return Err(QpError::Backend { backend: BACKEND, status: format!("{other:?}") });
            }
        };
        if sol.x.len() != n || sol.x.iter().any(|v| !v.is_finite()) {
            return Err(QpError::Backend { backend: BACKEND, status: "non-finite solution".into() });
        }
        for (i, xi) in x.iter_mut().enumerate() {
            // Interior-point iterates may sit a hair outside the box; project.
            *xi = sol.x[i].max(problem.lb[i]).min(problem.ub[i]);
        }
        Ok(QpStats { status, iterations: sol.iterations, objective: problem.objective(x) })
    }
}

/// Fills `p_vals` (upper triangle of `H`, column by column), `q = g` and `b` (one per row).
fn fill_data(
    problem: &QpProblem<'_>,
    constraints: Option<&LinearConstraints>,
    rows: &[Row],
    p_vals: &mut Vec<f64>,
    q: &mut Vec<f64>,
    b: &mut Vec<f64>,
) {
    let n = problem.g.len();
    let h = problem.h.as_slice();
    p_vals.clear();
    for j in 0..n {
        p_vals.extend_from_slice(&h[j * n..=j * n + j]);
    }
    q.clear();
    q.extend_from_slice(problem.g.as_slice());
    b.clear();
    b.extend(rows.iter().map(|row| {
        let (lo, hi, sign) = match (*row, constraints) {
            (Row::Var(i, s), _) => (problem.lb[i], problem.ub[i], s),
            (Row::Con(k, s), Some(c)) => (c.lo[k], c.hi[k], s),
            (Row::Con(_, s), None) => (0.0, 0.0, s),
        };
        if sign > 0.0 {
            hi
        } else {
            -lo
        }
    }));
}
