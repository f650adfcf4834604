//! Hostile inputs and runs (issue 12): concurrent converts into one folder, outputs that
//! collide or escape `--out`, discovery through link loops and FIFOs, absurd models, corrupt
//! MCAP files, absurd counts, garbage marker data, and one exit-code scheme.
//!
//! Over 600 lines: one family of behaviour (what smocap does with hostile input) whose tests share
//! their fixtures and the exit-code table; a reader checks the scheme in one file.

use smocap::archive::config::{read_datasets, SyntheticSpec};
use smocap::archive::inspect::{inspect, verify};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

fn smocap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().expect("run smocap")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-hostile-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Every file under `dir` whose name ends with `suffix`, sorted.
fn files(dir: &Path, suffix: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else { return out };
    for e in rd {
        let p = e.unwrap().path();
        if p.is_dir() && !p.is_symlink() {
            out.extend(files(&p, suffix));
        } else if p.to_string_lossy().ends_with(suffix) {
            out.push(p);
        }
    }
    out.sort();
    out
}

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A small synthetic archive (`subjNN/static.trc`, `subjNN/walkNN.trc`) and its datasets.toml.
fn archive(name: &str, subjects: usize, trials: usize, frames: usize) -> (PathBuf, PathBuf) {
    let dir = tmp(name);
    let root = dir.join("data");
    let spec = SyntheticSpec { subjects, trials, frames, seed: 7 };
    smocap::archive::synthetic::generate(&spec, &root).unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(
        &toml,
        "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\", \"*/walk*.c3d\"]\nsubject = \"{subject}/{trial}\"\nstatic = \"{subject}/static.trc\"\n",
    )
    .unwrap();
    (dir, toml)
}

fn statuses(rep: &Path) -> Vec<(String, String, String)> {
    report(rep)["trials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            let s = |k: &str| t[k].as_str().unwrap_or("").to_string();
            (s("trial"), s("status"), s("error"))
        })
        .collect()
}

