//! Forward kinematics, Jacobian and Gauss–Newton assembly throughput on the shipped model:
//! per frame on one thread, and batched over frames with rayon.
//!
//! `cargo bench --bench kinematics` — results are recorded in BENCHMARKS.md.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayon::prelude::*;
use smocap::kinematics::assembly::{EvalWorkspace, FrameProblem};
use smocap::kinematics::cpu;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::pipeline::Context;
use std::hint::black_box;

fn kinematics(c: &mut Criterion) {
    let ctx = Context::shipped().expect("shipped model");
    let eval = ctx.evaluator();
    let frames = 1024;
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames, seed: 5, ..SynthOptions::default() });
    let ps = &s.truth.proxies;
    let obs = &s.trial.positions;
    let stride = 3 * ctx.model.markers.len();
    let zeros = vec![0.0; ctx.model.ny()];
    let mut ws = EvalWorkspace::new(&ctx.model, &ctx.proxy);
    let mut g = c.benchmark_group("kinematics_one_thread");
    g.throughput(Throughput::Elements(1));
    let y = ctx.proxy.state(&ps[10]);
    g.bench_function("forward", |b| b.iter(|| cpu::forward(&ctx.model, black_box(&y), &mut ws.kin)));
    g.bench_function("forward_jacobian", |b| {
        b.iter(|| {
            cpu::forward(&ctx.model, black_box(&y), &mut ws.kin);
            cpu::jacobian(&ctx.model, &eval.layout, &mut ws.kin);
        })
    });
    let frame = FrameProblem {
        observed: &obs[10 * stride..11 * stride],
        marker_weights: &ctx.marker_weights,
        tracking_ref: &zeros,
        tracking_weights: &zeros,
    };
    g.bench_function("linearize_h_g", |b| b.iter(|| eval.linearize(black_box(&ps[10]), &frame, &mut ws)));
    g.finish();

    let mut g = c.benchmark_group("kinematics_batch_rayon");
    g.throughput(Throughput::Elements(frames as u64));
    g.sample_size(20);
    g.bench_function("linearize_1024_frames", |b| {
        b.iter(|| {
            (0..frames).into_par_iter().for_each_init(
                || EvalWorkspace::new(&ctx.model, &ctx.proxy),
                |ws, f| {
                    let frame = FrameProblem { observed: &obs[f * stride..(f + 1) * stride], ..frame };
                    eval.linearize(&ps[f], &frame, ws);
                    black_box(ws.gn.energy);
                },
            )
        })
    });
    g.finish();
}

criterion_group!(benches, kinematics);
criterion_main!(benches);
