//! BoxQp vs ClarabelQp on representative trust-region-sized problems (n = 40, 60) with about
//! 20% of the bounds active at the solution.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{DMatrix, DVector};
use smocap::solve::qp::{BoxQp, ClarabelQp, ClarabelQpSettings, QpProblem, QpSolver};

/// SplitMix64 (seeded, dependency-free).
struct Rng(u64);

impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        lo + (hi - lo) * ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// SPD `H = AᵀA/n + 0.05 I`, random `g`, and a box around the unconstrained minimiser that
/// cuts it off in every fifth variable (trust-region-like bounds elsewhere).
fn problem(n: usize, seed: u64) -> (DMatrix<f64>, DVector<f64>, DVector<f64>, DVector<f64>) {
    let mut rng = Rng(seed);
    let a = DMatrix::from_fn(n, n, |_, _| rng.uniform(-1.0, 1.0));
    let h = a.transpose() * &a / n as f64 + DMatrix::identity(n, n) * 0.05;
    let g = DVector::from_fn(n, |_, _| rng.uniform(-1.0, 1.0));
    let x_unc = h.clone().cholesky().map(|c| c.solve(&(-&g))).unwrap_or_else(|| DVector::zeros(n));
    let radius = 2.0 * x_unc.amax();
    let mut lb = DVector::from_element(n, -radius);
    let mut ub = DVector::from_element(n, radius);
    for i in (0..n).step_by(5) {
        if x_unc[i] > 0.0 {
            ub[i] = 0.5 * x_unc[i];
        } else {
            lb[i] = 0.5 * x_unc[i];
        }
    }
    (h, g, lb, ub)
}

fn bench_qp(c: &mut Criterion) {
    for n in [40, 60] {
        let (h, g, lb, ub) = problem(n, 0xbe7c + n as u64);
        let p = QpProblem { h: &h, g: &g, lb: &lb, ub: &ub };
        let mut boxqp = BoxQp::with_capacity(n);
        let mut ipm = ClarabelQp::new(ClarabelQpSettings::default());

        // Report the problem's character once.
        let mut x = DVector::zeros(n);
        let stats = boxqp.solve(&p, &mut x).expect("boxqp");
        let active = (0..n).filter(|&i| x[i] <= lb[i] || x[i] >= ub[i]).count();
        let mut xc = DVector::zeros(n);
        let cstats = ipm.solve(&p, &mut xc).expect("clarabel");
        eprintln!(
            "n = {n}: {active} active bounds; boxqp {} iterations, clarabel {} iterations, |Δx|∞ = {:.1e}",
            stats.iterations,
            cstats.iterations,
            (&x - &xc).amax()
        );
        // Warm start as in a trust-region loop: the solution of a slightly different problem.
        let g_prev = DVector::from_fn(n, |i, _| g[i] * (1.0 + 0.05 * ((i * 37 % 11) as f64 / 5.0 - 1.0)));
        let mut previous = DVector::zeros(n);
        let p_prev = QpProblem { h: &h, g: &g_prev, lb: &lb, ub: &ub };
        boxqp.solve(&p_prev, &mut previous).expect("boxqp");
        let mut xw = previous.clone();
        let wstats = boxqp.solve(&p, &mut xw).expect("boxqp");
        eprintln!("n = {n}: warm start from a perturbed problem: {} iterations", wstats.iterations);

        let mut group = c.benchmark_group(format!("qp_n{n}"));
        group.measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
        group.bench_function("boxqp_cold", |b| {
            b.iter(|| {
                x.fill(0.0);
                black_box(boxqp.solve(black_box(&p), &mut x).ok());
            })
        });
        group.bench_function("boxqp_warm", |b| {
            b.iter(|| {
                x.copy_from(&previous);
                black_box(boxqp.solve(black_box(&p), &mut x).ok());
            })
        });
        group.bench_function("clarabel_reused", |b| b.iter(|| black_box(ipm.solve(black_box(&p), &mut xc).ok())));
        group.finish();
    }
}

criterion_group!(benches, bench_qp);
criterion_main!(benches);
