//! `smocap bench` end to end on a tiny synthetic datasets.toml: the table's columns and rows,
//! the JSON report's fields, and an SVG figure; plus the reference rows read from OpenSim
//! summaries.

use std::path::PathBuf;
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-eval-bench-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn bench_prints_the_table_writes_the_report_and_an_svg_figure() {
    let dir = tmp("cli");
    let toml = dir.join("datasets.toml");
    std::fs::write(
        &toml,
        "[[dataset]]\nname = \"tiny\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\n\
         static = \"{subject}/static.trc\"\nsynthetic = { subjects = 1, trials = 1, frames = 20, seed = 1 }\n\n\
         [[dataset]]\nname = \"absent\"\nroot = \"no/such/folder\"\ntrials = [\"*.trc\"]\n",
    )
    .unwrap();
    // An OpenSim summary, as the shared reference folder holds them.
    let reference = dir.join("reference");
    std::fs::create_dir_all(reference.join("tiny")).unwrap();
    std::fs::write(
        reference.join("tiny/walk_summary.json"),
        r#"{"tool": "OpenSim", "tag": "walk01", "frames": 20, "ms_per_frame_marginal": 5.0,
            "rms_mean_m": 0.02, "rms_p50_m": 0.019, "rms_p90_m": 0.025}"#,
    )
    .unwrap();
    let (json, svg) = (dir.join("bench.json"), dir.join("bench.svg"));
    let out = Command::new(env!("CARGO_BIN_EXE_smocap"))
        .args(["bench", toml.to_str().unwrap(), "--backend", "cpu", "--out"])
        .arg(dir.join("out"))
        .arg("--reference")
        .arg(&reference)
        .arg("--report-json")
        .arg(&json)
        .arg("--figure")
        .arg(&svg)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let header = stdout.lines().next().unwrap();
    for col in ["dataset", "source", "frames", "FPS", "ms/frame p50", "iter p50", "RMSE mm p50"] {
        assert!(header.contains(col), "column {col} missing: {header}");
    }
    let row = |source: &str, dataset: &str| stdout.lines().any(|l| l.starts_with(dataset) && l.contains(source));
    assert!(row("smocap", "tiny"), "{stdout}");
    assert!(row("OpenSim 4.6 IK", "tiny"), "{stdout}");
    for d in ["CAMS-Knee", "Riglet", "MoYo (yoga)"] {
        assert!(row("SmoCap (published)", d), "{stdout}");
    }
    assert!(stdout.contains("absent skipped"), "{stdout}");
    assert!(stdout.contains("timed:"), "{stdout}");

    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(r["timed"].as_str().unwrap().contains("Excluded: file I/O"));
    let tiny = &r["datasets"][0];
    assert_eq!(tiny["name"], "tiny");
    assert_eq!(tiny["frames"], 20);
    assert_eq!(tiny["trials"], 1);
    assert!(tiny["fps"].as_f64().unwrap() > 0.0 && tiny["wall_fps"].as_f64().unwrap() > 0.0);
    for k in ["ms_per_frame", "iterations", "rmse_mm"] {
        let (p50, p90) = (tiny[k]["p50"].as_f64().unwrap(), tiny[k]["p90"].as_f64().unwrap());
        assert!(p50.is_finite() && p90 >= p50, "{k}: {p50} {p90}");
    }
    // Synthetic trials carry 2 mm noise and 5 mm misplacement: the RMSE is millimetres, not metres.
    assert!(tiny["rmse_mm"]["p50"].as_f64().unwrap() < 50.0);
    assert!(r["datasets"][1]["skipped"].as_str().unwrap().contains("not found"));
    assert_eq!(r["published"].as_array().unwrap().len(), 3);
    assert_eq!(r["opensim"][0]["ms_p50"], 5.0);
    assert!((r["opensim"][0]["rmse_mm_p50"].as_f64().unwrap() - 19.0).abs() < 1e-9);

    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.trim_start().starts_with("<svg") && text.trim_end().ends_with("</svg>"), "not an SVG");
    assert!(text.contains("per-frame solve time") && text.contains("per-frame marker RMSE"));
    assert!(text.contains("\ntiny\n"), "dataset label missing from the figure");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn opensim_rows_read_the_shared_reference_when_present() {
    let dir = std::path::Path::new("../shared/reference/opensim-4.6");
    if !dir.is_dir() {
        eprintln!("note: {} absent, skipped", dir.display());
        return;
    }
    let rows = smocap::eval::bench::opensim_rows(dir);
    let gait = rows.iter().find(|r| r.dataset == "gait2354_subject01").expect("gait2354 summary");
    assert_eq!(gait.frames, 151);
    assert!((gait.rmse_mm_p50.unwrap() - 21.59).abs() < 0.01);
    assert!(gait.ms_p50.unwrap() > 0.0);
}
