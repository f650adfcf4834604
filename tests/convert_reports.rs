//! What `smocap convert` tells and leaves behind: plain progress lines and the final table when
//! stderr is not a terminal, `smocap merge-reports` joining shard summaries, and
//! `smocap export` reading a converted trial back as an OpenSim motion and a CSV table.

use smocap::archive::config::SyntheticSpec;
use smocap::io::sto::read_sto;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn smocap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().expect("run smocap")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A synthetic archive (`subjNN/static.trc`, `subjNN/walkNN.trc`) and its datasets.toml.
fn archive(name: &str, subjects: usize, trials: usize, frames: usize) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("smocap-reports-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let spec = SyntheticSpec { subjects, trials, frames, seed: 11 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(
        &toml,
        "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\nstatic = \"{subject}/static.trc\"\n",
    )
    .unwrap();
    (dir, toml)
}

fn convert(toml: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--jobs", "2"];
    args.extend_from_slice(extra);
    smocap(&args)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// `(trial, status, frames)` of every trial of a summary.
fn trials(r: &serde_json::Value) -> Vec<(String, String, u64)> {
    r["trials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (t["trial"].as_str().unwrap().into(), t["status"].as_str().unwrap().into(), t["frames"].as_u64().unwrap())
        })
        .collect()
}

#[test]
fn plain_progress_lines_and_a_final_table_when_stderr_is_not_a_terminal() {
    let (dir, toml) = archive("progress", 1, 2, 30);
    let o = convert(&toml, &dir.join("out"), &["--progress-every", "0.01"]);
    let (out, err) = (text(&o.stdout), text(&o.stderr));
    assert!(o.status.success(), "{err}");
    assert!(err.contains("[1/2] lab/subj01/walk0") && err.contains("[2/2] lab/subj01/walk0"), "{err}");
    assert!(err.contains("done: 1/1 subjects calibrated, 2/2 trials (0 failed), 60/60 frames"), "{err}");
    // Where the workers' time went, at the end of the line.
    let done = err.lines().find(|l| l.starts_with("done: ")).expect("a done line");
    assert!(done.contains("(calibration ") && done.contains(" s, solving ") && done.ends_with(" s)"), "{done}");
    assert!(!err.contains('\u{1b}'), "no terminal escapes in plain output: {err:?}");
    for col in ["dataset", "ok", "failed", "frames", "frames/s", "ms/frame p50/90", "iter p50/90", "RMSE mm p50/90"] {
        assert!(out.contains(col), "table column {col}: {out}");
    }
    let row = out.lines().find(|l| l.starts_with("lab ")).unwrap_or_else(|| panic!("a row for lab: {out}"));
    assert_eq!(row.split_whitespace().take(5).collect::<Vec<_>>(), ["lab", "2", "0", "0", "60"], "{row}");

    let o = convert(&toml, &dir.join("out2"), &["--quiet"]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("[1/2]") && !err.contains("done:") && !err.contains("progress:"), "{err}");
    assert!(text(&o.stdout).contains("lab "), "the table still prints");
}

