//! Label quality control (`smocap::pipeline::input::label_qc`): swapped labels (left/right pairs and
//! neighbours on one body or adjacent bodies) and jumps injected into synthetic trials are found,
//! swaps repaired so that the joint angles are those of the clean trial; nothing is reported on
//! the clean trials of the same seeds nor on the shared real trials.

mod common;

use common::{rng, shared};
use prost::Message;
use rand::RngExt;
use smocap::io::MarkerTrial;
use smocap::kinematics::synth::{synthesize, SynthOptions, Synthetic};
use smocap::pipeline::input::convention::InputOptions;
use smocap::pipeline::input::label_qc::{screen_in_place, screen_trial, Action, EventKind, LabelQc, QcMode};
use smocap::pipeline::input::trial::match_markers;
use smocap::pipeline::{calibrate_subject, session, solve_trial, Context};
use std::path::Path;
use std::process::Command;

/// Left/right pairs and neighbours (one body or adjacent bodies) whose exchange the screen must
/// find.
const LEFT_RIGHT: [(&str, &str); 8] = [
    ("LKNE", "RKNE"),
    ("LHEE", "RHEE"),
    ("LANK", "RANK"),
    ("LTOE", "RTOE"),
    ("LASI", "RASI"),
    ("LTHI", "RTHI"),
    ("LTIB", "RTIB"),
    ("LPSI", "RPSI"),
];
const NEIGHBOURS: [(&str, &str); 6] =
    [("LASI", "LPSI"), ("RTHI", "RKNE"), ("LKNE", "LTIB"), ("RASI", "RTHI"), ("LHEE", "LTOE"), ("RTIB", "RANK")];

fn synth(ctx: &Context, seed: u64, frames: usize) -> Synthetic {
    let opt = SynthOptions { frames, seed, ..SynthOptions::default() };
    synthesize(&ctx.model, &ctx.proxy, &opt)
}

fn column(t: &MarkerTrial, name: &str) -> usize {
    t.labels.iter().position(|l| l == name).unwrap_or_else(|| panic!("{name} in the trial"))
}

/// Exchanges the columns of labels `a` and `b` over frames `first..first + len`.
fn inject_swap(t: &mut MarkerTrial, a: &str, b: &str, first: usize, len: usize) {
    let (ca, cb, nl) = (column(t, a), column(t, b), t.labels.len());
    for f in first..first + len {
        for k in 0..3 {
            t.positions.swap((f * nl + ca) * 3 + k, (f * nl + cb) * 3 + k);
        }
    }
}

/// Moves marker `m` by `offset` (m) over frames `first..first + len`.
fn inject_jump(t: &mut MarkerTrial, m: &str, first: usize, len: usize, offset: [f64; 3]) {
    let (c, nl) = (column(t, m), t.labels.len());
    for f in first..first + len {
        for (k, o) in offset.iter().enumerate() {
            t.positions[(f * nl + c) * 3 + k] += o;
        }
    }
}

fn screen(ctx: &Context, t: &MarkerTrial) -> LabelQc {
    let m = match_markers(ctx, "trial", t).expect("markers match");
    screen_trial(ctx, t, &m.columns).expect("screen")
}

/// Whether `qc` has an event of `kind` on exactly `markers` covering `first..first + len` (within
/// a frame at either end) with `action`.
fn found(qc: &LabelQc, kind: &[EventKind], markers: &[&str], first: usize, len: usize, action: Action) -> bool {
    let last = first + len - 1;
    qc.events.iter().any(|e| {
        let mut names: Vec<&str> = e.markers.iter().map(String::as_str).collect();
        let mut want = markers.to_vec();
        names.sort_unstable();
        want.sort_unstable();
        kind.contains(&e.kind)
            && names == want
            && e.action == action
            && e.first_frame.abs_diff(first) <= 1
            && e.last_frame.abs_diff(last) <= 1
    })
}

