//! The lane scheduler against the plain per-segment loop it replaced (CPU backend, whole trial),
//! batched evaluation throughput per backend and batch size (wgpu where an adapter exists), and
//! the wgpu backend's host path alone (packing and hand-out on plain memory, no device needed:
//! CPU time summed over threads, per call of 2048 frames).
//!
//! `cargo bench --bench lanes` — results are recorded in BENCHMARKS.md.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use rayon::prelude::*;
use smocap::kinematics::assembly::FrameProblem;
use smocap::kinematics::backend::{BatchBackend, CpuBackend, FrameModel, GnSink, GnView};
use smocap::kinematics::gpu::{host_path_alone, Precision, WgpuBackend, DEFAULT_CAP};
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::model::proxy::ProxyKind;
use smocap::pipeline::{calibrate_subject, solve_trial_with, Context};
use smocap::solve::{init::cold_start, make_qp, Calibration, FrameSolver, FrameStatus};
use std::hint::black_box;

/// The pre-scheduler driver: each segment on its own thread, frame by frame.
fn plain_segments(ctx: &Context, obs: &[f64], cal: &Calibration, threads: usize) -> usize {
    let eval = ctx.evaluator();
    let (ny, nq, stride) = (ctx.model.ny(), ctx.model.nq(), 3 * ctx.model.markers.len());
    let n = obs.len() / stride;
    let y_cal = ctx.proxy.state(&cal.proxies);
    let mut tw = vec![0.0; ny];
    for t in &ctx.proxy.terms {
        let scale = ctx.proxy.proxies[t.proxy].kind == ProxyKind::Scale;
        tw[t.y_index] = if scale { ctx.settings.scale_tracking_weight } else { ctx.settings.pose_prior_weight };
    }
    let mut neutral = ctx.proxy.default_proxies();
    for (k, px) in ctx.proxy.proxies.iter().enumerate() {
        if px.kind == ProxyKind::Scale {
            neutral[k] = cal.proxies[k];
        }
    }
    let segments = threads.min(n.div_ceil(100)).max(1);
    (0..segments)
        .into_par_iter()
        .map(|i| {
            let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(ctx.settings.qp));
            let mut reference = y_cal.clone();
            let mut prev: Option<Vec<f64>> = None;
            let mut its = 0;
            for o in obs[i * n / segments * stride..(i + 1) * n / segments * stride].chunks(stride) {
                let mut p = prev.clone().unwrap_or_else(|| neutral.clone());
                solver.clamp(&mut p);
                let y = ctx.proxy.state(&p);
                reference[..nq].copy_from_slice(&y[..nq]);
                let frame = FrameProblem {
                    observed: o,
                    marker_weights: &ctx.marker_weights,
                    tracking_ref: &reference,
                    tracking_weights: &tw,
                };
                if prev.is_none() {
                    cold_start(&mut solver, &frame, &mut p);
                }
                let st = solver.solve(&frame, &mut p);
                its += st.iterations as usize;
                if st.status != FrameStatus::TooFewMarkers {
                    prev = Some(p);
                }
            }
            its
        })
        .sum()
}

