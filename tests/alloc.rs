//! The per-frame hot path (trust-region solve: kinematics, assembly, box-QP) allocates nothing
//! once its workspaces exist: counted with a global allocator in this test binary.

use smocap::kinematics::assembly::FrameProblem;
use smocap::pipeline::Context;
use smocap::solve::{make_qp, FrameSolver, QpBackend};
use smocap::synth::{synthesize, SynthOptions};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn solving_frames_allocates_nothing_once_warm() {
    let ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 40, seed: 2, ..SynthOptions::default() });
    let eval = ctx.evaluator();
    let stride = 3 * ctx.model.markers.len();
    let zeros = vec![0.0; ctx.model.ny()];
    let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(QpBackend::Boxqp));
    let mut p = s.truth.proxies[0].clone();
    let frame = |f: usize| FrameProblem {
        observed: &s.trial.positions[f * stride..(f + 1) * stride],
        marker_weights: &ctx.marker_weights,
        tracking_ref: &zeros,
        tracking_weights: &zeros,
    };
    solver.solve(&frame(0), &mut p); // warm-up: workspaces reach their sizes
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let mut iterations = 0;
    for f in 1..40 {
        iterations += solver.solve(&frame(f), &mut p).iterations;
    }
    let allocated = ALLOCATIONS.load(Ordering::Relaxed) - before;
    assert!(iterations >= 39);
    assert_eq!(allocated, 0, "{allocated} allocations in 39 frames");
}
