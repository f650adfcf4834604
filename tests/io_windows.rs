//! Marker files read a window at a time ([`smocap::io::MarkerFile`]) give the frames the whole
//! file gives, for TRC (line endings, gaps, a BOM) and C3D (integer and float storage).

use smocap::io::{read_markers, MarkerFile};
use std::path::{Path, PathBuf};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("smocap-io-windows-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// NaN-aware equality of two position arrays.
fn same(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// Every window (several sizes, unaligned starts) of `path` read on demand equals the same
/// frames of the whole file, and the file opened with a larger `keep` holds them all.
fn windows_match_the_whole_file(path: &Path) {
    let whole = read_markers(path).unwrap();
    let n = whole.n_frames();
    let w = whole.n_markers() * 3;
    assert!(n > 10, "{}: {n} frames", path.display());
    let held = MarkerFile::open(path, n).unwrap();
    assert!(held.held());
    assert!(same(&held.trial.positions, &whole.positions));
    let lazy = MarkerFile::open(path, n / 3).unwrap();
    assert!(!lazy.held(), "more frames than kept are not held");
    assert!(lazy.trial.positions.is_empty());
    assert_eq!(lazy.trial.times, whole.times);
    assert_eq!(lazy.trial.frame_numbers, whole.frame_numbers);
    assert_eq!(lazy.trial.labels, whole.labels);
    for size in [1, 7, n / 2, n] {
        for start in [0, 1, n / 3, n - size.min(n)] {
            let r = start..(start + size).min(n);
            let got = lazy.read(r.clone()).unwrap();
            assert!(same(&got, &whole.positions[r.start * w..r.end * w]), "{}: frames {r:?}", path.display());
        }
    }
    // Past the end: clamped.
    assert!(lazy.read(n..n + 5).unwrap().is_empty());
}

#[test]
fn trc_windows_read_the_frames_the_whole_file_has_whatever_the_line_endings() {
    let d = tmp("trc");
    use smocap::kinematics::synth::{synthesize, SynthOptions};
    let ctx = smocap::pipeline::Context::shipped().unwrap();
    let opt = SynthOptions { frames: 57, seed: 5, dropout: 0.1, ..SynthOptions::default() };
    let s = synthesize(&ctx.model, &ctx.proxy, &opt);
    // Gaps (dropout), a BOM, CRLF and CR-only line endings, blank lines between rows.
    let gappy = smocap::io::trc::to_trc_string(&s.trial, "mm", "w.trc").unwrap();
    for (name, body) in [
        ("lf.trc", gappy.clone()),
        ("bom.trc", format!("\u{feff}{gappy}")),
        ("crlf.trc", gappy.replace('\n', "\r\n")),
        ("cr.trc", gappy.replace('\n', "\r")),
        ("blank.trc", gappy.replace("\n2\t", "\n\n\n2\t")),
    ] {
        let p = d.join(name);
        std::fs::write(&p, body).unwrap();
        windows_match_the_whole_file(&p);
    }
}

#[test]
fn c3d_windows_read_the_frames_the_whole_file_has() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets/c3d_sample01");
    let files: Vec<PathBuf> =
        ["Eb015pi.c3d", "Eb015vi.c3d"].iter().map(|f| dir.join(f)).filter(|p| p.is_file()).collect();
    if files.is_empty() {
        eprintln!("note: ../shared/datasets/c3d_sample01 not found; C3D windows checked on the synthetic file only");
    }
    for p in &files {
        windows_match_the_whole_file(p);
    }
}