#[test]
fn injected_swaps_are_found_and_repaired_on_twenty_seeds_and_clean_trials_have_none() {
    let ctx = Context::shipped().expect("shipped model");
    let (mut injected, mut hits) = (0, 0);
    let mut missed = Vec::new();
    for seed in 1..=20u64 {
        let s = synth(&ctx, seed, 800);
        let clean = screen(&ctx, &s.trial);
        assert!(clean.events.is_empty(), "seed {seed}: events on the clean trial: {:?}", clean.events);
        let mut r = rng(seed + 1000);
        let mut t = s.trial.clone();
        // A left/right exchange and a neighbour exchange in separate halves, spans 5 to 200.
        let lr = LEFT_RIGHT[(seed as usize) % LEFT_RIGHT.len()];
        let nb = NEIGHBOURS[(seed as usize) % NEIGHBOURS.len()];
        let mut spans = Vec::new();
        for (pair, lo) in [(lr, 10usize), (nb, 410)] {
            let len = r.random_range(5..=200usize);
            let first = lo + r.random_range(0..(380 - len));
            inject_swap(&mut t, pair.0, pair.1, first, len);
            spans.push((pair, first, len));
        }
        let qc = screen(&ctx, &t);
        for ((a, b), first, len) in spans {
            injected += 1;
            if found(&qc, &[EventKind::Swap], &[a, b], first, len, Action::Repaired) {
                hits += 1;
            } else {
                missed.push(format!("seed {seed}: {a}/{b} {first}+{len}: got {:?}", qc.events));
            }
        }
    }
    println!("swaps found and repaired: {hits} of {injected}");
    for m in &missed {
        println!("missed {m}");
    }
    assert!(hits as f64 >= 0.95 * injected as f64, "{hits} of {injected} found: {missed:#?}");
}

#[test]
fn injected_jumps_are_found_and_masked_on_twenty_seeds_and_clean_trials_have_none() {
    let ctx = Context::shipped().expect("shipped model");
    let markers = ["LKNE", "RHEE", "LASI", "RTHI", "LANK", "RTOE", "LKNM", "RTIB", "LMT5", "SACR"];
    let (mut injected, mut hits) = (0, 0);
    let mut missed = Vec::new();
    for seed in 1..=20u64 {
        let s = synth(&ctx, seed, 400);
        let clean = screen(&ctx, &s.trial);
        assert!(clean.events.is_empty(), "seed {seed}: events on the clean trial: {:?}", clean.events);
        let mut r = rng(seed + 2000);
        let mut t = s.trial.clone();
        let m = markers[(seed as usize) % markers.len()];
        let len = r.random_range(3..=8usize);
        let first = r.random_range(20..(380 - len));
        // 80 to 150 mm in a random direction.
        let dir: [f64; 3] = [r.random_range(-1.0..1.0), r.random_range(-1.0..1.0), r.random_range(-1.0..1.0)];
        let norm = dir.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-3);
        let size = r.random_range(0.08..0.15);
        inject_jump(&mut t, m, first, len, dir.map(|x| x / norm * size));
        let qc = screen(&ctx, &t);
        injected += 1;
        if found(&qc, &[EventKind::Jump, EventKind::Ghost], &[m], first, len, Action::Masked) {
            hits += 1;
        } else {
            missed.push(format!("seed {seed}: {m} {first}+{len} by {size:.3} m: got {:?}", qc.events));
        }
    }
    println!("jumps found: {hits} of {injected}");
    for m in &missed {
        println!("missed {m}");
    }
    // The step test (each marker's distances to its partners against their last kept values)
    // finds jumps in any direction; the trial-wide test alone found 15 of these 20.
    assert!(hits as f64 >= 0.95 * injected as f64, "{hits} of {injected} found: {missed:#?}");
}

