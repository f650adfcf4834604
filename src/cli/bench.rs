//! `smocap bench-batch`: batched evaluation throughput (frame-evaluations/s) of the shipped model
//! per backend and batch size, for BENCHMARKS.md. Frames are synthetic (2 mm noise, 100 Hz),
//! evaluated at the true proxies; the first repetition is a warm-up and not timed.

use crate::kinematics::assembly::FrameProblem;
use crate::kinematics::backend::{BatchBackend, CpuBackend, EnergyEval, FrameModel, GnSink, GnView};
use crate::kinematics::gpu::PhaseTimes;
use crate::kinematics::synth::{synthesize, SynthOptions};
use crate::pipeline::running::device::{choose_with, BackendChoice, Chosen};
use crate::pipeline::Context;
use clap::Args;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Backend to measure (`auto` as in `solve`).
    #[arg(long, value_enum, default_value_t = BackendChoice::Cpu)]
    pub backend: BackendChoice,
    /// Batch sizes (frames per call), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1000,10000,100000")]
    pub sizes: Vec<usize>,
    /// Timed repetitions per size (the median is reported).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Distinct synthetic frames, tiled up to the batch size.
    #[arg(long, default_value_t = 2000)]
    pub distinct: usize,
    /// wgpu only: frames per dispatch (capped by the adapter's binding limits).
    #[arg(long, default_value_t = crate::kinematics::gpu::DEFAULT_CAP)]
    pub cap: usize,
    /// wgpu only: how the shaders spread a frame's work over the GPU.
    #[arg(long, value_enum, default_value_t = crate::kinematics::gpu::Kernel::default())]
    pub kernel: crate::kinematics::gpu::Kernel,
    /// wgpu only: chunks each call is cut into at least, so that the device evaluates one while
    /// the host hands out another (chunks of at least 256 frames).
    #[arg(long, default_value_t = crate::kinematics::gpu::DEFAULT_PIECES)]
    pub pieces: usize,
}

