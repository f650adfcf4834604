//! `smocap convert` killed mid-way (SIGKILL) and then run again with `--resume` ends with every
//! trial converted, no temporary file left, and outputs identical to an uninterrupted run.
//!
//! "Identical" (CPU backend) is checked by [`assert_same_content`]: both files are read with the
//! `mcap` crate and compared record by record: every message in file order (its channel's topic,
//! message encoding and metadata; its schema's name, encoding and bytes; sequence, log time,
//! publish time and data bytes), every metadata record (name and all key/value pairs) and every
//! attachment (name, media type, log and create times, data bytes), and the header (profile,
//! library). Files are written without per-frame timings (no `--timings`), so the files are also
//! compared byte for byte.

use smocap::archive::config::SyntheticSpec;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-kill-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every file under `dir`, sorted.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd {
            let p = e.unwrap().path();
            if p.is_dir() {
                out.extend(files(&p));
            } else {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

fn ends(p: &Path, suffix: &str) -> bool {
    p.to_string_lossy().ends_with(suffix)
}

/// What a file holds, in order (see the module docs).
fn content(path: &Path) -> Vec<String> {
    let buf = std::fs::read(path).unwrap();
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(&buf).unwrap() {
        let m = m.unwrap();
        let c = &m.channel;
        let schema = c.schema.as_ref().map(|s| (s.name.clone(), s.encoding.clone(), s.data.to_vec()));
        let data = m.data.to_vec();
        out.push(format!(
            "{} {} {:?} {:?} {} {} {} {:?}",
            c.topic, c.message_encoding, c.metadata, schema, m.sequence, m.log_time, m.publish_time, data
        ));
    }
    let summary = mcap::Summary::read(&buf).unwrap().expect("a summary section");
    for idx in &summary.metadata_indexes {
        let m = mcap::read::metadata(&buf, idx).unwrap();
        out.push(format!("metadata {} {:?}", m.name, m.metadata));
    }
    for idx in &summary.attachment_indexes {
        let a = mcap::read::attachment(&buf, idx).unwrap();
        out.push(format!("attachment {} {} {} {} {:?}", a.name, a.media_type, a.log_time, a.create_time, a.data));
    }
    let header = mcap::read::LinearReader::new(&buf)
        .unwrap()
        .find_map(|r| match r.unwrap() {
            mcap::records::Record::Header(h) => Some(h),
            _ => None,
        })
        .unwrap();
    out.push(format!("header {} {}", header.profile, header.library));
    out
}

/// Asserts that `a` and `b` hold the same content (see the module docs).
fn assert_same_content(a: &Path, b: &Path) {
    let (ca, cb) = (content(a), content(b));
    assert_eq!(ca.len(), cb.len(), "{} vs {}", a.display(), b.display());
    for (i, (x, y)) in ca.iter().zip(&cb).enumerate() {
        assert!(x == y, "{} vs {}: record {i} differs", a.display(), b.display());
    }
    assert!(std::fs::read(a).unwrap() == std::fs::read(b).unwrap(), "{} vs {}: bytes differ", a.display(), b.display());
}

fn convert(toml: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_smocap"));
    c.args(["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap()]).args(extra);
    c.stdout(std::process::Stdio::null()).stderr(std::process::Stdio::null());
    c
}

#[test]
fn a_killed_run_resumed_ends_complete_and_identical_to_an_uninterrupted_one() {
    let dir = tmp("kill");
    let (subjects, trials, frames) = (2, 6, 40);
    let spec = SyntheticSpec { subjects, trials, frames, seed: 3 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(
        &toml,
        "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\nstatic = \"{subject}/static.trc\"\n",
    )
    .unwrap();
    let total = subjects * trials;

    // Killed as soon as its first output appears (one worker, so the others are still to come).
    let killed = dir.join("killed");
    let mut child = convert(&toml, &killed, &["--jobs", "1"]).spawn().unwrap();
    let start = Instant::now();
    while !files(&killed.join("lab")).iter().any(|p| ends(p, ".mcap")) {
        assert!(child.try_wait().unwrap().is_none(), "the run ended before any output appeared");
        assert!(start.elapsed() < Duration::from_secs(120), "no output after 120 s");
        std::thread::sleep(Duration::from_millis(2));
    }
    let running = child.try_wait().unwrap().is_none();
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(running, "the run ended before it could be killed");
    let left = files(&killed.join("lab"));
    let done: Vec<&PathBuf> = left.iter().filter(|p| ends(p, ".mcap")).collect();
    assert!(!done.is_empty() && done.len() < total, "{left:?}");
    // Anything else is a temporary file; nothing partial carries a final name.
    assert!(left.iter().all(|p| ends(p, ".mcap") || ends(p, ".mcap.partial")), "{left:?}");

    // The uninterrupted run, then the resumed one.
    let reference = dir.join("reference");
    assert!(convert(&toml, &reference, &["--jobs", "2"]).status().unwrap().success());
    let rep = dir.join("resume.json");
    let resumed =
        convert(&toml, &killed, &["--resume", "--jobs", "2", "--report-json", rep.to_str().unwrap()]).status().unwrap();
    assert!(resumed.success());
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    let skipped = r["trials"].as_array().unwrap().iter().filter(|t| t["status"] == "skipped").count();
    assert_eq!(skipped, done.len(), "the finished trials are kept");

    let a = files(&killed.join("lab"));
    let b = files(&reference.join("lab"));
    assert_eq!(a.len(), total, "every trial converted, no temporary file left: {a:?}");
    assert!(a.iter().all(|p| ends(p, ".mcap")));
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.strip_prefix(&killed).unwrap(), y.strip_prefix(&reference).unwrap());
        assert_same_content(x, y);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
