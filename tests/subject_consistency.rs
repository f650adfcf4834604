//! Trials grouped as one subject: what their C3D files say of the subject (names, recorded
//! height and mass) feeds the prior and decides whether they are one person.

use smocap::io::MarkerTrial;
use smocap::kinematics::synth::{synthesize, SynthOptions};
use smocap::pipeline::Context;
use std::path::{Path, PathBuf};
use std::process::Command;

/// One parameter record: group id, name, type (-1 char, 2 int16, 4 float), dimensions, data.
fn param(gid: i8, name: &str, kind: i8, dims: &[u8], data: &[u8]) -> Vec<u8> {
    let mut body = vec![kind as u8, dims.len() as u8];
    body.extend(dims);
    body.extend(data);
    body.push(0);
    let mut r = vec![name.len() as u8, gid as u8];
    r.extend(name.as_bytes());
    r.extend(((body.len() + 2) as i16).to_le_bytes());
    r.extend(body);
    r
}

fn group(gid: i8, name: &str) -> Vec<u8> {
    let mut r = vec![name.len() as u8, (-gid) as u8];
    r.extend(name.as_bytes());
    r.extend(3i16.to_le_bytes());
    r.push(0);
    r
}

/// Writes `t` as an Intel float C3D file (mm) naming `subject` of `height_mm` and `mass_kg`.
fn write_c3d(path: &Path, t: &MarkerTrial, subject: &str, height_mm: f32, mass_kg: f32) {
    let (n, nm) = (t.n_frames(), t.n_markers());
    let width = t.labels.iter().map(String::len).max().unwrap_or(1);
    let mut labels = Vec::new();
    for l in &t.labels {
        let mut b = l.as_bytes().to_vec();
        b.resize(width, b' ');
        labels.extend(b);
    }
    let f32s = |v: f32| v.to_le_bytes().to_vec();
    let i16s = |v: i16| v.to_le_bytes().to_vec();
    // Parameter section: 8 blocks at most here; data from block 2 + 8.
    let data_start = 10i16;
    let mut s = vec![1, 0x50, 8, 84];
    s.extend(group(1, "POINT"));
    s.extend(group(2, "SUBJECTS"));
    s.extend(group(3, "PROCESSING"));
    s.extend(param(1, "USED", 2, &[], &i16s(nm as i16)));
    s.extend(param(1, "FRAMES", 2, &[], &i16s(n as i16)));
    s.extend(param(1, "SCALE", 4, &[], &f32s(-1.0)));
    s.extend(param(1, "RATE", 4, &[], &f32s(t.rate_hz as f32)));
    s.extend(param(1, "DATA_START", 2, &[], &i16s(data_start)));
    s.extend(param(1, "UNITS", -1, &[2], b"mm"));
    s.extend(param(1, "LABELS", -1, &[width as u8, nm as u8], &labels));
    s.extend(param(2, "NAMES", -1, &[subject.len() as u8, 1], subject.as_bytes()));
    s.extend(param(3, "Height", 4, &[], &f32s(height_mm)));
    s.extend(param(3, "Bodymass", 4, &[], &f32s(mass_kg)));
    s.extend([0, 0, 0, 0]);
    assert!(s.len() <= 8 * 512);
    s.resize(8 * 512, 0);
    let mut h = vec![0u8; 512];
    h[0] = 2;
    h[1] = 0x50;
    for (o, w) in [(2, nm as i16), (4, 0), (6, 1), (8, n as i16), (16, data_start)] {
        h[o..o + 2].copy_from_slice(&w.to_le_bytes());
    }
    h[12..16].copy_from_slice(&(-1.0f32).to_le_bytes());
    h[20..24].copy_from_slice(&(t.rate_hz as f32).to_le_bytes());
    let mut out = h;
    out.extend(s);
    for f in 0..n {
        for m in 0..nm {
            match t.position(f, m) {
                Some(p) => {
                    p.iter().for_each(|v| out.extend(((v * 1e3) as f32).to_le_bytes()));
                    out.extend(0f32.to_le_bytes());
                }
                None => (0..4).for_each(|_| out.extend((-1f32).to_le_bytes())),
            }
        }
    }
    std::fs::write(path, out).unwrap();
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("smocap-subject-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn solve(files: &[PathBuf], report: &Path) -> (i32, serde_json::Value, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_smocap"))
        .arg("solve")
        .args(files)
        .arg("--report-json")
        .arg(report)
        .output()
        .unwrap();
    let json = serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    (o.status.code().unwrap(), json, String::from_utf8_lossy(&o.stderr).into_owned())
}

fn trial(seed: u64, spread: f64) -> MarkerTrial {
    let ctx = Context::shipped().unwrap();
    let opt = SynthOptions { frames: 200, seed, scale_spread: spread, ..SynthOptions::default() };
    synthesize(&ctx.model, &ctx.proxy, &opt).trial
}

