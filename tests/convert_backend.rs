//! `smocap convert --backend` and `--lanes`: the CPU backend asked for gives the default's files;
//! `auto` without an adapter converts on the CPU and says so; `wgpu` without one fails before any
//! work; and a subject's trials solved together, their segments sharing the lanes of one
//! scheduler (any lane count, any window, any job count), give the same files, byte for byte, as
//! each trial solved alone.

use smocap::archive::config::SyntheticSpec;
use smocap::archive::inspect::recorded_run;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `smocap args`, with the Vulkan loader pointed at `icd` when given (a missing file hides every
/// adapter).
fn smocap(args: &[&str], icd: Option<&str>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_smocap"));
    cmd.args(args);
    if let Some(v) = icd {
        cmd.env("VK_ICD_FILENAMES", v).env("VK_DRIVER_FILES", v);
    }
    cmd.output().expect("run smocap")
}

const NO_ADAPTER: Option<&str> = Some("/nonexistent/icd.json");

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-convert-backend-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A synthetic archive of `subjects` × `trials` trials of `frames` frames, and its datasets.toml.
fn archive(name: &str, subjects: usize, trials: usize, frames: usize) -> (PathBuf, PathBuf) {
    let dir = tmp(name);
    let spec = SyntheticSpec { subjects, trials, frames, seed: 11 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(
        &toml,
        "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}\"\nstatic = \"{subject}/static.trc\"\n",
    )
    .unwrap();
    (dir, toml)
}

/// Every `.mcap` file under `dir` (relative path, bytes), sorted.
fn mcaps(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(PathBuf, Vec<u8>)>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(root, &p, out);
            } else if p.extension().is_some_and(|x| x == "mcap") {
                out.push((p.strip_prefix(root).unwrap().to_path_buf(), std::fs::read(&p).unwrap()));
            }
        }
    }
    let mut out = Vec::new();
    if dir.is_dir() {
        walk(dir, dir, &mut out);
    }
    out.sort();
    out
}

/// Converts `toml` into `dir/out-<tag>` with `extra` arguments; the files written.
fn convert(dir: &Path, toml: &Path, tag: &str, extra: &[&str], icd: Option<&str>) -> (Output, Vec<(PathBuf, Vec<u8>)>) {
    let out = dir.join(format!("out-{tag}"));
    let mut args = vec!["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"];
    args.extend_from_slice(extra);
    let o = smocap(&args, icd);
    (o, mcaps(&out))
}

/// The files differ: which ones.
fn differ(a: &[(PathBuf, Vec<u8>)], b: &[(PathBuf, Vec<u8>)]) -> Vec<String> {
    assert_eq!(a.iter().map(|f| &f.0).collect::<Vec<_>>(), b.iter().map(|f| &f.0).collect::<Vec<_>>());
    a.iter().zip(b).filter(|(x, y)| x.1 != y.1).map(|(x, _)| x.0.display().to_string()).collect()
}

#[test]
fn convert_backend_cpu_writes_the_default_files_and_auto_without_an_adapter_converts_on_the_cpu_saying_so() {
    let (dir, toml) = archive("cpu-auto", 1, 2, 120);
    let (o, default) = convert(&dir, &toml, "default", &[], None);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(default.len(), 2);
    let (o, cpu) = convert(&dir, &toml, "cpu", &["--backend", "cpu"], None);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(differ(&default, &cpu).is_empty(), "--backend cpu changed the files: {:?}", differ(&default, &cpu));
    let (o, auto) = convert(&dir, &toml, "auto", &["--backend", "auto"], NO_ADAPTER);
    assert!(o.status.success(), "auto without an adapter must fall back: {}", stderr(&o));
    assert!(stderr(&o).contains("using the CPU backend"), "auto says why, even with -q: {}", stderr(&o));
    assert!(differ(&default, &auto).is_empty(), "auto on the CPU changed the files");
    let run = recorded_run(&dir.join("out-auto/lab/subj01/walk01.mcap")).expect("run metadata");
    assert_eq!((run["backend"].as_str(), run["adapter"].as_str()), ("cpu", "cpu"));
}

#[test]
fn convert_backend_wgpu_without_an_adapter_fails_clearly_before_any_work() {
    let (dir, toml) = archive("wgpu-none", 1, 1, 30);
    for backend in ["wgpu", "wgpu-f64"] {
        let (o, files) = convert(&dir, &toml, backend, &["--backend", backend], NO_ADAPTER);
        assert!(!o.status.success(), "--backend {backend} without an adapter must fail");
        assert_eq!(o.status.code(), Some(1));
        let e = stderr(&o);
        assert!(e.contains("no wgpu adapter") && e.contains(backend), "the error says what is missing: {e}");
        assert!(!e.contains("panicked"), "{e}");
        assert!(files.is_empty(), "nothing converted");
    }
}

