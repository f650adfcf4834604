//! Per-frame solve time on the shipped full-body model (one thread): a warm-started sequence of
//! synthetic frames (2 mm noise, 100 Hz), as the trial driver solves them.
//!
//! `cargo bench --bench solve` — results are recorded in BENCHMARKS.md.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use smocap::kinematics::assembly::FrameProblem;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::model::proxy::ProxyKind;
use smocap::pipeline::{calibrate_subject, Context};
use smocap::solve::{init::cold_start, make_qp, FrameSolver, QpBackend};
use std::hint::black_box;

fn solve_sequence(c: &mut Criterion) {
    let ctx = Context::shipped().expect("shipped model");
    let frames = 200;
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames, seed: 3, ..SynthOptions::default() });
    let cal = calibrate_subject(&ctx, &[("bench", &s.trial)]).expect("calibration");
    let map = smocap::pipeline::input::trial::match_markers(&ctx, "synthetic", &s.trial).unwrap().columns;
    let obs = smocap::pipeline::input::trial::observations(&s.trial, &map);
    let stride = 3 * ctx.model.markers.len();
    let eval = ctx.evaluator();
    let ny = ctx.model.ny();
    let y_cal = ctx.proxy.state(&cal.proxies);
    let mut tw = vec![0.0; ny];
    for t in &ctx.proxy.terms {
        tw[t.y_index] =
            if ctx.proxy.proxies[t.proxy].kind == ProxyKind::Scale { ctx.settings.scale_tracking_weight } else { 0.0 };
    }
    let mut group = c.benchmark_group("solve_frame");
    group.throughput(Throughput::Elements(frames as u64));
    group.sample_size(20);
    for qp in [QpBackend::Boxqp, QpBackend::Clarabel] {
        let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(qp));
        let first = FrameProblem {
            observed: &obs[..stride],
            marker_weights: &ctx.marker_weights,
            tracking_ref: &y_cal,
            tracking_weights: &tw,
        };
        let mut p0 = cal.proxies.clone();
        cold_start(&mut solver, &first, &mut p0);
        solver.solve(&first, &mut p0);
        group.bench_function(format!("fullbody_{:?}", qp).to_lowercase(), |b| {
            b.iter(|| {
                let mut p = p0.clone();
                let mut its = 0;
                for f in 0..frames {
                    let frame = FrameProblem { observed: &obs[f * stride..(f + 1) * stride], ..first };
                    its += solver.solve(&frame, &mut p).iterations;
                }
                black_box(its)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, solve_sequence);
criterion_main!(benches);
