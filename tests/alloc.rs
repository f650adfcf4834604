//! The per-frame hot path (trust-region solve: kinematics, assembly, box-QP) allocates nothing
//! once its workspaces exist: counted with a global allocator in this test binary.

use smocap::kinematics::assembly::FrameProblem;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::pipeline::Context;
use smocap::solve::{make_qp, FrameSolver, QpBackend};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Whether this thread's allocations count (the test's own thread, not the harness's).
    static COUNTED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Counts this thread's allocations while it lives: dropped before the test releases `SERIAL`,
/// so that what the harness allocates on this thread after the test returns is never counted
/// into the next test's window.
struct Counted;

impl Counted {
    fn on() -> Counted {
        COUNTED.with(|c| c.set(true));
        Counted
    }
}

impl Drop for Counted {
    fn drop(&mut self) {
        COUNTED.with(|c| c.set(false));
    }
}

fn count() {
    if COUNTED.with(|c| c.get()) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The tests share the counter, so they run one at a time (each counts its own thread only).
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn solving_frames_allocates_nothing_once_warm() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let _counted = Counted::on();
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

/// The step QP formed from a model handed over in place (`linearized_view`, `H` as the device
/// leaves it: f32, upper triangle packed by columns) allocates nothing once warm.
#[test]
fn a_step_from_a_handed_over_packed_model_allocates_nothing_once_warm() {
    use smocap::kinematics::assembly::EvalWorkspace;
    use smocap::kinematics::backend::{upper_index, GnView, HessianView, Reals};
    use smocap::solve::trqp::Next;
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let _counted = Counted::on();
    let ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 20, seed: 3, ..SynthOptions::default() });
    let eval = ctx.evaluator();
    let (np, stride) = (ctx.proxy.np(), 3 * ctx.model.markers.len());
    let zeros = vec![0.0; ctx.model.ny()];
    let mut solver = FrameSolver::new(&eval, ctx.settings.clone(), make_qp(QpBackend::Boxqp));
    let mut ws = EvalWorkspace::new(&ctx.model, &ctx.proxy);
    let (mut h32, mut g32) = (vec![0.0f32; np * (np + 1) / 2], vec![0.0f32; np]);
    let mut p = vec![0.0; np];
    let mut run = |f: usize, solver: &mut FrameSolver<'_>| {
        let frame = FrameProblem {
            observed: &s.trial.positions[f * stride..(f + 1) * stride],
            marker_weights: &ctx.marker_weights,
            tracking_ref: &zeros,
            tracking_weights: &zeros,
        };
        p.copy_from_slice(&s.truth.proxies[f]);
        p[0] += 0.01;
        let mut it = solver.begin(&mut p);
        eval.linearize(&p, &frame, &mut ws);
        for j in 0..np {
            g32[j] = ws.gn.g[j] as f32;
            for i in 0..=j {
                h32[upper_index(i, j)] = ws.gn.h[(i, j)] as f32;
            }
        }
        let view = GnView {
            energy: ws.gn.energy,
            marker_sq_sum: ws.gn.marker_sq_sum,
            markers_used: ws.gn.markers_used,
            g: Reals::F32(&g32),
            h: HessianView::UpperColumns(Reals::F32(&h32)),
            markers: Reals::F64(&ws.kin.markers),
            reference: [0.0; 3],
        };
        let next = solver.linearized_view(&mut it, &p, &view);
        matches!(next, Next::Energy)
    };
    run(0, &mut solver); // warm-up
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let steps = (1..20).filter(|&f| run(f, &mut solver)).count();
    let allocated = ALLOCATIONS.load(Ordering::Relaxed) - before;
    assert!(steps > 0, "no step was taken");
    assert_eq!(allocated, 0, "{allocated} allocations in 19 handed-over steps");
}

