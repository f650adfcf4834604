//! `smocap convert` end to end: the shipped datasets.toml's synthetic dataset to MCAP files that
//! read back (schemas, counts, run metadata), faulty trials reported while the others convert,
//! shards that cover every trial once, and `--resume`.

use smocap::archive::config::{read_datasets, SyntheticSpec};
use smocap::archive::discover::{discover, match_pattern};
use smocap::archive::inspect::inspect;
use smocap::archive::shard::{assign, Shard};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn smocap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().expect("run smocap")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-convert-{}-{name}", std::process::id()));
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
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
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

#[test]
fn shipped_synthetic_dataset_converts_to_mcap_that_reads_back() {
    let out = tmp("shipped");
    let toml = concat!(env!("CARGO_MANIFEST_DIR"), "/datasets.toml");
    let rep = out.join("report.json");
    let o = smocap(&[
        "convert",
        toml,
        "--dataset",
        "synthetic",
        "--out",
        out.to_str().unwrap(),
        "--report-json",
        rep.to_str().unwrap(),
        "--jobs",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&rep);
    let trials = r["trials"].as_array().unwrap();
    assert_eq!(trials.len(), 4, "{r}");
    assert!(trials.iter().all(|t| t["status"] == "ok"), "{r}");
    let mcaps = files(&out.join("synthetic"), ".mcap");
    assert_eq!(mcaps.len(), 4);
    assert!(files(&out, ".partial").is_empty());
    assert!(mcaps[0].ends_with("synthetic/subj01/walk01.mcap"), "{mcaps:?}");
    for (m, t) in mcaps.iter().zip(trials) {
        let info = inspect(m).unwrap();
        let frames = t["frames"].as_u64().unwrap();
        assert_eq!(frames, 100);
        let schema = |topic: &str| info.channels.iter().find(|c| c.topic == topic).unwrap_or_else(|| panic!("{topic}"));
        for (topic, name, n) in [
            ("/smocap/state", "smocap.State", frames),
            ("/smocap/stats", "smocap.SolverStats", frames),
            ("/tf", "foxglove.FrameTransforms", frames),
            ("/markers", "foxglove.PointCloud", frames),
            ("/scene", "foxglove.SceneUpdate", 1),
            ("/smocap/subject", "smocap.Subject", 1),
            ("/smocap/label_qc", "smocap.LabelQc", 1),
        ] {
            let c = schema(topic);
            assert_eq!((c.schema.as_str(), c.encoding.as_str(), c.messages), (name, "protobuf", n), "{topic}");
        }
        let run = &info.metadata["smocap.run"];
        let input = out.join(".synthetic/synthetic").join(t["trial"].as_str().unwrap());
        assert_eq!(run["input_sha256"], smocap::archive::sha256_hex(&std::fs::read(&input).unwrap()));
        assert_eq!(run["backend"], "cpu");
        let names: Vec<&str> = info.attachments.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["settings.json", "scaled_model.osim.zst"]);
        // Every message decodes; the state has every coordinate.
        let buf = std::fs::read(m).unwrap();
        let mut n = 0;
        for msg in mcap::MessageStream::new(&buf).unwrap() {
            let msg = msg.unwrap();
            use prost::Message;
            use smocap::archive::proto;
            match msg.channel.topic.as_str() {
                "/smocap/state" => assert!(proto::State::decode(&msg.data[..]).unwrap().q.len() > 10),
                "/smocap/stats" => drop(proto::SolverStats::decode(&msg.data[..]).unwrap()),
                "/smocap/subject" => {
                    assert!(proto::Subject::decode(&msg.data[..]).unwrap().bodies.contains(&"pelvis".into()))
                }
                "/tf" => drop(proto::FrameTransforms::decode(&msg.data[..]).unwrap()),
                "/markers" => drop(proto::PointCloud::decode(&msg.data[..]).unwrap()),
                "/scene" => drop(proto::SceneUpdate::decode(&msg.data[..]).unwrap()),
                "/smocap/label_qc" => drop(proto::LabelQc::decode(&msg.data[..]).unwrap()),
                t => panic!("unexpected topic {t}"),
            }
            n += 1;
        }
        assert_eq!(n, 4 * frames + 3);
    }
    // inspect on the command line.
    let o = smocap(&["inspect", mcaps[0].to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("foxglove.FrameTransforms") && text.contains("input_sha256"), "{text}");
}

#[test]
fn faulty_trials_are_reported_and_the_others_convert() {
    let (dir, toml) = archive("faults", 1, 1, 30);
    let subj = dir.join("data/subj01");
    let good = std::fs::read_to_string(subj.join("walk01.trc")).unwrap();
    // A truncated C3D: a header that stops after a few bytes.
    std::fs::write(subj.join("walk02.c3d"), [0x02u8, 0x50, 0x01, 0x00, 0x0a]).unwrap();
    // A TRC with garbage rows.
    let mut lines: Vec<String> = good.lines().map(String::from).collect();
    lines[10] = "garbage\trow\there".into();
    std::fs::write(subj.join("walk03.trc"), lines.join("\n") + "\n").unwrap();
    // A TRC whose markers match nothing in the model.
    let mut t = smocap::io::read_markers(&subj.join("walk01.trc")).unwrap();
    t.labels = (0..t.labels.len()).map(|i| format!("junk{i}")).collect();
    smocap::io::trc::write_trc(&subj.join("walk04.trc"), &t, "mm").unwrap();

    let out = dir.join("out");
    let rep = dir.join("report.json");
    let o = smocap(&[
        "convert",
        toml.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--report-json",
        rep.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let r = report(&rep);
    let status: Vec<(String, String, String)> = r["trials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            let s = |k: &str| t[k].as_str().unwrap_or("").to_string();
            (s("trial"), s("status"), s("error"))
        })
        .collect();
    assert_eq!(status.len(), 4, "{status:?}");
    assert_eq!(status[0].1, "ok", "{status:?}");
    for (i, needle) in [(1, "walk02.c3d"), (2, ":11: column"), (3, "none of its markers")] {
        assert_eq!(status[i].1, "failed", "{status:?}");
        assert!(status[i].2.contains(needle), "{:?} should mention {needle}", status[i]);
    }
    assert_eq!(files(&out, ".mcap").len(), 1);
    assert!(files(&out, ".partial").is_empty());
    assert!(!stderr(&o).contains("panicked"));
}

#[test]
fn shards_cover_every_trial_exactly_once_with_subjects_whole() {
    let (_dir, toml) = archive("shards", 7, 2, 5);
    let ds = read_datasets(&toml, None).unwrap();
    let groups = discover(0, &ds[0], ds[0].root.as_ref().unwrap()).unwrap();
    assert_eq!(groups.len(), 7);
    assert!(groups.iter().all(|g| g.trials.len() == 2 && g.static_trial.is_some()));
    for n in 1..=5 {
        let owner = assign(&groups, n);
        assert_eq!(owner, assign(&groups, n), "deterministic");
        let mut seen = Vec::new();
        for i in 0..n {
            for (g, _) in groups.iter().zip(&owner).filter(|(_, &o)| o == i) {
                seen.extend(g.trials.iter().map(|t| t.rel.clone()));
            }
        }
        seen.sort();
        let mut all: Vec<String> = groups.iter().flat_map(|g| g.trials.iter().map(|t| t.rel.clone())).collect();
        all.sort();
        assert_eq!(seen, all, "{n} shards");
        // Equal subjects: shard sizes differ by at most one subject.
        let counts: Vec<usize> = (0..n).map(|i| owner.iter().filter(|&&o| o == i).count()).collect();
        assert!(counts.iter().max().unwrap() - counts.iter().min().unwrap() <= 1, "{counts:?}");
    }
    assert_eq!("2/4".parse::<Shard>().unwrap(), Shard { index: 2, count: 4 });
    assert!("4/4".parse::<Shard>().is_err() && "x".parse::<Shard>().is_err());
    let env = |pairs: &'static [(&'static str, &'static str)]| {
        move |k: &str| pairs.iter().find(|(a, _)| *a == k).map(|(_, v)| v.to_string())
    };
    let slurm = Shard::from_env(env(&[("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_COUNT", "5")])).unwrap();
    assert_eq!(slurm, Some(Shard { index: 3, count: 5 }));
    let k8s = Shard::from_env(env(&[("JOB_COMPLETION_INDEX", "1"), ("SMOCAP_SHARD_COUNT", "2")])).unwrap();
    assert_eq!(k8s, Some(Shard { index: 1, count: 2 }));
    assert_eq!(Shard::from_env(env(&[])).unwrap(), None);
}

#[test]
fn sharded_runs_together_convert_every_trial_once() {
    let (dir, toml) = archive("shardrun", 3, 1, 20);
    let out = dir.join("out");
    let mut seen = Vec::new();
    for i in 0..2 {
        let rep = dir.join(format!("r{i}.json"));
        let shard = format!("{i}/2");
        let o = smocap(&[
            "convert",
            toml.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--shard",
            &shard,
            "--report-json",
            rep.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        seen.extend(
            report(&rep)["trials"].as_array().unwrap().iter().map(|t| t["trial"].as_str().unwrap().to_string()),
        );
    }
    seen.sort();
    assert_eq!(seen, ["subj01/walk01.trc", "subj02/walk01.trc", "subj03/walk01.trc"]);
    assert_eq!(files(&out, ".mcap").len(), 3);
}

#[test]
fn resume_skips_done_trials_and_redoes_missing_or_changed_ones() {
    let (dir, toml) = archive("resume", 1, 3, 20);
    let out = dir.join("out");
    let run = |extra: &[&str]| {
        let rep = dir.join("r.json");
        let mut args = vec![
            "convert",
            toml.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--report-json",
            rep.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = smocap(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let r = report(&rep);
        r["trials"].as_array().unwrap().iter().map(|t| t["status"].as_str().unwrap().to_string()).collect::<Vec<_>>()
    };
    assert_eq!(run(&[]), ["ok", "ok", "ok"]);
    let first = std::fs::read(out.join("lab/subj01/walk01.mcap")).unwrap();
    // Interrupted state: one output missing, a stale temporary file, one input changed.
    std::fs::remove_file(out.join("lab/subj01/walk02.mcap")).unwrap();
    std::fs::write(out.join("lab/subj01/walk01.mcap.partial"), b"half").unwrap();
    let w3 = dir.join("data/subj01/walk03.trc");
    let text = std::fs::read_to_string(&w3).unwrap();
    std::fs::write(&w3, text.replacen("\n", " \n", 1)).unwrap();
    assert_eq!(run(&["--resume"]), ["skipped", "ok", "ok"]);
    assert_eq!(std::fs::read(out.join("lab/subj01/walk01.mcap")).unwrap(), first, "skipped output untouched");
    assert!(files(&out, ".partial").is_empty());
    assert_eq!(run(&["--resume"]), ["skipped", "skipped", "skipped"]);
}

#[test]
fn subject_patterns_read_subject_and_trial_from_paths() {
    let v = match_pattern("{subject}/{trial}.c3d", "S01/walk_1.c3d").unwrap();
    assert_eq!((v["subject"].as_str(), v["trial"].as_str()), ("S01", "walk_1"));
    let v = match_pattern("{subject}_{trial}.trc", "subject01_walk1.trc").unwrap();
    assert_eq!((v["subject"].as_str(), v["trial"].as_str()), ("subject01", "walk1"));
    assert!(match_pattern("{subject}/{trial}.c3d", "a/b/c.c3d").is_none());
    assert!(match_pattern("{subject}/{trial}.c3d", "S01/walk.trc").is_none());
}

#[test]
fn shipped_datasets_toml_parses_and_resolves_paths_against_its_folder() {
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/datasets.toml"));
    let ds = read_datasets(path, None).unwrap();
    let names: Vec<&str> = ds.iter().map(|d| d.name.as_str()).collect();
    assert_eq!(names, ["synthetic", "gait2354_subject01", "rajagopal2016_walk"]);
    assert!(ds[1].model.as_ref().unwrap().starts_with(env!("CARGO_MANIFEST_DIR")));
    let err = read_datasets(path, Some("nope")).unwrap_err().to_string();
    assert!(err.contains("synthetic, gait2354_subject01"), "{err}");
}

/// The `smocap.run` metadata and the `settings.json` attachment of a converted trial.
fn run_and_settings(path: &Path) -> (std::collections::BTreeMap<String, String>, serde_json::Value) {
    let buf = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&buf).unwrap().unwrap();
    let run = mcap::read::metadata(&buf, &summary.metadata_indexes[0]).unwrap().metadata;
    let idx = summary.attachment_indexes.iter().find(|a| a.name == "settings.json").unwrap();
    let settings = serde_json::from_slice(&mcap::read::attachment(&buf, idx).unwrap().data).unwrap();
    (run, settings)
}

#[test]
fn datasets_toml_rate_and_settings_override_the_files_and_the_defaults_and_are_recorded() {
    let (dir, toml) = archive("overrides", 1, 1, 20);
    let text = std::fs::read_to_string(&toml).unwrap();
    std::fs::write(&toml, text + "rate = 50.0\nsettings = { max_iterations = 2, min_markers = 4 }\n").unwrap();
    let ds = read_datasets(&toml, None).unwrap();
    assert_eq!(ds[0].rate, Some(50.0));
    let out = dir.join("out");
    let o = smocap(&["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mcap_path = out.join("lab/subj01/walk01.mcap");
    let (run, settings) = run_and_settings(&mcap_path);
    assert_eq!((run["rate_hz"].as_str(), run["rate_source"].as_str()), ("50", "datasets.toml"));
    let overrides: serde_json::Value = serde_json::from_str(&run["settings_overrides"]).unwrap();
    assert_eq!(overrides, serde_json::json!({"max_iterations": 2, "min_markers": 4}));
    assert_eq!((settings["max_iterations"].as_u64(), settings["min_markers"].as_u64()), (Some(2), Some(4)));
    assert_eq!(settings["residual_tol_m"].as_f64(), Some(1e-6), "other settings keep their defaults");
    // Frame times follow the overriding rate (the files say 100 Hz); the solver kept to its cap.
    let buf = std::fs::read(&mcap_path).unwrap();
    let mut n = 0;
    for m in mcap::MessageStream::new(&buf).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == "/smocap/stats" {
            use prost::Message;
            let v = smocap::archive::proto::SolverStats::decode(&m.data[..]).unwrap();
            let f = v.frame as u64;
            let epoch = smocap::archive::mcap_out::DEFAULT_EPOCH_NS;
            assert_eq!(m.log_time, epoch + f * 20_000_000, "frame {f} at 50 Hz");
            assert!(v.iterations <= 2, "{v:?}");
            n += 1;
        }
    }
    assert_eq!(n, 20);
    // Without overrides: the file's rate, no overrides recorded.
    let (dir2, toml2) = archive("no-overrides", 1, 1, 20);
    let out2 = dir2.join("out");
    assert!(smocap(&["convert", toml2.to_str().unwrap(), "--out", out2.to_str().unwrap()]).status.success());
    let (run2, settings2) = run_and_settings(&out2.join("lab/subj01/walk01.mcap"));
    assert_eq!((run2["rate_hz"].as_str(), run2["rate_source"].as_str()), ("100", "file"));
    assert_eq!(run2["settings_overrides"], "{}");
    assert_eq!(settings2["max_iterations"].as_u64(), Some(20));
}

#[test]
fn bad_overrides_in_datasets_toml_are_clear_errors() {
    let (_dir, toml) = archive("bad-overrides", 1, 1, 5);
    let text = std::fs::read_to_string(&toml).unwrap();
    let err = |extra: &str| {
        std::fs::write(&toml, text.clone() + extra).unwrap();
        read_datasets(&toml, None).unwrap_err().to_string()
    };
    let e = err("settings = { max_iter = 3 }\n");
    assert!(e.contains("max_iter`") && e.contains("max_iterations") && e.contains("'lab'"), "{e}");
    let e = err("settings = { max_iterations = \"many\" }\n");
    assert!(e.contains("max_iterations"), "{e}");
    let e = err("rate = 0.0\n");
    assert!(e.contains("rate"), "{e}");
}

/// A trial whose output fails mid-way (the process may write files of ~0.5 MB at most, and the
/// trial's file is ~3 MB: "file too large" once a chunk past the limit is flushed) leaves no
/// file with its final name and no temporary file, and is reported failed with the frame it
/// stopped at.
#[cfg(target_os = "linux")]
#[test]
fn a_trial_failing_mid_stream_leaves_no_output_and_is_reported_failed() {
    let (dir, toml) = archive("midway", 1, 1, 2000);
    let out = dir.join("out");
    let rep = dir.join("report.json");
    // SIGXFSZ ignored (kept across exec), so writes past the limit fail with EFBIG.
    let o = Command::new("sh")
        .args(["-c", "trap '' XFSZ; ulimit -f 256; exec \"$0\" \"$@\"", env!("CARGO_BIN_EXE_smocap"), "convert"])
        .args([toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--report-json", rep.to_str().unwrap()])
        .output()
        .unwrap();
    // Its only trial failed: nothing could run (exit 1, as `solve` gives).
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let r = report(&rep);
    let t = &r["trials"][0];
    assert_eq!(t["status"], "failed", "{r}");
    let e = t["error"].as_str().unwrap();
    let frame: usize =
        e.split("frame ").nth(1).and_then(|s| s.split(':').next()).and_then(|s| s.parse().ok()).unwrap_or(0);
    assert!(frame > 0 && frame < 1999, "failed mid-way: {e}");
    assert!(e.contains("too large"), "{e}");
    assert!(!out.join("lab/subj01/walk01.mcap").exists());
    assert!(files(&out, ".partial").is_empty(), "temporary file removed");
    assert!(files(&out, ".mcap").is_empty());
}

#[test]
fn long_trials_read_a_window_at_a_time_convert_to_the_same_bytes_as_trials_held_whole() {
    // 700 frames (static trial too): with windows of 150 frames, calibration, the convention
    // checks, the solve (segments of ~230 frames, their run-ins, the `auto` re-solve) and the
    // writer all read the files a window at a time.
    let (dir, toml) = archive("windows", 1, 1, 700);
    let mut outs = Vec::new();
    for window in ["150", "100000"] {
        let out = dir.join(format!("out-{window}"));
        let o = smocap(&[
            "convert",
            toml.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--window-frames",
            window,
            "-q",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let mcaps = files(&out, ".mcap");
        assert_eq!(mcaps.len(), 1, "{mcaps:?}");
        outs.push(std::fs::read(&mcaps[0]).unwrap());
    }
    assert!(outs[0] == outs[1], "the window size changed the output");
}