#[test]
fn merged_shard_reports_hold_the_trials_of_an_unsharded_run() {
    let (dir, toml) = archive("merge", 3, 1, 20);
    let report = |name: &str, extra: &[&str]| {
        let rep = dir.join(name);
        let mut args = vec!["--report-json", rep.to_str().unwrap(), "--quiet"];
        args.extend_from_slice(extra);
        let o = convert(&toml, &dir.join(format!("out-{name}")), &args);
        assert!(o.status.success(), "{}", text(&o.stderr));
        rep
    };
    let whole = report("whole.json", &[]);
    let r0 = report("r0.json", &["--shard", "0/2"]);
    let r1 = report("r1.json", &["--shard", "1/2"]);
    let merged = dir.join("merged.json");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let o = smocap(&["merge-reports", &s(&r1), &s(&r0), "--out", &s(&merged)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).lines().any(|l| l.starts_with("lab ")), "{}", text(&o.stdout));
    let m = json(&merged);
    assert_eq!(trials(&m), trials(&json(&whole)));
    assert_eq!(trials(&m).len(), 3);
    let shards: Vec<&str> = m["merged_from"].as_array().unwrap().iter().map(|x| x["shard"].as_str().unwrap()).collect();
    assert_eq!(shards, ["1/2", "0/2"]);

    // A trial in two summaries is an error, or the later one is kept when asked.
    let o = smocap(&["merge-reports", &s(&r0), &s(&r0)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o.stderr).contains("is in both"), "{}", text(&o.stderr));
    let o = smocap(&["merge-reports", &s(&r0), &s(&r0), "--keep-last"]);
    assert!(o.status.success() && text(&o.stderr).contains("replaces"), "{}", text(&o.stderr));
    // A missing shard is reported.
    let o = smocap(&["merge-reports", &s(&r0)]);
    assert!(text(&o.stderr).contains("no summary for shard(s) 1/2"), "{}", text(&o.stderr));
    // A failed trial in any summary: exit 3, and it is listed.
    let mut bad = json(&r1);
    bad["trials"][0]["status"] = "failed".into();
    bad["trials"][0]["error"] = "broken on purpose".into();
    let bad_path = dir.join("bad.json");
    std::fs::write(&bad_path, bad.to_string()).unwrap();
    let o = smocap(&["merge-reports", &s(&r0), &s(&bad_path)]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("broken on purpose"));
}

#[test]
fn export_gives_the_motion_smocap_solve_writes_and_a_csv_row_per_frame() {
    let (dir, toml) = archive("export", 1, 1, 40);
    let out = dir.join("out");
    let o = convert(&toml, &out, &["--quiet"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let mcap = out.join("lab/subj01/walk01.mcap");
    let (mot, csv) = (dir.join("export.mot"), dir.join("export.csv"));
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let o = smocap(&["export", &s(&mcap), "--mot", &s(&mot), "--csv", &s(&csv)]);
    assert!(o.status.success(), "{}", text(&o.stderr));

    // The same trial through `smocap solve`, same static trial, same (shipped) model.
    let data = dir.join("data/subj01");
    let mot_dir = dir.join("solve-mot");
    let o = smocap(&[
        "solve",
        "--static",
        &s(&data.join("static.trc")),
        &s(&data.join("walk01.trc")),
        "--backend",
        "cpu",
        "--threads",
        "1",
        "--mot-dir",
        &s(&mot_dir),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let (a, b) = (read_sto(&mot).unwrap(), read_sto(&mot_dir.join("walk01.mot")).unwrap());
    assert_eq!(a.columns, b.columns);
    assert_eq!(a.header, b.header);
    assert_eq!(a.rows.len(), 40);
    assert_eq!(a.rows.len(), b.rows.len());
    for (ra, rb) in a.rows.iter().zip(&b.rows) {
        for ((x, y), c) in ra.iter().zip(rb).zip(&a.columns) {
            assert!((x - y).abs() <= 1e-8, "{c}: {x} vs {y}");
        }
    }

    let table = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 1 + 40, "a header and one row per frame");
    let header: Vec<&str> = lines[0].split(',').collect();
    assert_eq!(header[..2], ["time", "frame"]);
    assert_eq!(header[header.len() - 2..], ["rmse_m", "status"]);
    assert!(header.contains(&"scale_pelvis_x") || header.iter().any(|h| h.starts_with("scale_")), "{header:?}");
    for c in &a.columns[1..] {
        assert!(header.contains(&c.as_str()), "CSV lacks coordinate {c}");
    }
    for (f, l) in lines[1..].iter().enumerate() {
        let cells: Vec<&str> = l.split(',').collect();
        assert_eq!(cells.len(), header.len());
        assert_eq!(cells[1], f.to_string());
        let rmse: f64 = cells[cells.len() - 2].parse().unwrap();
        assert!((0.0..0.05).contains(&rmse), "frame {f}: RMSE {rmse} m");
    }
}