/// Writing a solved frame to its MCAP file (kinematics, protobuf encoding of `/tf`, `/markers`,
/// `/smocap/state`, `/smocap/stats`, the chunk's compression) allocates nothing of its own per
/// frame: with the whole trial in one chunk, what remains is the MCAP writer's amortised growth
/// of its chunk and index buffers (a few dozen reallocations in all; a new chunk adds a few
/// dozen more, every ≈ 300 frames at the default 1 MiB).
#[test]
fn writing_frames_allocates_far_less_than_once_per_frame() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let _counted = Counted::on();
    use smocap::archive::mcap_out::{TrialNames, TrialWriter, WriterOptions};
    use smocap::pipeline::SolvedFrame;
    use smocap::solve::{Calibration, FrameStats, FrameStatus};
    let ctx = Context::shipped().unwrap();
    let n = 2000;
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: n, seed: 3, ..SynthOptions::default() });
    let cal = Calibration {
        proxies: s.truth.proxies[0].clone(),
        frames: 1,
        iterations: 1,
        rmse_m: 0.0,
        ..Default::default()
    };
    let dir = std::env::temp_dir().join(format!("smocap-alloc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("t.mcap");
    let names = TrialNames::default();
    let opt = WriterOptions { chunk_size: 1 << 30, ..WriterOptions::default() };
    let mut w = TrialWriter::create(&out, &ctx, &s.trial, &cal, &names, None, &opt).unwrap();
    let stats = FrameStats {
        iterations: 1,
        accepted: 1,
        energy: 1e-3,
        rmse_m: 2e-3,
        markers_used: 53,
        status: FrameStatus::Converged,
    };
    // The frames, made before counting (the solver hands them over as they are), with their
    // observations in model order as the solver reads them.
    let map = smocap::pipeline::input::trial::match_markers(&ctx, "t", &s.trial).unwrap().columns;
    let obs = smocap::pipeline::input::trial::observations(&s.trial, &map);
    let stride = 3 * map.len();
    let frames: Vec<SolvedFrame> = (0..n)
        .map(|f| SolvedFrame {
            index: f,
            proxies: s.truth.proxies[f].clone(),
            stats,
            seconds: 1e-4,
            bridged: false,
            observed: obs[f * stride..(f + 1) * stride].to_vec(),
        })
        .collect();
    w.frame(&frames[0]).unwrap(); // warm-up: message buffers reach their sizes
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    for f in &frames[1..] {
        w.frame(f).unwrap();
    }
    let allocated = ALLOCATIONS.load(Ordering::Relaxed) - before;
    drop(w);
    let _ = std::fs::remove_dir_all(&dir);
    assert!(allocated < 100, "{allocated} allocations in {} frames", n - 1);
}

/// Allocations of `f` on this thread.
fn allocations_of(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    f();
    ALLOCATIONS.load(Ordering::Relaxed) - before
}

/// A synthetic trial of `n` frames written as a TRC file in `dir`.
fn trc_of(ctx: &Context, n: usize, dir: &std::path::Path) -> std::path::PathBuf {
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: n, seed: 3, ..SynthOptions::default() });
    let path = dir.join(format!("t{n}.trc"));
    smocap::io::trc::write_trc(&path, &s.trial, "mm").unwrap();
    path
}

#[test]
fn reading_a_trc_allocates_no_more_for_more_rows() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let _counted = Counted::on();
    let ctx = Context::shipped().unwrap();
    let dir = std::env::temp_dir().join(format!("smocap-alloc-trc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (short, long) = (trc_of(&ctx, 500, &dir), trc_of(&ctx, 2000, &dir));
    let a = allocations_of(|| drop(smocap::io::trc::read_trc(&short).unwrap()));
    let b = allocations_of(|| drop(smocap::io::trc::read_trc(&long).unwrap()));
    let _ = std::fs::remove_dir_all(&dir);
    // The arrays are reserved once; the rows' cells reuse one buffer.
    assert!(b <= a + 20, "500 rows: {a} allocations, 2000 rows: {b}");
}

#[test]
fn the_label_screen_allocates_no_more_for_more_frames() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let _counted = Counted::on();
    let ctx = Context::shipped().unwrap();
    let screen = |n: usize| {
        let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: n, seed: 3, ..SynthOptions::default() });
        let columns = smocap::pipeline::input::trial::match_markers(&ctx, "t", &s.trial).unwrap().columns;
        allocations_of(|| drop(smocap::pipeline::input::label_qc::screen_trial(&ctx, &s.trial, &columns).unwrap()))
    };
    let (a, b) = (screen(500), screen(2000));
    // Per rigid-pair candidate a sample buffer reserved once; per frame nothing (clean frames).
    assert!(b <= a + 20, "500 frames: {a} allocations, 2000 frames: {b}");
}