/// Joint-angle RMSE (deg) against the truth of `t` solved after label QC as `mode` says.
fn angle_rmse(ctx: &Context, s: &Synthetic, t: &MarkerTrial, mode: QcMode) -> (f64, LabelQc) {
    let mut ctx = ctx.clone();
    ctx.settings.label_qc.mode = mode;
    let mut t = t.clone();
    let m = match_markers(&ctx, "trial", &t).expect("markers match");
    let qc = screen_in_place(&ctx, &mut t, &m.columns).expect("screen");
    let cal = calibrate_subject(&ctx, &[("trial", &t)]).expect("calibration");
    let r = solve_trial(&ctx, "trial", &t, &cal, 2).expect("solve");
    // The per-marker error table: every weighted marker once, its maximum at least its RMSE.
    let table = &r.marker_errors;
    assert_eq!(table.anatomical.len() + table.tracking.len(), ctx.model.markers.len());
    assert!(!table.anatomical.is_empty() && !table.tracking.is_empty());
    assert!(table.anatomical.iter().chain(&table.tracking).all(|e| e.max_mm >= e.rmse_mm && e.frames > 0));
    assert_eq!(table.worst_frames.len(), smocap::pipeline::running::marker_errors::WORST_FRAMES);
    assert!(table.worst_frames.windows(2).all(|w| w[0].rmse_mm >= w[1].rmse_mm));
    let rep = smocap::pipeline::results::report::trial_report(&ctx, &r, Some(&s.truth));
    (rep.pose_error_deg.expect("truth given").rmse, qc)
}

#[test]
fn repaired_swaps_give_the_clean_trials_joint_angles() {
    let ctx = Context::shipped().expect("shipped model");
    let s = synth(&ctx, 5, 600);
    let mut t = s.trial.clone();
    inject_swap(&mut t, "LKNE", "RKNE", 100, 150);
    inject_swap(&mut t, "LASI", "LPSI", 300, 40);
    inject_swap(&mut t, "LHEE", "RHEE", 450, 12);
    let (clean, _) = angle_rmse(&ctx, &s, &s.trial, QcMode::Repair);
    let (off, _) = angle_rmse(&ctx, &s, &t, QcMode::Off);
    let (repaired, qc) = angle_rmse(&ctx, &s, &t, QcMode::Repair);
    println!("angle RMSE: clean {clean:.3}°, swapped {off:.3}°, repaired {repaired:.3}°");
    assert_eq!(qc.events.len(), 3, "{:?}", qc.events);
    assert!(qc.events.iter().all(|e| e.action == Action::Repaired));
    assert!((repaired - clean).abs() <= 0.3, "repaired {repaired}° vs clean {clean}°");
    assert!(off > clean + 0.3, "the swaps matter: {off}° vs {clean}°");
}

#[test]
fn flag_mode_reports_without_changing_the_data_and_makes_the_trial_suspect() {
    let ctx = Context::shipped().expect("shipped model");
    let mut ctx_flag = ctx.clone();
    ctx_flag.settings.label_qc.mode = QcMode::Flag;
    let s = synth(&ctx, 3, 300);
    let mut t = s.trial.clone();
    inject_swap(&mut t, "LKNE", "RKNE", 50, 30);
    let before = t.clone();
    let m = match_markers(&ctx, "trial", &t).expect("markers match");
    let qc = screen_in_place(&ctx_flag, &mut t, &m.columns).expect("screen");
    assert_eq!(qc.events.len(), 1);
    assert_eq!(qc.events[0].action, Action::Flagged);
    assert!(qc.suspect.is_some());
    assert!(t.positions.iter().zip(&before.positions).all(|(a, b)| a.to_bits() == b.to_bits()));
    // Repair exchanges the labels back.
    let qc = screen_in_place(&ctx, &mut t, &m.columns).expect("screen");
    assert_eq!(qc.events[0].action, Action::Repaired);
    assert!(qc.suspect.is_none());
    assert!(t.positions.iter().zip(&s.trial.positions).all(|(a, b)| a.to_bits() == b.to_bits()));
    let mut ctx_off = ctx.clone();
    ctx_off.settings.label_qc.mode = QcMode::Off;
    assert!(screen(&ctx_off, &before).events.is_empty());
}

