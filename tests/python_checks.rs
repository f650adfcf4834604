//! Converted files read by Python users' tools: `scripts/check_mcap.py` (the official `mcap`
//! readers and `mcap-protobuf-support` decode every message of every channel from the file's own
//! descriptors; Foxglove's messages match `foxglove-schemas-protobuf` field by field; every
//! `/tf` and `/robot/tf` is one tree rooted at `world`) on the synthetic archive (with `--robot g1`) and both shared OpenSim
//! datasets. (The NumPy/pandas recipe of docs/guide/python.md, `scripts/load_trial.py` on the
//! smocap Python package, is tested by `python/tests/test_load_trial.py`.)
//!
//! They run with the Python named by `SMOCAP_PYTHON` (`.ci/run` makes a venv with the pinned
//! packages); without it each test prints a note and passes.

use std::path::{Path, PathBuf};
use std::process::Command;

fn python() -> Option<String> {
    let p = std::env::var("SMOCAP_PYTHON").ok().filter(|p| !p.is_empty());
    if p.is_none() {
        eprintln!("note: SMOCAP_PYTHON not set; the Python checks of converted files are skipped");
    }
    p
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("smocap-python-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn convert(args: &[&str], out: &Path) {
    let o = Command::new(env!("CARGO_BIN_EXE_smocap"))
        .arg("convert")
        .args(args)
        .args(["--out", out.to_str().unwrap(), "-q"])
        .output()
        .unwrap();
    assert!(o.status.success(), "convert {args:?}: {}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn python_mcap_readers_decode_every_message_of_every_converted_channel() {
    let Some(py) = python() else { return };
    let dir = tmp("check");
    let toml = dir.join("datasets.toml");
    std::fs::write(
        &toml,
        "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\nstatic = \"{subject}/static.trc\"\nsynthetic = { subjects = 1, trials = 2, frames = 120, seed = 3 }\n",
    )
    .unwrap();
    let out = dir.join("out");
    // With the robot's channels (issue 31), which the readers check too.
    convert(&[toml.to_str().unwrap(), "--robot", "g1"], &out);
    let shipped = repo().join("datasets.toml");
    for d in ["gait2354_subject01", "rajagopal2016_walk"] {
        if repo().join("../shared/datasets").join(d).is_dir() {
            convert(&[shipped.to_str().unwrap(), "--dataset", d], &out);
        } else {
            eprintln!("note: ../shared/datasets/{d} not found; not checked");
        }
    }
    let o = Command::new(&py).arg(repo().join("scripts/check_mcap.py")).arg(&out).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    eprintln!("{text}");
    assert!(o.status.success(), "scripts/check_mcap.py found problems:\n{text}");
}