#[test]
fn retargeting_frames_onto_the_g1_allocates_nothing_once_warm() {
    use smocap::retarget::{self, solve::Solver, Human, Plan};
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let _counted = Counted::on();
    let ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 60, seed: 3, ..SynthOptions::default() });
    let scales: Vec<f64> =
        ctx.model.bodies.iter().flat_map(|b| s.truth.body_scales.get(&b.name).copied().unwrap_or([1.0; 3])).collect();
    let times: Vec<f64> = (0..60).map(|i| i as f64 / 100.0).collect();
    let human = Human {
        model: &ctx.model,
        scales: &scales,
        q: &s.truth.coordinates,
        times: &times,
        world_from_model: smocap::archive::mcap_out::world_from_model(ctx.up),
    };
    let (mapping, robot) = retarget::shipped("g1").unwrap().unwrap();
    let plan = Plan::new(&robot, &mapping, &human).unwrap();
    let targets = plan.targets(&human, &Default::default());
    let mut solver = Solver::new(&robot, &plan, Default::default());
    let (mut q, mut prev) = (plan.reference.clone(), plan.reference.clone());
    let pins = vec![None; plan.feet.len()];
    solver.frame(&targets, 0, &mut q, None, &pins);
    prev.copy_from_slice(&q);
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    for i in 1..60 {
        solver.frame(&targets, i, &mut q, Some((&prev, 0.01)), &pins);
        prev.copy_from_slice(&q);
    }
    let allocated = ALLOCATIONS.load(Ordering::Relaxed) - before;
    assert_eq!(allocated, 0, "59 retargeted frames allocated {allocated} times");
}

#[test]
fn posing_the_body_mesh_allocates_nothing_once_warm() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 20, seed: 3, ..SynthOptions::default() });
    let asset = smocap::body::BodyAsset::shipped().unwrap();
    let scales: Vec<f64> =
        ctx.model.bodies.iter().flat_map(|b| s.truth.body_scales.get(&b.name).copied().unwrap_or([1.0; 3])).collect();
    let sub = smocap::body::SubjectBody { stature_m: None, info: Default::default() };
    let wfm = nalgebra::UnitQuaternion::identity();
    let (body, _) = smocap::body::dress_subject(&ctx.model, &wfm, &asset, &scales, &sub).unwrap();
    assert!(!body.binding.helpers.helpers.is_empty(), "the shipped model's body has helper joints");
    assert!(!body.correctives.is_empty(), "and volume correctives");
    let mut ws = smocap::body::PoseWorkspace::new(&ctx.model, &body);
    let states: Vec<Vec<f64>> = (0..s.truth.coordinates.len())
        .map(|f| {
            let mut y = ctx.model.default_state();
            for (name, v) in s.truth.coordinate_names.iter().zip(&s.truth.coordinates[f]) {
                if let Some(j) = ctx.model.coordinates.iter().position(|c| &c.name == name) {
                    y[j] = *v;
                }
            }
            y[ctx.model.nq()..].copy_from_slice(&scales);
            y
        })
        .collect();
    body.pose(&ctx.model, &states[0], &mut ws);
    let _counted = Counted::on();
    let n = allocations_of(|| {
        for y in &states {
            body.pose(&ctx.model, y, &mut ws);
        }
    });
    assert_eq!(n, 0, "{n} allocations posing {} frames", states.len());
}