/// The shared real trials (each with the model it is solved with): no event.
#[test]
fn shared_real_trials_have_no_label_events() {
    let d = |p: &str| shared(&format!("datasets/{p}"));
    let osim = |m: &str, ms: Option<&str>| {
        Context::from_files_with_markers(&d(m), ms.map(d).as_deref(), None).expect("model loads")
    };
    let mut cases: Vec<(Context, Vec<std::path::PathBuf>)> = Vec::new();
    if d("gait2354_subject01").exists() {
        let ctx =
            osim("gait2354_subject01/gait2354_simbody.osim", Some("gait2354_subject01/gait2354_Scale_MarkerSet.xml"));
        cases.push((
            ctx,
            vec![d("gait2354_subject01/subject01_walk1.trc"), d("gait2354_subject01/subject01_static.trc")],
        ));
    }
    if d("rajagopal2016_walk").exists() {
        let ctx = osim("rajagopal2016_walk/Rajagopal2016.osim", Some("rajagopal2016_walk/markerset_walk_preScale.xml"));
        cases.push((
            ctx,
            vec![d("rajagopal2016_walk/motion_capture_walk.trc"), d("rajagopal2016_walk/static_walk_1.trc")],
        ));
    }
    if d("opencap_addbiomechanics").exists() {
        let ctx = osim("opencap_addbiomechanics/unscaled_generic.osim", None);
        let mut trials: Vec<_> = std::fs::read_dir(d("opencap_addbiomechanics/MarkerData"))
            .expect("marker data")
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "trc"))
            .collect();
        trials.sort();
        cases.push((ctx, trials));
    }
    let shipped = Context::shipped().expect("shipped model");
    for (dir, files) in [
        ("vicon_plugingait_flatfoot", ["PiG_Calibration3_FF.c3d", "PiG_Motion3_FF.c3d"]),
        ("c3d_sample01", ["Eb015pi.c3d", "Eb015vi.c3d"]),
    ] {
        if d(dir).exists() {
            cases.push((shipped.clone(), files.iter().map(|f| d(&format!("{dir}/{f}"))).collect()));
        }
    }
    if cases.is_empty() {
        println!("skipped: ../shared/datasets is absent");
        return;
    }
    let mut reported = Vec::new();
    for (ctx, files) in &cases {
        for p in files {
            let (t, _) = session::read_input(ctx, p, &InputOptions::default()).expect("reads");
            let Ok(m) = match_markers(ctx, "trial", &t) else { continue };
            let qc = screen_trial(ctx, &t, &m.columns).expect("screen");
            println!("{}: {} rigid pairs, {} events", p.display(), qc.rigid_pairs, qc.events.len());
            if !qc.events.is_empty() {
                reported.push(format!("{}: {:?}", p.display(), qc.events));
            }
        }
    }
    assert!(reported.is_empty(), "events on real trials: {reported:#?}");
}

