//! The lane scheduler across trials (`solve_trials_streaming`): trials of one subject solved
//! together, their segments sharing the lanes of one scheduler, give every frame exactly as each
//! trial solved alone gives it (proxies and statistics bit for bit, bridged frames, frame order),
//! whatever the lane and thread counts, with the `auto` pre-solve and without it, and for trials
//! read a window at a time.

use smocap::io::MarkerTrial;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::pipeline::running::stream::{solve_trials_streaming, TrialStream};
use smocap::pipeline::{calibrate_subject, solve_trial_with, Context, SolvedFrame};
use smocap::solve::Presolve;

/// A frame as bits: index, proxies, iterations, accepted, energy, RMSE, markers used, status,
/// bridged.
type Bits = (usize, Vec<u64>, u32, u32, u64, u64, usize, String, bool);

fn bits(f: &SolvedFrame) -> Bits {
    let s = &f.stats;
    (
        f.index,
        f.proxies.iter().map(|x| x.to_bits()).collect(),
        s.iterations,
        s.accepted,
        s.energy.to_bits(),
        s.rmse_m.to_bits(),
        s.markers_used,
        format!("{:?}", s.status),
        f.bridged,
    )
}

/// Three trials of 450, 90 and 230 frames; the second with every marker gone for frames 40–45
/// (bridged), the third with one marker gone for a while.
fn trials(ctx: &Context) -> Vec<MarkerTrial> {
    let mut out = Vec::new();
    for (frames, seed) in [(450, 3), (90, 4), (230, 5)] {
        out.push(synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames, seed, ..SynthOptions::default() }).trial);
    }
    let m = out[1].n_markers();
    out[1].positions[40 * m * 3..46 * m * 3].fill(f64::NAN);
    for f in 100..160 {
        out[2].positions[(f * m + 2) * 3..(f * m + 3) * 3].fill(f64::NAN);
    }
    out
}

/// Every trial solved alone (one lane, one thread): its frames as bits.
fn alone(ctx: &Context, trials: &[MarkerTrial], cal: &smocap::solve::Calibration) -> Vec<Vec<Bits>> {
    trials
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let r = solve_trial_with(ctx, &format!("t{i}"), t, cal, 1, 1, None).unwrap();
            (0..t.n_frames())
                .map(|f| {
                    let frame = SolvedFrame {
                        index: f,
                        proxies: r.proxies[f].clone(),
                        stats: r.stats[f],
                        seconds: 0.0,
                        bridged: r.bridged.contains(&f),
                        observed: Vec::new(),
                    };
                    bits(&frame)
                })
                .collect()
        })
        .collect()
}

/// The trials solved together with `lanes` lanes on `threads` threads, each read `window` frames
/// at a time (as a file would be): each trial's frames as bits, in the order its sink got them.
fn together(
    ctx: &Context,
    trials: &[MarkerTrial],
    cal: &smocap::solve::Calibration,
    lanes: usize,
    threads: usize,
    window: usize,
) -> Vec<Vec<Bits>> {
    let windowed: Vec<Windowed<'_>> = trials.iter().map(|t| Windowed(t, window)).collect();
    let mut got: Vec<Vec<Bits>> = vec![Vec::new(); trials.len()];
    let names: Vec<String> = (0..trials.len()).map(|i| format!("t{i}")).collect();
    let mut sinks: Vec<_> = got
        .iter_mut()
        .map(|g| {
            move |f: SolvedFrame| -> Result<(), smocap::pipeline::input::trial::SinkError> {
                g.push(bits(&f));
                Ok(())
            }
        })
        .collect();
    let streams: Vec<TrialStream<'_, '_>> = windowed
        .iter()
        .zip(&names)
        .zip(sinks.iter_mut())
        .map(|((t, name), sink)| TrialStream { name, trial: t, sink })
        .collect();
    for r in solve_trials_streaming(ctx, streams, cal, threads, lanes, None) {
        let r = r.unwrap();
        assert!(r.frames > 0);
    }
    drop(sinks);
    got
}

/// A trial held whole but read `.1` frames at a time.
struct Windowed<'a>(&'a MarkerTrial, usize);

impl smocap::pipeline::input::frames::TrialFrames for Windowed<'_> {
    fn header(&self) -> &MarkerTrial {
        self.0
    }
    fn window(&self, range: std::ops::Range<usize>) -> Result<std::borrow::Cow<'_, MarkerTrial>, String> {
        self.0.window(range)
    }
    fn window_frames(&self) -> usize {
        self.1
    }
}

#[test]
fn trials_solved_together_give_every_frame_as_each_trial_solved_alone() {
    for presolve in [Presolve::Auto, Presolve::Never] {
        let mut ctx = Context::shipped().unwrap();
        ctx.settings.presolve = presolve;
        let trials = trials(&ctx);
        let cal = calibrate_subject(&ctx, &[("t0", &trials[0])]).unwrap();
        let want = alone(&ctx, &trials, &cal);
        assert!(want[1].iter().filter(|f| f.8).count() >= 6, "the gap is bridged");
        for (lanes, threads, window) in [(1, 1, usize::MAX), (3, 2, usize::MAX), (16, 2, usize::MAX), (4, 2, 150)] {
            let got = together(&ctx, &trials, &cal, lanes, threads, window);
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                assert_eq!(g.len(), w.len(), "{presolve:?}, {lanes} lanes, window {window}: trial {i}");
                let first = g.iter().zip(w).position(|(a, b)| a != b);
                assert!(
                    first.is_none(),
                    "{presolve:?}, {lanes} lanes, window {window}: trial {i} differs at {first:?}"
                );
            }
        }
    }
}