fn lanes(c: &mut Criterion) {
    let ctx = Context::shipped().expect("shipped model");
    let frames = 400;
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames, seed: 8, ..SynthOptions::default() });
    let cal = calibrate_subject(&ctx, &[("bench", &s.trial)]).expect("calibration");
    let map = smocap::pipeline::input::trial::match_markers(&ctx, "synthetic", &s.trial).unwrap().columns;
    let obs = smocap::pipeline::input::trial::observations(&s.trial, &map);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");

    let mut g = c.benchmark_group("solve_trial_cpu");
    g.throughput(Throughput::Elements(frames as u64));
    g.sample_size(10);
    g.bench_function(format!("plain_segment_loop_{threads}_threads"), |b| {
        b.iter(|| pool.install(|| black_box(plain_segments(&ctx, &obs, &cal, threads))))
    });
    g.bench_function(format!("lane_scheduler_{threads}_lanes"), |b| {
        b.iter(|| black_box(solve_trial_with(&ctx, "b", &s.trial, &cal, threads, threads, None).expect("solve")))
    });
    g.finish();

    // Batched evaluation throughput.
    let eval = ctx.evaluator();
    let (np, nm, stride) = (ctx.proxy.np(), ctx.model.markers.len(), 3 * ctx.model.markers.len());
    let zeros = vec![0.0; ctx.model.ny()];
    let mut g = c.benchmark_group("batch_linearize");
    g.sample_size(10);
    let mut cpu = CpuBackend::new(eval.clone());
    let mut gpu = WgpuBackend::new(&eval, DEFAULT_CAP).ok();
    if gpu.is_none() {
        eprintln!("note: no wgpu adapter; wgpu rows skipped");
    }
    for n in [256usize, 1024, 4096] {
        let batch: Vec<FrameProblem<'_>> = (0..n)
            .map(|i| FrameProblem {
                observed: &obs[(i % frames) * stride..(i % frames + 1) * stride],
                marker_weights: &ctx.marker_weights,
                tracking_ref: &zeros,
                tracking_weights: &zeros,
            })
            .collect();
        let proxies: Vec<f64> = (0..n).flat_map(|i| s.truth.proxies[i % frames].iter().copied()).collect();
        let mut out = vec![FrameModel::new(np, nm); n];
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::new("cpu", n), &n, |b, _| {
            b.iter(|| pool.install(|| cpu.linearize(&batch, &proxies, &mut out).expect("cpu")))
        });
        if let Some(gpu) = gpu.as_mut() {
            g.bench_with_input(BenchmarkId::new("wgpu", n), &n, |b, _| {
                b.iter(|| gpu.linearize(&batch, &proxies, &mut out).expect("wgpu"))
            });
        }
    }
    g.finish();

    // The host path alone: CPU time of packing and hand-out (criterion's time is CPU time here).
    let mut g = c.benchmark_group("host_path");
    g.sample_size(20);
    let n = 2048;
    let tw = vec![1e-6; ctx.model.ny()];
    let batch: Vec<FrameProblem<'_>> = (0..n)
        .map(|i| FrameProblem {
            observed: &obs[(i % frames) * stride..(i % frames + 1) * stride],
            marker_weights: &ctx.marker_weights,
            tracking_ref: &zeros,
            tracking_weights: &tw,
        })
        .collect();
    let proxies: Vec<f64> = (0..n).flat_map(|i| s.truth.proxies[i % frames].iter().copied()).collect();
    let mut sinks: Vec<CopySink> = (0..n).map(|_| CopySink { energy: 0.0, g: vec![0.0; np] }).collect();
    g.throughput(Throughput::Elements(n as u64));
    for precision in [Precision::F32, Precision::F64] {
        g.bench_function(BenchmarkId::new("pack_and_hand_out", precision.name()), |b| {
            b.iter_custom(|iters| {
                let mut total = 0.0;
                for _ in 0..iters {
                    let mut dyns: Vec<&mut dyn GnSink> = sinks.iter_mut().map(|s| s as &mut dyn GnSink).collect();
                    let (p, h) = pool
                        .install(|| host_path_alone(&eval, precision, &batch, &proxies, &mut dyns))
                        .expect("host path");
                    total += p + h;
                }
                std::time::Duration::from_secs_f64(total)
            })
        });
    }
    g.finish();
}

/// A solver-like sink: copies E and g (H stays where the backend left it, as the QP reads it).
struct CopySink {
    energy: f64,
    g: Vec<f64>,
}

impl GnSink for CopySink {
    fn take(&mut self, view: &GnView<'_>) {
        self.energy = view.energy;
        view.g.copy_to(&mut self.g);
    }
}

criterion_group!(benches, lanes);
criterion_main!(benches);