/// `smocap synth --seed 11` (1000 frames) with LKNE/RKNE exchanged for 200 frames, LASI/LPSI for
/// 50 and LHEE/RHEE for 20: exit 0, the three swaps repaired and listed in the report; a
/// static trial's swap repaired and listed too.
#[test]
fn cli_repairs_and_lists_the_swaps_of_the_issue() {
    let dir = std::env::temp_dir().join(format!("smocap-label-qc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let p = |f: &str| dir.join(f).display().to_string();
    let bin = env!("CARGO_BIN_EXE_smocap");
    let out = Command::new(bin)
        .args(["synth", "--seed", "11", "--frames", "1000", "--out", &p("s.trc"), "--truth", &p("s.json")])
        .output()
        .expect("synth");
    assert!(out.status.success());
    let mut t = smocap::io::read_markers(std::path::Path::new(&p("s.trc"))).expect("reads");
    inject_swap(&mut t, "LKNE", "RKNE", 300, 200);
    inject_swap(&mut t, "LASI", "LPSI", 600, 50);
    inject_swap(&mut t, "LHEE", "RHEE", 800, 20);
    smocap::io::trc::write_trc(std::path::Path::new(&p("w.trc")), &t, "mm").expect("writes");
    let out = Command::new(bin)
        .args(["solve", &p("w.trc"), "--threads", "2", "--report-json", &p("r.json")])
        .output()
        .expect("solve");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p("r.json")).expect("report")).expect("json");
    let events = r["trials"][0]["label_qc"]["events"].as_array().expect("events").clone();
    let got: Vec<(String, u64, u64, String)> = events
        .iter()
        .map(|e| {
            let mut m: Vec<&str> = e["markers"].as_array().unwrap().iter().map(|x| x.as_str().unwrap()).collect();
            m.sort_unstable();
            (
                m.join("/"),
                e["first_frame"].as_u64().unwrap(),
                e["last_frame"].as_u64().unwrap(),
                e["action"].as_str().unwrap().into(),
            )
        })
        .collect();
    let want = [("LKNE/RKNE", 300, 499), ("LASI/LPSI", 600, 649), ("LHEE/RHEE", 800, 819)];
    assert_eq!(got.len(), 3, "{got:?}");
    for ((m, a, b), g) in want.iter().zip(&got) {
        assert_eq!((m.to_string(), *a, *b, "repaired".to_string()), g.clone());
    }
    assert!(stderr.contains("label QC: swap"), "{stderr}");
    // A static trial is screened as the trials are: a standing trial of the synthetic archive
    // with its knee markers exchanged for 40 frames.
    let spec = smocap::archive::config::SyntheticSpec { subjects: 1, trials: 1, frames: 300, seed: 2 };
    smocap::archive::synthetic::generate(&spec, &dir.join("arch")).expect("synthetic archive");
    let mut st = smocap::io::read_markers(&dir.join("arch/subj01/static.trc")).expect("reads");
    inject_swap(&mut st, "LKNE", "RKNE", 20, 40);
    smocap::io::trc::write_trc(Path::new(&p("st.trc")), &st, "mm").expect("writes");
    let walk = dir.join("arch/subj01/walk01.trc").display().to_string();
    let out = Command::new(bin)
        .args(["solve", &walk, "--static", &p("st.trc"), "--threads", "2", "--report-json", &p("r2.json")])
        .output()
        .expect("solve");
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p("r2.json")).expect("report")).expect("json");
    let events = r["static_label_qc"]["events"].as_array().expect("the static trial's events");
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!((&events[0]["kind"], &events[0]["action"]), (&"swap".into(), &"repaired".into()), "{events:?}");
    assert_eq!((events[0]["first_frame"].as_u64(), events[0]["last_frame"].as_u64()), (Some(20), Some(59)));
    // `convert` screens every trial the same way; `--label-qc off` leaves them as they are.
    std::fs::create_dir_all(dir.join("data/s01")).expect("data dir");
    std::fs::copy(p("w.trc"), dir.join("data/s01/w.trc")).expect("copy");
    let toml = "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/*.trc\"]\n";
    std::fs::write(dir.join("datasets.toml"), toml).expect("toml");
    for (mode, want) in [(None, 3), (Some("off"), 0)] {
        let (out_dir, summary) = (p(&format!("out-{want}")), p(&format!("summary-{want}.json")));
        let mut cmd = Command::new(bin);
        cmd.args(["convert", &p("datasets.toml"), "--out", &out_dir, "--report-json", &summary, "--quiet"]);
        if let Some(m) = mode {
            cmd.args(["--label-qc", m]);
        }
        let out = cmd.output().expect("convert");
        assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&summary).expect("summary")).expect("json");
        let events = s["trials"][0]["label_qc"].as_array().map_or(0, Vec::len);
        assert_eq!(events, want, "--label-qc {mode:?}: {}", s["trials"][0]);
        // The converted file carries them on `/smocap/label_qc`, with their frames' log times.
        let buf = std::fs::read(Path::new(&out_dir).join("lab/s01/w.mcap")).expect("converted file");
        let qc = mcap::MessageStream::new(&buf)
            .expect("mcap")
            .map(|m| m.expect("message"))
            .find(|m| m.channel.topic == "/smocap/label_qc")
            .map(|m| smocap::archive::proto::LabelQc::decode(&m.data[..]).expect("decodes"))
            .expect("a /smocap/label_qc message");
        assert_eq!((qc.mode.as_str(), qc.events.len()), (mode.unwrap_or("repair"), want), "{qc:?}");
        if let Some(e) = qc.events.first() {
            assert_eq!(
                (e.kind.as_str(), e.action.as_str(), e.first_frame, e.last_frame),
                ("swap", "repaired", 300, 499)
            );
            let secs =
                |ts: &Option<smocap::archive::proto::Timestamp>| ts.map(|s| s.seconds as f64 + s.nanos as f64 * 1e-9);
            let span = secs(&e.last_time).expect("time") - secs(&e.first_time).expect("time");
            assert!((span - 199.0 / t.rate_hz).abs() < 1e-6, "{e:?}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