pub fn run(a: BenchArgs) -> anyhow::Result<u8> {
    let ctx = Context::shipped()?;
    let eval = ctx.evaluator();
    let mut chosen = choose_with(a.backend, &eval, a.cap, a.kernel)?;
    if let Chosen::Wgpu(b) = &mut chosen {
        b.set_pieces(a.pieces);
    }
    if let Some(note) = chosen.note() {
        eprintln!("note: {note}");
    }
    let mut cpu = CpuBackend::new(eval.clone());
    let device = match &chosen {
        Chosen::Wgpu(b) => {
            format!(
                "{}, at most {} frames per dispatch, {} pieces per call",
                chosen.device(),
                b.chunk_capacity(),
                b.pieces()
            )
        }
        _ => chosen.device(),
    };
    let distinct = a.distinct.max(1);
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: distinct, seed: 5, ..SynthOptions::default() });
    let matched = crate::pipeline::input::trial::match_markers(&ctx, "synthetic", &s.trial)?;
    let obs = crate::pipeline::input::trial::observations(&s.trial, &matched.columns);
    let (np, nm, ny) = (ctx.proxy.np(), ctx.model.markers.len(), ctx.model.ny());
    let stride = 3 * nm;
    let y_ref = ctx.proxy.state(&ctx.proxy.default_proxies());
    let tw = vec![1e-6; ny];
    println!(
        "# bench-batch: shipped model ({np} proxies, {nm} markers), backend {} on {device}, median of {} runs",
        chosen.name(),
        a.repeats
    );
    let cost = crate::kinematics::gpu::pack::pack(&ctx.model, &ctx.proxy, &eval.layout).cost;
    println!(
        "# cost per frame-evaluation (docs/KINEMATICS.md): in {} words, out {} words, cooperative scratch {} words; \
         {} bodies in {} levels, {} chain items, {} Jacobian row words, {} H and {} g products; ≈ {:.0} kflop",
        cost.in_words,
        cost.out_words,
        cost.scratch_words,
        cost.bodies,
        cost.levels,
        cost.chain_items,
        cost.row_words,
        cost.h_products,
        cost.g_products,
        cost.flops() as f64 / 1e3
    );
    println!(
        "# backend\tbatch\tlinearize_ms\tlinearize_frames_per_s\thandoff_ms\thandoff_frames_per_s\tenergy_ms\tenergy_frames_per_s"
    );
    println!(
        "#   linearize: (H, g, E, x) copied into owned per-frame results (both triangles of H, f64; \
         batches up to {FULL_COPY_MAX} frames); handoff: each frame's model handed to a solver-like sink \
         that copies E, g and the statistics, H left in place for the QP to read"
    );
    for &n in &a.sizes {
        let n = n.max(1);
        let frames: Vec<FrameProblem<'_>> = (0..n)
            .map(|i| {
                let f = i % distinct;
                FrameProblem {
                    observed: &obs[f * stride..(f + 1) * stride],
                    marker_weights: &ctx.marker_weights,
                    tracking_ref: &y_ref,
                    tracking_weights: &tw,
                }
            })
            .collect();
        let proxies: Vec<f64> = (0..n).flat_map(|i| s.truth.proxies[i % distinct].iter().copied()).collect();
        let mut out = if n <= FULL_COPY_MAX { vec![FrameModel::new(np, nm); n] } else { Vec::new() };
        let mut handoff: Vec<Handoff> = (0..n).map(|_| Handoff::new(np)).collect();
        let mut energies = vec![EnergyEval::default(); n];
        let repeats = a.repeats.max(1);
        // The same host code on plain memory, before the device runs (its threads share these
        // cores on lavapipe and linger after a call): median of the repetitions.
        let mut alone = None;
        if let Chosen::Wgpu(b) = &chosen {
            let (mut packs, mut hands) = (Vec::new(), Vec::new());
            for _ in 0..repeats {
                let mut sinks: Vec<&mut dyn GnSink> = handoff.iter_mut().map(|h| h as &mut dyn GnSink).collect();
                let (p, h) =
                    crate::kinematics::gpu::host_path_alone(&eval, b.precision(), &frames, &proxies, &mut sinks)?;
                packs.push(p * 1e6 / n as f64);
                hands.push(h * 1e6 / n as f64);
            }
            alone = Some((median(&mut packs), median(&mut hands)));
        }
        // Each kind of call: a warm-up, then `repeats` timed calls (wgpu: with its phase account).
        let mut timed = |kind: Kind| -> anyhow::Result<(f64, Option<PhaseTimes>)> {
            if kind == Kind::Linearize && out.is_empty() {
                return Ok((f64::NAN, None));
            }
            let mut times = Vec::new();
            for r in 0..=repeats {
                if r == 1 {
                    if let Chosen::Wgpu(b) = &mut chosen {
                        b.reset_phase_times();
                    }
                }
                let backend: &mut dyn BatchBackend = match &mut chosen {
                    Chosen::Cpu { .. } => &mut cpu,
                    Chosen::Wgpu(b) => b.as_mut(),
                };
                let t = Instant::now();
                match kind {
                    Kind::Linearize => backend.linearize(&frames, &proxies, &mut out)?,
                    Kind::Handoff => {
                        let mut sinks: Vec<&mut dyn GnSink> =
                            handoff.iter_mut().map(|h| h as &mut dyn GnSink).collect();
                        backend.linearize_into(&frames, &proxies, &mut sinks)?
                    }
                    Kind::Energy => backend.energy(&frames, &proxies, &mut energies)?,
                }
                if r > 0 {
                    times.push(t.elapsed().as_secs_f64());
                }
            }
            let phases = match &chosen {
                Chosen::Wgpu(b) => Some(b.phase_times()),
                Chosen::Cpu { .. } => None,
            };
            Ok((median(&mut times), phases))
        };
        let (ml, pl) = timed(Kind::Linearize)?;
        let (mh, ph) = timed(Kind::Handoff)?;
        let (me, pe) = timed(Kind::Energy)?;
        let fps = |t: f64| if t.is_nan() { "-".to_string() } else { format!("{:.0}", n as f64 / t) };
        println!(
            "{}\t{n}\t{:.3}\t{}\t{:.3}\t{}\t{:.3}\t{}",
            chosen.name(),
            ml * 1e3,
            fps(ml),
            mh * 1e3,
            fps(mh),
            me * 1e3,
            fps(me)
        );
        if let Some((p, h)) = alone {
            println!(
                "#   host path alone (plain memory, before the device runs): CPU time per frame: pack {p:.3} us + \
                 hand-out {h:.3} us = {:.3} us",
                p + h
            );
        }
        for (what, p) in [("linearize", pl), ("handoff", ph), ("energy", pe)] {
            if let Some(p) = p {
                let per = |s: f64| s * 1e3 / repeats as f64;
                let us = |s: f64| s * 1e6 / p.frames.max(1) as f64;
                println!(
                    "#   {what} phases, mean ms per call: pack {:.3}, upload+submit {:.3}, device wait {:.3}, \
                     read-back mapping {:.3}, unpack {:.3}; host CPU time per frame: pack {:.3} us + unpack \
                     {:.3} us = {:.3} us",
                    per(p.pack_s),
                    per(p.submit_s),
                    per(p.wait_s),
                    per(p.read_s),
                    per(p.unpack_s),
                    us(p.pack_cpu_s),
                    us(p.unpack_cpu_s),
                    us(p.pack_cpu_s + p.unpack_cpu_s)
                );
            }
        }
    }
    Ok(0)
}

/// Batches above this size skip the owned-result linearize (24 KB per frame).
const FULL_COPY_MAX: usize = 100_000;

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Linearize,
    Handoff,
    Energy,
}

/// What the trust-region solver copies out of a handed-over model before its QP reads `H`
/// in place: `E`, the statistics and `g`.
struct Handoff {
    energy: f64,
    marker_sq_sum: f64,
    markers_used: usize,
    g: Vec<f64>,
}

impl Handoff {
    fn new(np: usize) -> Handoff {
        Handoff { energy: 0.0, marker_sq_sum: 0.0, markers_used: 0, g: vec![0.0; np] }
    }
}

impl GnSink for Handoff {
    fn take(&mut self, view: &GnView<'_>) {
        self.energy = view.energy;
        self.marker_sq_sum = view.marker_sq_sum;
        self.markers_used = view.markers_used;
        view.g.copy_to(&mut self.g);
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
