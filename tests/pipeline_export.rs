//! Export of solved trials as OpenSim motions: the same columns and values as OpenSim's own
//! inverse kinematics output, and exact round trips through the `.mot` writer and reader.

mod common;

use common::shared;
use smocap::io::sto::{format_sto, parse_sto, read_sto, write_sto};
use smocap::pipeline::results::export::{motion_table, opensim_degrees};
use smocap::pipeline::Context;

/// A context for an OpenSim dataset's generic model, its IK motion, and proxies reproducing it.
fn from_opensim_ik(model: &str, mot: &str) -> Option<(Context, smocap::io::sto::Table, Vec<Vec<f64>>)> {
    let (model, mot) = (shared(model), shared(mot));
    if !model.exists() || !mot.exists() {
        eprintln!("skipped: {} or {} is absent", model.display(), mot.display());
        return None;
    }
    let ctx = Context::from_files_with_markers(&model, None, None).expect("context");
    let ik = read_sto(&mot).expect("mot");
    assert_eq!(ik.in_degrees(), Some(true));
    let deg = opensim_degrees(&ctx.model);
    let p0 = ctx.proxy.default_proxies();
    let proxies = ik
        .rows
        .iter()
        .map(|row| {
            let mut y = ctx.proxy.state(&p0);
            for (i, c) in ctx.model.coordinates.iter().enumerate() {
                let v = row[ik.column(&c.name).unwrap_or_else(|| panic!("{} not in the .mot", c.name))];
                y[i] = if deg[i] { v.to_radians() } else { v };
            }
            // A consistent state (OpenSim meets its coupler constraints only to a tolerance).
            for k in &ctx.model.couplings {
                y[k.dependent] = k.func.eval(y[k.independent]).0;
            }
            ctx.proxy.proxies_from_state(&y, &p0)
        })
        .collect();
    Some((ctx, ik, proxies))
}

#[test]
fn motions_have_opensims_columns_and_values_for_both_datasets() {
    for (model, mot) in [
        (
            "datasets/rajagopal2016_walk/Rajagopal2016.osim",
            "reference/opensim-4.6/rajagopal2016_walk/motion_capture_walk_ik.mot",
        ),
        (
            "datasets/gait2354_subject01/gait2354_simbody.osim",
            "reference/opensim-4.6/gait2354_subject01/subject01_walk1_ik.mot",
        ),
    ] {
        let Some((ctx, ik, proxies)) = from_opensim_ik(model, mot) else { continue };
        let times: Vec<f64> = ik.rows.iter().map(|r| r[0]).collect();
        let ours = motion_table(&ctx, &proxies, &times).expect("table");
        assert_eq!(ours.columns, ik.columns, "{model}: same coordinates in the same order");
        assert_eq!(ours.in_degrees(), Some(true));
        let (mut worst, mut column) = (0.0f64, 0);
        for (a, b) in ours.rows.iter().zip(&ik.rows) {
            for (c, (x, y)) in a.iter().zip(b).enumerate() {
                if (x - y).abs() > worst {
                    (worst, column) = ((x - y).abs(), c);
                }
            }
        }
        // OpenSim prints 8 decimals (coupled columns in radians, locked ones at their defaults).
        println!("{model}: worst difference from OpenSim's .mot {worst:.2e} ({})", ik.columns[column]);
        assert!(worst <= 1e-8, "{model}: {worst} in {}", ik.columns[column]);
    }
}

#[test]
fn a_motion_round_trips_exactly_through_the_writer_and_reader() {
    let ctx = Context::shipped().expect("shipped");
    let deg = opensim_degrees(&ctx.model);
    let rot = ctx.model.coordinate_index("hip_flexion_r").expect("hip");
    let tx = ctx.model.coordinate_index("pelvis_tx").expect("pelvis_tx");
    assert!(deg[rot] && !deg[tx]);
    let mut r = common::rng(5);
    let mut proxies = Vec::new();
    for _ in 0..7 {
        let mut p = ctx.proxy.default_proxies();
        for (k, px) in ctx.proxy.proxies.iter().enumerate() {
            let (lo, hi) = (px.range.0.max(-1.0), px.range.1.min(1.0));
            if lo < hi && px.kind != smocap::model::proxy::ProxyKind::Scale {
                p[k] = rand::RngExt::random_range(&mut r, lo..hi);
            }
        }
        p[ctx.proxy.proxy_index("hip_flexion_r").expect("proxy")] = 0.5;
        proxies.push(p);
    }
    let times: Vec<f64> = (0..7).map(|f| f as f64 / 120.0).collect();
    let table = motion_table(&ctx, &proxies, &times).expect("table");
    assert_eq!(table.rows[3][rot + 1], 0.5f64.to_degrees(), "rotations in degrees");
    assert_eq!(table.rows[3][tx + 1], ctx.proxy.state(&proxies[3])[tx], "translations in metres");

    let text = format_sto("Coordinates", &table);
    let head: Vec<&str> = text.lines().take(6).collect();
    assert_eq!(
        head,
        [
            "Coordinates",
            "version=1",
            "nRows=7",
            &format!("nColumns={}", ctx.model.nq() + 1),
            "inDegrees=yes",
            "endheader"
        ]
    );
    let path = std::env::temp_dir().join(format!("smocap-export-{}.mot", std::process::id()));
    write_sto(&path, "Coordinates", &table).expect("write");
    let back = read_sto(&path).expect("read back");
    std::fs::remove_file(&path).ok();
    assert_eq!(back.columns, table.columns);
    assert_eq!(back.rows, table.rows, "bit-exact round trip");
    assert_eq!(back.in_degrees(), Some(true));
    // Extreme magnitudes and non-finite values survive too.
    let mut t = table.clone();
    t.rows[0][1..5].copy_from_slice(&[1e-300, -3.5e20, f64::NAN, f64::INFINITY]);
    let back = parse_sto(&format_sto("x", &t), "x.mot").expect("parse");
    assert_eq!(&back.rows[0][1..3], &[1e-300, -3.5e20]);
    assert!(back.rows[0][3].is_nan() && back.rows[0][4] == f64::INFINITY);
}

#[test]
fn a_frame_count_mismatch_is_an_error() {
    let ctx = Context::shipped().expect("shipped");
    let p = vec![ctx.proxy.default_proxies(); 3];
    let e = motion_table(&ctx, &p, &[0.0, 0.1]).expect_err("mismatch");
    assert!(e.to_string().contains("3 frames of proxies but 2 frame times"), "{e}");
}