#[test]
fn a_subject_folder_mixing_two_peoples_trials_is_suspect_and_one_persons_is_not() {
    let d = dir("mixed");
    let (a, b) = (d.join("ann.c3d"), d.join("bob.c3d"));
    write_c3d(&a, &trial(3, 0.1), "Ann", 1505.0, 48.0);
    write_c3d(&b, &trial(5, 0.1), "Bob", 1790.0, 80.0);
    let (code, r, err) = solve(&[a.clone(), b], &d.join("mixed.json"));
    assert_eq!(code, 3, "{err}");
    let cal = &r["calibration"];
    assert_eq!(cal["status"], "suspect");
    let why = cal["warnings"].to_string();
    assert!(why.contains("Ann") && why.contains("Bob") && why.contains("1.505"), "{why}");
    assert!(r["trials"].as_array().unwrap().iter().all(|t| t["status"] == "suspect"));

    // One person's two trials (the same subject, heights a centimetre apart): not suspect for it,
    // and the prior took the recorded height and mass.
    let a2 = d.join("ann2.c3d");
    write_c3d(&a2, &trial(4, 0.0), "Ann", 1515.0, 48.0);
    let (_, r, err) = solve(&[a, a2], &d.join("one.json"));
    let cal = &r["calibration"];
    let why = cal["warnings"].to_string();
    assert!(!why.contains("SUBJECTS:NAMES") && !why.contains("PROCESSING:Height"), "{why}\n{err}");
    let from = cal["subject_from_files"].as_str().unwrap_or_default();
    assert!(from.contains("height 1.505 m") && from.contains("mass 48.0 kg"), "{from}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn converting_a_subject_folder_that_mixes_two_people_makes_its_trials_suspect() {
    let d = dir("convert");
    for (sub, files) in [
        ("mixed", [("ann", "Ann", 1505.0, 3), ("bob", "Bob", 1790.0, 5)]),
        ("ann", [("a1", "Ann", 1505.0, 3), ("a2", "Ann", 1515.0, 4)]),
    ] {
        std::fs::create_dir_all(d.join("data").join(sub)).unwrap();
        for (stem, name, h, seed) in files {
            write_c3d(
                &d.join("data").join(sub).join(format!("{stem}.c3d")),
                &trial(seed, if name == "Bob" { 0.1 } else { 0.0 }),
                name,
                h,
                60.0,
            );
        }
    }
    std::fs::write(
        d.join("datasets.toml"),
        "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/*.c3d\"]\nsubject = \"{subject}/{trial}.c3d\"\n",
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_smocap"))
        .arg("convert")
        .arg(d.join("datasets.toml"))
        .arg("--out")
        .arg(d.join("out"))
        .arg("--report-json")
        .arg(d.join("summary.json"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap()).unwrap();
    let trials = summary["trials"].as_array().unwrap();
    assert_eq!(trials.len(), 4, "{summary}");
    for t in trials {
        let why = t["error"].as_str().unwrap_or_default();
        if t["subject"] == "mixed" {
            assert_eq!(t["status"], "suspect", "{t}");
            assert!(why.contains("SUBJECTS:NAMES") && why.contains("Ann") && why.contains("Bob"), "{why}");
        } else {
            assert!(!why.contains("SUBJECTS:NAMES") && !why.contains("PROCESSING:Height"), "{t}");
        }
    }
    assert!(err.contains("height 1.505 m"), "the prior took the recorded height: {err}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_trial_of_another_person_among_a_subjects_trials_is_named_from_its_fit() {
    // TRC files say nothing of their subject: the fit under the calibrated morphology does.
    let d = dir("misfit");
    let write = |name: &str, t: &MarkerTrial| {
        let p = d.join(format!("{name}.trc"));
        smocap::io::trc::write_trc(&p, t, "mm").unwrap();
        p
    };
    let own: Vec<PathBuf> = [3, 4, 6].iter().map(|&s| write(&format!("ann{s}"), &trial(s, 0.0))).collect();
    let bob = write("bob", &trial(5, 0.3));
    let (code, r, err) = solve(&[own.clone(), vec![bob]].concat(), &d.join("mixed.json"));
    assert_eq!(code, 3, "{err}");
    let why = r["calibration"]["warnings"].to_string();
    assert!(why.contains("bob.trc fits the calibrated subject far worse"), "{why}");
    assert!(!why.contains("ann"), "only the odd trial is named: {why}");
    let (_, r, err) = solve(&own, &d.join("own.json"));
    let why = r["calibration"]["warnings"].to_string();
    assert!(!why.contains("far worse"), "{why}\n{err}");
    let _ = std::fs::remove_dir_all(&d);
}