#[test]
fn trials_solved_together_sharing_lanes_give_the_files_of_trials_solved_alone() {
    // Three trials of 430 frames: two segments each (of 215 frames, the second walked from 20
    // frames before it), so lanes take segments of several trials in one round; windows of 150
    // frames read each trial in two steps, every trial's windows of a step solved together.
    let (dir, toml) = archive("lanes", 1, 3, 430);
    let (o, alone) = convert(&dir, &toml, "alone", &[], None);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(alone.len(), 3);
    for (tag, extra) in [
        ("lanes1", &["--lanes", "1"][..]),
        ("lanes4", &["--lanes", "4", "--jobs", "1"][..]),
        ("lanes4-jobs2", &["--lanes", "4", "--jobs", "2"][..]),
        ("lanes64", &["--lanes", "64"][..]),
        ("lanes5-window150", &["--lanes", "5", "--window-frames", "150"][..]),
    ] {
        let (o, together) = convert(&dir, &toml, tag, extra, None);
        assert!(o.status.success(), "{tag}: {}", stderr(&o));
        assert!(differ(&alone, &together).is_empty(), "{tag} changed {:?}", differ(&alone, &together));
    }
}

#[test]
fn convert_backend_wgpu_solves_trials_together_on_whatever_adapter_exists() {
    if smocap::kinematics::gpu::list_adapters().is_empty() {
        println!("skipped: no wgpu adapter");
        return;
    }
    let (dir, toml) = archive("wgpu", 1, 2, 230);
    let (o, few) = convert(&dir, &toml, "wgpu-lanes1", &["--backend", "wgpu", "--lanes", "1"], None);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(few.len(), 2);
    let report = dir.join("wgpu.json");
    let (o, many) =
        convert(&dir, &toml, "wgpu", &["--backend", "wgpu", "--report-json", report.to_str().unwrap()], None);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(differ(&few, &many).is_empty(), "the lane count changed {:?}", differ(&few, &many));
    let run = recorded_run(&dir.join("out-wgpu/lab/subj01/walk01.mcap")).expect("run metadata");
    assert_eq!(run["backend"], "wgpu");
    assert_ne!(run["adapter"], "cpu", "the adapter is named");
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("wgpu.json")).unwrap()).unwrap();
    let summary = rep["trials"][0]["backend"].as_str().unwrap();
    assert_eq!(summary, format!("wgpu: {}", run["adapter"]), "the summary names the backend too");
}

#[test]
fn a_trial_failing_mid_stream_among_trials_solved_together_fails_alone() {
    // walk01 (2000 frames) outgrows the file-size limit mid-way; walk02 (its first 30 frames)
    // fits, and is solved in the same batch (64 lanes hold both trials' segments).
    let (dir, toml) = archive("midway", 1, 1, 2000);
    let subj = dir.join("data/subj01");
    let t = smocap::io::read_markers(&subj.join("walk01.trc")).unwrap();
    smocap::io::trc::write_trc(&subj.join("walk02.trc"), &t.select_frames(0..30), "mm").unwrap();
    let out = dir.join("out");
    let rep = dir.join("report.json");
    // SIGXFSZ ignored (kept across exec), so writes past the limit fail with EFBIG.
    let o = Command::new("sh")
        .args(["-c", "trap '' XFSZ; ulimit -f 256; exec \"$0\" \"$@\"", env!("CARGO_BIN_EXE_smocap"), "convert"])
        .args([toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--report-json", rep.to_str().unwrap()])
        .args(["--lanes", "64", "-q"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(3), "one trial failed, one converted: {}", stderr(&o));
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    let (t1, t2) = (&r["trials"][0], &r["trials"][1]);
    assert_eq!((&t1["trial"], &t1["status"]), (&"subj01/walk01.trc".into(), &"failed".into()), "{r}");
    assert!(t1["error"].as_str().unwrap().contains("too large"), "{r}");
    assert_eq!((&t2["status"], &t2["frames"], &t2["backend"]), (&"ok".into(), &30.into(), &"cpu".into()), "{r}");
    let files: Vec<PathBuf> = mcaps(&out).into_iter().map(|f| f.0).collect();
    assert_eq!(files, [PathBuf::from("lab/subj01/walk02.mcap")]);
    assert!(!stderr(&o).contains("panicked"));
}