/// Every message of a converted file reads, the file verifies, and its frames decode (protobuf
/// channels, through the reader `export` uses).
fn decodes_completely(path: &Path) {
    verify(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let buf = std::fs::read(path).unwrap();
    for msg in mcap::MessageStream::new(&buf).unwrap() {
        msg.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
    let rec = smocap::archive::export::read_trial_record(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(!rec.frames.is_empty(), "{}: no frames", path.display());
}

// 1. Concurrent runs, and --resume verifying what it skips.

#[test]
fn two_converts_into_one_out_never_interleave_and_every_output_decodes_completely() {
    let (dir, toml) = archive("concurrent", 1, 3, 150);
    let out = dir.join("out");
    let spawn = || {
        Command::new(env!("CARGO_BIN_EXE_smocap"))
            .args(["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--jobs", "2", "--quiet"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    let codes = [a.status.code(), b.status.code()];
    // At least one ran; one refused (when they overlapped) says why.
    assert!(codes.contains(&Some(0)), "{codes:?}\n{}\n{}", stderr(&a), stderr(&b));
    for o in [&a, &b] {
        if !o.status.success() {
            assert_eq!(o.status.code(), Some(1), "{}", stderr(o));
            assert!(stderr(o).contains("another smocap convert is writing into this folder"), "{}", stderr(o));
        }
    }
    let mcaps = files(&out, ".mcap");
    assert_eq!(mcaps.len(), 3);
    for m in &mcaps {
        decodes_completely(m);
    }
    assert!(files(&out, ".partial").is_empty());
}

/// `smocap convert <toml> --out <out> --shard <shard> --quiet`, spawned, its summary in `rep`.
fn spawn_shard(toml: &Path, out: &Path, shard: &str, rep: &Path) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_smocap"))
        .args(["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--jobs", "1", "--quiet"])
        .args(["--shard", shard, "--report-json", rep.to_str().unwrap()])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn different_shards_converting_into_one_out_at_once_both_succeed_with_their_own_summaries() {
    // A synthetic dataset generated inside --out: both shards find it generated once.
    let dir = tmp("shards-side-by-side");
    let toml = dir.join("datasets.toml");
    std::fs::write(&toml, "[[dataset]]\nname = \"syn\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\nstatic = \"{subject}/static.trc\"\nsynthetic = { subjects = 4, trials = 2, frames = 60, seed = 5 }\n")
        .unwrap();
    let out = dir.join("out");
    let reps = [dir.join("r0.json"), dir.join("r1.json")];
    let children = [spawn_shard(&toml, &out, "0/2", &reps[0]), spawn_shard(&toml, &out, "1/2", &reps[1])];
    let mut trials = Vec::new();
    for (c, rep) in children.into_iter().zip(&reps) {
        let o = c.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let r = report(rep);
        assert!(r["shard"].as_str().is_some_and(|s| s.ends_with("/2")), "{r}");
        trials.extend(statuses(rep).into_iter().map(|(t, st, _)| (t, st)));
    }
    trials.sort();
    let want: Vec<(String, String)> =
        (1..=4).flat_map(|s| (1..=2).map(move |k| (format!("subj{s:02}/walk{k:02}.trc"), "ok".to_string()))).collect();
    assert_eq!(trials, want);
    let mcaps = files(&out, ".mcap");
    assert_eq!(mcaps.len(), 8);
    for m in &mcaps {
        decodes_completely(m);
    }
    assert!(files(&out, ".partial").is_empty());
}

#[test]
fn two_runs_of_the_same_shard_never_interleave_and_every_output_decodes_completely() {
    let (dir, toml) = archive("same-shard", 2, 3, 150);
    let out = dir.join("out");
    let (ra, rb) = (dir.join("a.json"), dir.join("b.json"));
    let (a, b) = (spawn_shard(&toml, &out, "0/2", &ra), spawn_shard(&toml, &out, "0/2", &rb));
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    let codes = [a.status.code(), b.status.code()];
    assert!(codes.contains(&Some(0)), "{codes:?}\n{}\n{}", stderr(&a), stderr(&b));
    for o in [&a, &b] {
        if !o.status.success() {
            assert_eq!(o.status.code(), Some(1), "{}", stderr(o));
            assert!(stderr(o).contains("another smocap convert is writing into this folder"), "{}", stderr(o));
        }
    }
    let mcaps = files(&out, ".mcap");
    assert_eq!(mcaps.len(), 3, "{mcaps:?}");
    for m in &mcaps {
        decodes_completely(m);
    }
    assert!(files(&out, ".partial").is_empty());
}

#[test]
fn resume_redoes_an_output_whose_chunks_are_corrupt_though_its_summary_reads() {
    let (dir, toml) = archive("resume-corrupt", 1, 2, 60);
    let out = dir.join("out");
    let rep = dir.join("r.json");
    let run = |extra: &[&str]| {
        let mut args = vec!["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap()];
        args.extend(["--report-json", rep.to_str().unwrap(), "--quiet"]);
        args.extend_from_slice(extra);
        let o = smocap(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        statuses(&rep).into_iter().map(|t| t.1).collect::<Vec<_>>()
    };
    assert_eq!(run(&[]), ["ok", "ok"]);
    let path = out.join("lab/subj01/walk01.mcap");
    let mut bytes = std::fs::read(&path).unwrap();
    // Damage the middle of the data section (compressed chunk data): the summary at the end
    // still reads, so `inspect` alone calls the file fine.
    let mid = bytes.len() / 3;
    for b in &mut bytes[mid..mid + 64] {
        *b ^= 0x5a;
    }
    std::fs::write(&path, &bytes).unwrap();
    assert!(verify(&path).is_err(), "a damaged file does not verify");
    assert_eq!(run(&["--resume"]), ["ok", "skipped"]);
    decodes_completely(&path);
}

// 2. Output-path collisions.

#[test]
fn trials_that_differ_only_by_extension_fail_with_both_names_before_any_work() {
    let (dir, toml) = archive("collide", 1, 2, 30);
    let subj = dir.join("data/subj01");
    std::fs::copy(subj.join("walk01.trc"), subj.join("walk01.c3d")).unwrap();
    let out = dir.join("out");
    let rep = dir.join("r.json");
    let o = smocap(&[
        "convert",
        toml.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--report-json",
        rep.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let st = statuses(&rep);
    assert_eq!(st.len(), 3, "{st:?}");
    for t in st.iter().filter(|t| t.0.starts_with("subj01/walk01.")) {
        assert_eq!(t.1, "failed", "{st:?}");
        assert!(t.2.contains("collision") && t.2.contains("walk01.c3d") && t.2.contains("walk01.trc"), "{t:?}");
    }
    assert_eq!(st.iter().filter(|t| t.1 == "ok").count(), 1, "{st:?}");
    assert!(!out.join("lab/subj01/walk01.mcap").exists(), "nothing written at a contested path");
}

// 3. Dataset names and paths inside --out.

#[test]
fn a_dataset_name_with_dotdot_a_separator_or_an_absolute_path_is_refused() {
    let dir = tmp("names");
    for name in ["../escape", "/tmp/abs", "a/b", "..", ".", ".hidden", ""] {
        let toml = dir.join("d.toml");
        std::fs::write(&toml, format!("[[dataset]]\nname = \"{name}\"\nroot = \"data\"\ntrials = [\"*.trc\"]\n"))
            .unwrap();
        let e = read_datasets(&toml, None).unwrap_err().to_string();
        assert!(e.contains("name"), "{name}: {e}");
    }
    // Synthetic ones too (their generated trials would land outside --out).
    let toml = dir.join("s.toml");
    let escape = format!("smocap-escape-{}", std::process::id());
    std::fs::write(
        &toml,
        format!("[[dataset]]\nname = \"../../{escape}\"\ntrials = [\"*/walk*.trc\"]\nsynthetic = {{ subjects = 1, trials = 1, frames = 5 }}\n"),
    )
    .unwrap();
    let o = smocap(&["convert", toml.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(!dir.join(&escape).exists() && !dir.parent().unwrap().join(&escape).exists());
}

#[test]
fn every_output_path_is_checked_to_lie_inside_out() {
    use smocap::archive::convert::{inside, output_path};
    let out = Path::new("/data/out");
    assert!(inside(out, &output_path(out, "lab", "s1/walk.trc")));
    assert!(!inside(out, &output_path(out, "..", "walk.trc")));
    assert!(!inside(out, &output_path(out, "lab", "../../walk.trc")));
    assert!(!inside(out, &output_path(out, "/etc", "walk.trc")));
}

// 4. Discovery: link loops, FIFOs.

#[test]
fn discovery_does_not_follow_link_loops_or_open_fifos() {
    let (dir, toml) = archive("loops", 1, 1, 10);
    let subj = dir.join("data/subj01");
    std::os::unix::fs::symlink("..", subj.join("up")).unwrap();
    std::os::unix::fs::symlink("../subj01", subj.join("again")).unwrap();
    std::os::unix::fs::symlink(subj.join("walk01.trc"), subj.join("walk02.trc")).unwrap();
    assert!(Command::new("mkfifo").arg(subj.join("walk03.trc")).status().unwrap().success());
    let ds = read_datasets(&toml, None).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let root = dir.join("data");
    std::thread::spawn(move || {
        let _ = tx.send(
            smocap::archive::discover::discover(0, &ds[0], &root)
                .map(|g| g.iter().flat_map(|g| g.trials.iter().map(|t| t.rel.clone())).collect::<Vec<_>>()),
        );
    });
    let found = rx.recv_timeout(Duration::from_secs(60)).expect("discovery finishes").unwrap();
    // The file link is a trial; the folder links and the FIFO are not walked into or read.
    assert_eq!(found, ["subj01/walk01.trc", "subj01/walk02.trc"]);
}

// 5. Models with absurd body counts.

#[test]
fn a_model_with_twenty_thousand_bodies_is_refused_with_a_clear_error() {
    let mut xml = String::from("<mujoco><worldbody>");
    for i in 0..20_000 {
        xml += &format!("<body name=\"b{i}\"><site name=\"s{i}\"/></body>");
    }
    xml += "</worldbody></mujoco>";
    let e = smocap::io::mjcf::parse_mjcf(&xml, "big.xml").unwrap_err().to_string();
    assert!(e.contains("20000 bodies") && e.contains("at most 1000"), "{e}");
    let dir = tmp("bigmodel");
    std::fs::write(dir.join("big.xml"), &xml).unwrap();
    let (model, trc, truth) = (dir.join("big.xml"), dir.join("x.trc"), dir.join("x.json"));
    let o = smocap(&[
        "synth",
        "--model",
        model.to_str().unwrap(),
        "--out",
        trc.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("at most 1000"), "{}", stderr(&o));
}

// 6. Corrupt MCAP length fields.

/// Offsets of the top-level records of an MCAP file: (offset, opcode, body length).
fn records(buf: &[u8]) -> Vec<(usize, u8, usize)> {
    let mut out = Vec::new();
    let mut pos = 8;
    while pos + 9 <= buf.len() - 8 {
        let n = u64::from_le_bytes(buf[pos + 1..pos + 9].try_into().unwrap()) as usize;
        out.push((pos, buf[pos], n));
        pos += 9 + n;
    }
    out
}

#[test]
fn corrupt_mcap_lengths_are_errors_naming_the_record_not_aborts() {
    let (dir, toml) = archive("mcap-corrupt", 1, 1, 20);
    let out = dir.join("out");
    let o = smocap(&["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let good = std::fs::read(out.join("lab/subj01/walk01.mcap")).unwrap();
    let recs = records(&good);
    let bad = dir.join("bad.mcap");
    let csv = dir.join("x.csv");

    // A chunk claiming 2.3 EB uncompressed: `export` reads the chunks.
    let &(chunk, _, _) = recs.iter().find(|r| r.1 == 0x06).expect("a chunk");
    let mut b = good.clone();
    b[chunk + 9 + 16..chunk + 9 + 24].copy_from_slice(&0x2000_0000_0000_0000u64.to_le_bytes());
    std::fs::write(&bad, &b).unwrap();
    let o = smocap(&["export", bad.to_str().unwrap(), "--csv", csv.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("chunk record: uncompressed size"), "{}", stderr(&o));

    // A schema name length of 0xFFFFFFFF in the summary: `inspect` reads the summary.
    let &(schema, _, _) = recs.iter().rev().find(|r| r.1 == 0x03).expect("a schema in the summary");
    let mut b = good.clone();
    b[schema + 9 + 2..schema + 9 + 6].copy_from_slice(&u32::MAX.to_le_bytes());
    std::fs::write(&bad, &b).unwrap();
    let e = inspect(&bad).unwrap_err().to_string();
    assert!(e.contains("schema record: name needs 4294967295 bytes"), "{e}");

    // Truncated: says so.
    std::fs::write(&bad, &good[..good.len() / 2]).unwrap();
    let e = inspect(&bad).unwrap_err().to_string();
    assert!(e.contains("truncated"), "{e}");
}

// 7. Config and CLI ranges.

#[test]
fn absurd_synthetic_counts_shards_and_workers_are_errors_not_panics() {
    let dir = tmp("ranges");
    for spec in [
        "subjects = 1, trials = 18446744073709551615, frames = 10",
        "subjects = 1, trials = 1, frames = 1000000000",
        "subjects = 0, trials = 1, frames = 10",
        "subjects = 100000, trials = 1, frames = 10",
    ] {
        let toml = dir.join("d.toml");
        std::fs::write(
            &toml,
            format!("[[dataset]]\nname = \"s\"\ntrials = [\"*/walk*.trc\"]\nsynthetic = {{ {spec} }}\n"),
        )
        .unwrap();
        let e = read_datasets(&toml, None).unwrap_err().to_string();
        assert!(e.contains("synthetic"), "{spec}: {e}");
    }
    for s in ["0/18446744073709551615", "0/100000000000"] {
        let e = s.parse::<smocap::archive::shard::Shard>().unwrap_err().to_string();
        assert!(e.contains("at most"), "{s}: {e}");
    }
    let (_, toml) = archive("ranges-cli", 1, 1, 5);
    let o = smocap(&["convert", toml.to_str().unwrap(), "--shard", "0/18446744073709551615"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    // A summary claiming an absurd shard: a warning, not an allocation.
    let summary = dir.join("s.json");
    std::fs::write(&summary, r#"{"smocap_version":"x","shard":"0/100000000000","datasets":[],"trials":[{"dataset":"d","subject":"s","trial":"t","output":"o","status":"ok","frames":1,"solve_s":0.1}]}"#).unwrap();
    let o = smocap(&["merge-reports", summary.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("at most"), "{}", stderr(&o));
}

// 8. Garbage reported "ok".

/// A synthetic static + motion trial pair written as TRC (mm), the motion edited by `edit`
/// (positions in metres, frame-major).
fn garbage_trial(name: &str, edit: impl Fn(&mut smocap::io::MarkerTrial)) -> (PathBuf, PathBuf, PathBuf) {
    let (dir, _) = archive(name, 1, 1, 100);
    let subj = dir.join("data/subj01");
    let mut t = smocap::io::read_markers(&subj.join("walk01.trc")).unwrap();
    edit(&mut t);
    smocap::io::trc::write_trc(&subj.join("bad.trc"), &t, "mm").unwrap();
    (dir.clone(), subj.join("static.trc"), subj.join("bad.trc"))
}

fn solve_json(dir: &Path, stat: &Path, trial: &Path) -> (Output, serde_json::Value) {
    let rep = dir.join("solve.json");
    let o = smocap(&[
        "solve",
        "--static",
        stat.to_str().unwrap(),
        trial.to_str().unwrap(),
        "--report-json",
        rep.to_str().unwrap(),
        "--threads",
        "1",
    ]);
    let r = std::fs::read_to_string(&rep).ok().and_then(|t| serde_json::from_str(&t).ok()).unwrap_or_default();
    (o, r)
}

#[test]
fn a_trial_with_every_marker_missing_fails_instead_of_reporting_the_default_pose() {
    let (dir, stat, bad) = garbage_trial("all-missing", |t| t.positions.fill(f64::NAN));
    let (o, r) = solve_json(&dir, &stat, &bad);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert_eq!(r["trials"][0]["status"], "failed", "{r}");
    assert!(stderr(&o).contains("nothing to solve"), "{}", stderr(&o));
}

#[test]
fn a_marker_kilometres_away_is_masked_with_a_warning_and_the_report_holds_only_numbers() {
    for far_mm in [1e15, 1e308] {
        let (dir, stat, bad) = garbage_trial("far", |t| {
            let nm = t.n_markers();
            for f in 0..t.n_frames() {
                t.positions[f * nm * 3] = far_mm * 1e-3;
            }
        });
        let (o, r) = solve_json(&dir, &stat, &bad);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        assert!(stderr(&o).contains("masked as gaps"), "{}", stderr(&o));
        let t = &r["trials"][0];
        assert_eq!(t["status"], "ok", "{t}");
        assert!(t["marker_rmse_mm"]["p50"].as_f64().is_some_and(|x| x < 20.0), "{t}");
        assert!(t["frames_at_iteration_cap"].as_u64().unwrap() < 50, "{t}");
        // Statistics and scales are numbers (a non-finite one would be written as null).
        fn numbers(v: &serde_json::Value, key: &str) {
            match v {
                serde_json::Value::Object(m) => m.iter().for_each(|(k, x)| numbers(x, k)),
                serde_json::Value::Array(a) => a.iter().for_each(|x| numbers(x, key)),
                serde_json::Value::Null => {
                    assert!(!["mean", "p50", "p90", "scale", "scale_drift_max", "frames_per_s"].contains(&key), "{key}")
                }
                _ => {}
            }
        }
        numbers(&r, "");
    }
}

#[test]
fn a_garbage_trial_in_an_archive_counts_as_failed_in_the_exit_code() {
    let (dir, toml) = archive("garbage-convert", 1, 2, 40);
    let w2 = dir.join("data/subj01/walk02.trc");
    let mut t = smocap::io::read_markers(&w2).unwrap();
    t.positions.fill(f64::NAN);
    smocap::io::trc::write_trc(&w2, &t, "mm").unwrap();
    let rep = dir.join("r.json");
    let out = dir.join("out");
    let o = smocap(&[
        "convert",
        toml.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--report-json",
        rep.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let st = statuses(&rep);
    assert_eq!((st[0].1.as_str(), st[1].1.as_str()), ("ok", "failed"), "{st:?}");
    assert!(!out.join("lab/subj01/walk02.mcap").exists());
}

// 9. One exit-code scheme.

#[test]
fn convert_exits_1_when_nothing_could_run_and_3_only_when_some_trials_failed() {
    let (dir, _) = archive("exits", 1, 1, 20);
    let run = |body: &str, extra: &[&str]| {
        let toml = dir.join("x.toml");
        std::fs::write(&toml, body).unwrap();
        let out = dir.join("out");
        let mut args = vec!["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap()];
        args.extend_from_slice(extra);
        let o = smocap(&args);
        (o.status.code(), stderr(&o))
    };
    let ds = |trials: &str| {
        format!("[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [{trials}]\nstatic = \"{{subject}}/static.trc\"\nsubject = \"{{subject}}/{{trial}}\"\n")
    };
    // A bad glob.
    let (code, err) = run(&ds("\"[\""), &[]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("bad glob"), "{err}");
    // A glob matching nothing: a failure unless asked for.
    let (code, err) = run(&ds("\"*/nothing*.trc\""), &[]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("no trial found"), "{err}");
    assert_eq!(run(&ds("\"*/nothing*.trc\""), &["--allow-empty"]).0, Some(0));
    // Every trial failing: 1, as `solve` gives.
    std::fs::write(dir.join("data/subj01/walk09.c3d"), b"not a c3d").unwrap();
    let (code, err) = run(&ds("\"*/walk09.c3d\""), &[]);
    assert_eq!(code, Some(1), "{err}");
    // A synthetic dataset that cannot be generated.
    let (code, err) = run(
        "[[dataset]]\nname = \"s\"\nroot = \"/proc/forbidden\"\ntrials = [\"*/walk*.trc\"]\nsynthetic = { subjects = 1, trials = 1, frames = 5 }\n",
        &[],
    );
    assert_eq!(code, Some(1), "{err}");
}

// Smaller: output locations made before work.

#[test]
fn export_into_a_missing_folder_creates_it() {
    let (dir, toml) = archive("export-dir", 1, 1, 10);
    let out = dir.join("out");
    assert!(smocap(&["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]).status.success());
    let mot = dir.join("new/deeper/walk01.mot");
    let o = smocap(&["export", out.join("lab/subj01/walk01.mcap").to_str().unwrap(), "--mot", mot.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(mot.is_file());
}

#[test]
fn solve_finds_mot_name_clashes_and_creates_the_scaled_model_folder_before_solving() {
    let (dir, _) = archive("solve-outputs", 2, 1, 10);
    let (a, b) = (dir.join("data/subj01/walk01.trc"), dir.join("data/subj02/walk01.trc"));
    let o =
        smocap(&["solve", a.to_str().unwrap(), b.to_str().unwrap(), "--mot-dir", dir.join("mot").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("would both write"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("wrote"), "found before any .mot is written: {}", stderr(&o));
    let model = dir.join("new/folder/s.osim");
    let o = smocap(&["solve", a.to_str().unwrap(), "--scaled-model", model.to_str().unwrap(), "--threads", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(model.is_file());
}

#[test]
fn a_file_size_limit_fails_the_trial_and_leaves_no_temporary_file() {
    let (dir, toml) = archive("ulimit", 1, 1, 100);
    let out = dir.join("out");
    let cmd = format!(
        "ulimit -f 64 && exec '{}' convert '{}' --out '{}' --quiet",
        env!("CARGO_BIN_EXE_smocap"),
        toml.display(),
        out.display()
    );
    let o = Command::new("sh").arg("-c").arg(cmd).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "every trial failed: {}", stderr(&o));
    assert!(files(&out, ".partial").is_empty(), "{:?}", files(&out, ""));
    assert!(files(&out, ".mcap").is_empty());
}

#[test]
fn a_missing_trial_file_is_named_once_with_its_error_said_once() {
    let o = smocap(&["solve", "/nonexistent/walk.trc"]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    // The last `error:` line is smocap's (a Vulkan loader may print its own before it).
    let line = err.lines().rfind(|l| l.starts_with("error:")).unwrap_or("");
    assert_eq!(line.matches("No such file or directory").count(), 1, "{err}");
}

#[test]
fn a_trc_with_cr_only_line_endings_reads_as_with_lf() {
    let (dir, _) = archive("cr-only", 1, 1, 10);
    let text = std::fs::read_to_string(dir.join("data/subj01/walk01.trc")).unwrap();
    let lf = smocap::io::trc::parse_trc(&text, "lf.trc").unwrap();
    let cr = smocap::io::trc::parse_trc(&text.replace("\r\n", "\n").replace('\n', "\r"), "cr.trc").unwrap();
    assert_eq!((cr.labels, cr.times), (lf.labels, lf.times));
    assert_eq!(
        cr.positions.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        lf.positions.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
}

#[test]
fn markers_of_weight_zero_alone_leave_nothing_to_solve_and_the_trial_fails() {
    use smocap::kinematics::synth::{synthesize, SynthOptions};
    use smocap::pipeline::{calibrate_subject, solve_trial, Context, TrialError};
    let mut ctx = Context::shipped().unwrap();
    let s = synthesize(&ctx.model, &ctx.proxy, &SynthOptions { frames: 20, seed: 3, ..SynthOptions::default() });
    let cal = calibrate_subject(&ctx, &[("t", &s.trial)]).unwrap();
    // As an IK setup whose marker tasks all have weight 0.
    ctx.marker_weights.iter_mut().for_each(|w| *w = 0.0);
    let e = solve_trial(&ctx, "t", &s.trial, &cal, 1).unwrap_err();
    assert!(matches!(e, TrialError::NothingSolvable { .. }), "{e}");
}
