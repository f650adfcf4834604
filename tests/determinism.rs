//! The result is a function of the input and the settings alone (issue 12, item 10): the same
//! trial solved with `--threads 1` and `--threads 2` (and so any lane count: lanes default to
//! the thread count) gives byte-identical `.mot` files and report numbers, timing aside; the
//! same archive converted with `--jobs 1` and `--jobs 2` gives identical outputs (exported back
//! as CSV) and summary numbers. The trial is long enough to be cut into segments.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn smocap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().expect("run smocap")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-determinism-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn ok(o: Output) -> Output {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

/// `v` without the fields that measure time or name the parallelism.
fn without_timing(mut v: serde_json::Value) -> serde_json::Value {
    const TIMING: [&str; 10] = [
        "ms_per_frame",
        "solve_wall_s",
        "frames_per_s",
        "solve_s",
        "threads",
        "lanes",
        "wall_seconds",
        "totals",
        "output",
        "seconds",
    ];
    fn strip(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(m) => {
                m.retain(|k, _| !TIMING.contains(&k.as_str()));
                m.values_mut().for_each(strip);
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(strip),
            _ => {}
        }
    }
    strip(&mut v);
    v
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

#[test]
fn solve_with_one_or_two_threads_gives_identical_mot_and_report_numbers() {
    let dir = tmp("solve");
    let trc = dir.join("walk.trc");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    ok(smocap(&[
        "synth",
        "--frames",
        "450",
        "--noise-mm",
        "2",
        "--seed",
        "5",
        "--out",
        &s(&trc),
        "--truth",
        &s(&dir.join("t.json")),
    ]));
    let run = |threads: &str| {
        let mot = dir.join(format!("mot{threads}"));
        let rep = dir.join(format!("r{threads}.json"));
        ok(smocap(&["solve", &s(&trc), "--threads", threads, "--mot-dir", &s(&mot), "--report-json", &s(&rep)]));
        (std::fs::read(mot.join("walk.mot")).unwrap(), without_timing(json(&rep)))
    };
    let (mot1, rep1) = run("1");
    let (mot2, rep2) = run("2");
    assert!(mot1 == mot2, ".mot files differ between --threads 1 and 2");
    assert_eq!(rep1, rep2);
}

#[test]
fn convert_with_one_or_two_jobs_gives_identical_outputs_and_summary_numbers() {
    let dir = tmp("convert");
    let spec = smocap::archive::config::SyntheticSpec { subjects: 2, trials: 1, frames: 420, seed: 9 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(&toml, "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nstatic = \"{subject}/static.trc\"\nsubject = \"{subject}/{trial}\"\n").unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let run = |jobs: &str| {
        let out = dir.join(format!("out{jobs}"));
        let rep = dir.join(format!("r{jobs}.json"));
        ok(smocap(&["convert", &s(&toml), "--out", &s(&out), "--jobs", jobs, "--report-json", &s(&rep), "--quiet"]));
        let csv: Vec<Vec<u8>> = ["subj01", "subj02"]
            .iter()
            .map(|subj| {
                let csv = dir.join(format!("{subj}-{jobs}.csv"));
                let mcap = out.join(format!("lab/{subj}/walk01.mcap"));
                ok(smocap(&["export", &s(&mcap), "--csv", &s(&csv)]));
                std::fs::read(csv).unwrap()
            })
            .collect();
        (csv, without_timing(json(&rep)))
    };
    let (csv1, rep1) = run("1");
    let (csv2, rep2) = run("2");
    assert!(csv1 == csv2, "exported outputs differ between --jobs 1 and 2");
    assert_eq!(rep1, rep2);
}

#[test]
fn segments_are_a_function_of_the_frame_count_alone() {
    use smocap::pipeline::running::stream::{segments, SEGMENT_FRAMES};
    assert_eq!(segments(151), [(0, 151)]);
    assert_eq!(segments(450), [(0, 225), (225, 450)]);
    for n in [1, 199, 200, 401, 10_000] {
        let s = segments(n);
        assert_eq!((s[0].0, s[s.len() - 1].1), (0, n));
        assert!(s.windows(2).all(|w| w[0].1 == w[1].0));
        assert!(n < SEGMENT_FRAMES || s.iter().all(|(a, b)| b - a >= SEGMENT_FRAMES));
    }
}

/// A trial cut into two segments (450 frames: cut at 225) against the same frames solved uncut
/// (its first 399 frames: one segment): from the cut on, the two agree to within the solver's
/// tolerance, because the second segment's lane tracks 20 frames into the cut before it keeps any.
#[test]
fn a_segment_cut_is_invisible_in_the_result() {
    use smocap::kinematics::synth::{synthesize, SynthOptions};
    use smocap::pipeline::{calibrate_subject, solve_trial, Context};
    let mut ctx = Context::shipped().unwrap();
    ctx.settings.presolve = smocap::solve::Presolve::Never;
    let s = synthesize(
        &ctx.model,
        &ctx.proxy,
        &SynthOptions { frames: 450, seed: 31, noise_m: 0.002, ..SynthOptions::default() },
    );
    let cal = calibrate_subject(&ctx, &[("t", &s.trial)]).unwrap();
    let cut = smocap::pipeline::running::stream::segments(450)[1].0;
    let n = 399;
    let w = 3 * s.trial.n_markers();
    let mut head = s.trial.clone();
    head.times.truncate(n);
    head.frame_numbers.truncate(n);
    head.positions.truncate(n * w);
    let whole = solve_trial(&ctx, "t", &s.trial, &cal, 2).unwrap();
    let uncut = solve_trial(&ctx, "t", &head, &cal, 2).unwrap();
    let mut worst = 0.0f64;
    for f in 0..n {
        let d = whole.proxies[f].iter().zip(&uncut.proxies[f]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        if f < cut {
            assert_eq!(d, 0.0, "frame {f} before the cut");
        }
        worst = worst.max(d);
    }
    eprintln!("largest proxy difference from the cut on: {worst:.3e}");
    assert!(worst < 1e-3, "the cut shows: {worst}");
}
