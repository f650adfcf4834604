//! TRC reading and writing: the shared real files, quirks, errors and a no-panic fuzz loop.

use std::path::PathBuf;

use smocap::io::markers::MarkerTrial;
use smocap::io::trc::{parse_trc, read_trc, to_trc_string, write_trc, TrcError};

fn shared(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/datasets")).join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("note: {} is absent; test skipped", p.display());
        None
    }
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
}

/// (file, frames, rate, markers, first label, last label, row 1 of first marker in mm,
/// row 1 of last marker in mm, last frame number, last time)
type Expect = (&'static str, usize, f64, usize, &'static str, &'static str, [f64; 3], [f64; 3], i64, f64);

const SHARED_FILES: [Expect; 4] = [
    (
        "gait2354_subject01/subject01_static.trc",
        300,
        60.0,
        49,
        "R.ASIS",
        "Top.Head",
        [608.664310, 1072.713130, 157.442150],
        [593.032100, 1814.390140, 32.174850],
        300,
        4.983,
    ),
    (
        "gait2354_subject01/subject01_walk1.trc",
        151,
        60.0,
        41,
        "R.ASIS",
        "Top.Head",
        [617.247620, 1055.275020, 170.781980],
        [749.332460, 1747.607670, 46.741460],
        151,
        2.5,
    ),
    (
        "rajagopal2016_walk/static_walk_1.trc",
        287,
        100.0,
        64,
        "R.Shoulder",
        "MidClavicle",
        [463.565, 1572.120, -254.468],
        [596.337, 1500.512, -163.163],
        287,
        2.86,
    ),
    (
        "rajagopal2016_walk/motion_capture_walk.trc",
        238,
        100.0,
        41,
        "R.Shoulder",
        "L.Toe",
        [-652.630, 1529.542, -94.520],
        [-412.723, 57.077, -251.120],
        238,
        2.37,
    ),
];

#[test]
fn reads_shared_trc_files_with_counts_rate_and_spot_values_in_metres() {
    for (rel, nf, rate, nm, first, last, p0, pl, last_frame, last_time) in SHARED_FILES {
        let Some(path) = shared(rel) else { continue };
        let t = read_trc(&path).unwrap_or_else(|e| panic!("{rel}: {e}"));
        assert_eq!(t.n_frames(), nf, "{rel}");
        assert_eq!(t.n_markers(), nm, "{rel}");
        assert_eq!(t.rate_hz, rate, "{rel}");
        assert_eq!(t.source_units, "mm", "{rel}");
        assert_eq!(t.labels[0], first, "{rel}");
        assert_eq!(t.labels[nm - 1], last, "{rel}");
        assert_eq!(t.frame_numbers[0], 1, "{rel}");
        assert_eq!(*t.frame_numbers.last().unwrap(), last_frame, "{rel}");
        assert!((t.times[nf - 1] - last_time).abs() < 1e-9, "{rel}");
        let mm = |p: [f64; 3]| p.map(|v| v * 1e-3);
        assert!(close(t.position(0, 0).unwrap(), mm(p0)), "{rel}");
        assert!(close(t.position(0, nm - 1).unwrap(), mm(pl)), "{rel}");
        assert_eq!(t.gap_counts().iter().sum::<usize>(), 0, "{rel} has no gaps");
        assert!(t.warnings.is_empty(), "{rel}: {:?}", t.warnings);
        assert!(t.check_consistent().is_ok());
    }
}

#[test]
fn double_tabs_and_leading_spaces_in_header_are_read_by_name() {
    let Some(path) = shared("rajagopal2016_walk/motion_capture_walk.trc") else {
        return;
    };
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.lines().nth(2).unwrap().contains("\t\t"), "fixture lost its double tabs");
    let t = parse_trc(&text, "motion_capture_walk.trc").unwrap();
    assert_eq!((t.rate_hz, t.n_frames(), t.n_markers()), (100.0, 238, 41));
}

const SMALL: &str = "PathFileType\t4\t(X/Y/Z)\tsmall.trc\n\
DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n\
50.00\t50.00\t3\t2\tmm\t50.00\t1\t3\n\
Frame#\tTime\tA\t\t\tB\t\t\n\
\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n\
\n\
1\t0.000\t1.0\t2.0\t3.0\t4.0\t5.0\t6.0\n\
2\t0.020\t\t\t\t7.0\t8.0\t9.0\n\
3\t0.040\t10.0\tNaN\t12.0\n";

#[test]
fn gaps_from_empty_nan_and_missing_trailing_cells_read_as_none() {
    let t = parse_trc(SMALL, "small").unwrap();
    assert_eq!((t.n_frames(), t.n_markers()), (3, 2));
    assert!(close(t.position(0, 1).unwrap(), [0.004, 0.005, 0.006]));
    assert_eq!(t.position(1, 0), None, "empty cells");
    assert_eq!(t.position(2, 0), None, "NaN on one axis makes the marker a gap");
    assert_eq!(t.position(2, 1), None, "missing trailing cells");
    assert_eq!(t.gap_counts(), vec![2, 1]);
    assert!(t.warnings.is_empty(), "{:?}", t.warnings);
}

#[test]
fn units_are_converted_to_metres() {
    for (u, s) in [("mm", 1e-3), ("cm", 1e-2), ("m", 1.0), ("M", 1.0), ("in", 0.0254)] {
        let text = SMALL.replace("\tmm\t", &format!("\t{u}\t"));
        let t = parse_trc(&text, "units").unwrap();
        assert_eq!(t.source_units, u);
        let p = t.position(0, 0).unwrap();
        assert!(close(p, [1.0 * s, 2.0 * s, 3.0 * s]), "{u}: {p:?}");
    }
}

#[test]
fn crlf_trailing_whitespace_blank_lines_and_count_mismatches_are_tolerated() {
    let text = SMALL.replace("\t3\t2\tmm", "\t5\t7\tmm").replace('\n', " \r\n") + "\r\n\r\n  \r\n";
    let t = parse_trc(&text, "crlf").unwrap();
    assert_eq!((t.n_frames(), t.n_markers()), (3, 2));
    assert_eq!(t.labels, ["A", "B"]);
    assert!(close(t.position(0, 1).unwrap(), [0.004, 0.005, 0.006]));
    assert!(t.warnings.iter().any(|w| w.contains("NumMarkers")), "{:?}", t.warnings);
    assert!(t.warnings.iter().any(|w| w.contains("NumFrames")), "{:?}", t.warnings);
}

#[test]
fn write_then_read_round_trips_to_printed_precision() {
    let mut t = parse_trc(SMALL, "small").unwrap();
    t.positions.iter_mut().for_each(|v| *v += 0.000_123_456_7);
    for units in ["mm", "m", "cm", "in"] {
        let text = to_trc_string(&t, units, "rt.trc").unwrap();
        let back = parse_trc(&text, "rt").unwrap();
        assert_eq!(back.labels, t.labels);
        assert_eq!(back.frame_numbers, t.frame_numbers);
        assert_eq!(back.rate_hz, t.rate_hz);
        assert!(back.warnings.is_empty(), "{units}: {:?}", back.warnings);
        for f in 0..t.n_frames() {
            assert!((back.times[f] - t.times[f]).abs() < 1e-6);
            for m in 0..t.n_markers() {
                match (t.position(f, m), back.position(f, m)) {
                    (Some(a), Some(b)) => assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9), "{units}"),
                    (a, b) => assert_eq!(a, b),
                }
            }
        }
        assert_eq!(to_trc_string(&back, units, "rt.trc").unwrap(), text, "second write is identical");
    }
}

#[test]
fn write_trc_to_disk_round_trips_a_shared_file() {
    let Some(path) = shared("gait2354_subject01/subject01_walk1.trc") else {
        return;
    };
    let t = read_trc(&path).unwrap();
    let out = std::env::temp_dir().join(format!("smocap_io_trc_{}.trc", std::process::id()));
    write_trc(&out, &t, "mm").unwrap();
    let back = read_trc(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    assert_eq!((back.n_frames(), back.n_markers(), back.labels.clone()), (151, 41, t.labels.clone()));
    assert!(t.positions.iter().zip(&back.positions).all(|(a, b)| (a - b).abs() < 1e-9));
}

#[test]
fn writer_rejects_unknown_units_and_inconsistent_trials() {
    let t = parse_trc(SMALL, "small").unwrap();
    assert!(matches!(to_trc_string(&t, "furlong", "x"), Err(TrcError::Unwritable { .. })));
    let mut bad = t.clone();
    bad.positions.pop();
    assert!(matches!(to_trc_string(&bad, "mm", "x"), Err(TrcError::Unwritable { .. })));
    let mut bad = t;
    bad.labels[0] = "A\tB".into();
    assert!(matches!(to_trc_string(&bad, "mm", "x"), Err(TrcError::Unwritable { .. })));
}

fn err(text: &str) -> TrcError {
    match parse_trc(text, "bad.trc") {
        Ok(t) => panic!("expected an error, got {} frames", t.n_frames()),
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.starts_with("bad.trc"), "{msg}");
            e
        }
    }
}

fn header_lines(n: usize) -> String {
    SMALL.lines().take(n).map(|l| format!("{l}\n")).collect()
}

#[test]
fn malformed_inputs_give_the_right_error_and_line() {
    assert!(matches!(err(""), TrcError::MissingHeader { line: 1, .. }));
    assert!(matches!(err("hello\nworld\n"), TrcError::MissingHeader { line: 1, .. }));
    assert!(matches!(err(&header_lines(1)), TrcError::MissingHeader { line: 2, .. }));
    assert!(matches!(err(&header_lines(2)), TrcError::MissingHeader { line: 3, .. }));
    assert!(matches!(err(&header_lines(3)), TrcError::MissingHeader { line: 4, .. }));
    assert!(matches!(err(&header_lines(4)), TrcError::NoData { line: 5, .. }));
    assert!(matches!(err(&header_lines(6)), TrcError::NoData { line: 7, .. }));
    let e = err(&SMALL.replace("\tmm\t", "\tfurlongs\t"));
    assert!(matches!(&e, TrcError::UnknownUnits { line: 3, units, .. } if units == "furlongs"), "{e}");
    let e = err(&SMALL.replace("50.00\t50.00", "fast\t50.00"));
    assert!(matches!(&e, TrcError::BadHeaderValue { line: 3, field, .. } if field == "DataRate"), "{e}");
    let e = err(&SMALL.replace("\tUnits\t", "\tWhatever\t"));
    assert!(matches!(e, TrcError::MissingHeader { line: 2, .. }), "{e}");
    let e = err(&SMALL.replace("8.0", "8.0x"));
    assert!(matches!(e, TrcError::NonNumeric { line: 8, column: 7, .. }), "{e}");
    let e = err(&SMALL.replace("3\t0.040", "three\t0.040"));
    assert!(matches!(e, TrcError::NonNumeric { line: 9, column: 1, .. }), "{e}");
    let e = err(&SMALL.replace("2\t0.020", "2\tt"));
    assert!(matches!(e, TrcError::NonNumeric { line: 8, column: 2, .. }), "{e}");
    let e = err(&SMALL.replace("6.0\n", "6.0\t99.0\n"));
    assert!(matches!(e, TrcError::RaggedRow { line: 7, found: 7, n_markers: 2, .. }), "{e}");
    assert_eq!(e.line(), Some(7));
}

#[test]
fn missing_file_is_an_io_error() {
    let e = read_trc(std::path::Path::new("/nonexistent/dir/x.trc")).unwrap_err();
    assert!(matches!(e, TrcError::Io { .. }));
    assert!(e.to_string().contains("x.trc"));
}

/// SplitMix64: a tiny seeded generator so the fuzz cases are reproducible.
struct Mix(u64);
impl Mix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

#[test]
fn mutated_inputs_never_panic() {
    let base = SMALL.as_bytes();
    let alphabet = b"\t\n\r 0123456789.-+eENaXYZ#mcin\xff";
    let mut rng = Mix(0x005E_ED7C);
    let (mut ok, mut failed) = (0, 0);
    for case in 0..2000 {
        let mut b = base.to_vec();
        match case % 4 {
            0 => b.truncate(rng.below(b.len() + 1)),
            1 | 2 => {
                for _ in 0..=rng.below(6) {
                    let i = rng.below(b.len());
                    match rng.below(3) {
                        0 => b[i] = alphabet[rng.below(alphabet.len())],
                        1 => b.insert(i, alphabet[rng.below(alphabet.len())]),
                        _ => {
                            b.remove(i);
                        }
                    }
                }
            }
            _ => {
                // Duplicate or drop a whole random line.
                let lines: Vec<&[u8]> = base.split(|&c| c == b'\n').collect();
                let k = rng.below(lines.len());
                b = lines
                    .iter()
                    .enumerate()
                    .flat_map(|(i, l)| {
                        let times = if i != k {
                            1
                        } else if rng.below(2) == 0 {
                            0
                        } else {
                            2
                        };
                        std::iter::repeat_n(*l, times)
                    })
                    .collect::<Vec<_>>()
                    .join(&b'\n');
            }
        }
        let text = String::from_utf8_lossy(&b);
        match parse_trc(&text, "fuzz") {
            Ok(t) => {
                assert!(t.check_consistent().is_ok(), "case {case}: {text:?}");
                let _ = to_trc_string(&t, &t.source_units, "fuzz");
                ok += 1;
            }
            Err(e) => {
                assert!(e.line().is_some(), "case {case}: {e}");
                failed += 1;
            }
        }
    }
    assert!(ok > 100 && failed > 100, "ok {ok}, failed {failed}");
}

#[test]
fn marker_trial_helpers_work_on_a_read_file() {
    let t: MarkerTrial = parse_trc(SMALL, "small").unwrap();
    assert_eq!(t.label_index("B"), Some(1));
    assert!((t.duration() - 0.04).abs() < 1e-12);
    assert_eq!(t.frame(0).len(), 6);
    let s = t.select_frames(1..3);
    assert_eq!(s.frame_numbers, vec![2, 3]);
    assert_eq!(s.trajectory(1)[0], Some([0.007, 0.008, 0.009]));
}

// ---- Motion Analysis Cortex exports ----

/// A Cortex-style export of `nm` markers over `frames` frames: the name row holds only the
/// first `named` names (Cortex cuts it at a fixed length), `NumMarkers` says `num_markers`;
/// marker `m` of frame `f` is at `(f + m, 2m, 3)` mm, the last marker missing in frame 0
/// (its cells empty and the row ending early).
fn cortex(nm: usize, named: usize, num_markers: usize, frames: usize) -> String {
    let mut s = format!(
        "PathFileType\t4\t(X/Y/Z)\tcortex.trc\nDataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\t\
         OrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n100.00\t100.00\t{frames}\t{num_markers}\tmm\t100.00\t1\t{frames}\n\
         Frame#\tTime"
    );
    for m in 0..named {
        s += &format!("\tMarker{m}\t\t");
    }
    s += "\n\t\t";
    for m in 1..=named {
        s += &format!("X{m}\tY{m}\tZ{m}\t");
    }
    s += "\n\n";
    for f in 0..frames {
        s += &format!("{}\t{:.3}", f + 1, f as f64 / 100.0);
        let last = if f == 0 { nm - 1 } else { nm };
        for m in 0..last {
            s += &format!("\t{}\t{}\t3", f + m, 2 * m);
        }
        s += "\n";
    }
    s
}

fn check_cortex(t: &MarkerTrial, nm: usize, frames: usize) {
    assert_eq!((t.n_frames(), t.n_markers()), (frames, nm));
    assert_eq!(t.position(0, nm - 1), None);
    assert!(close(
        t.position(frames - 1, nm - 1).unwrap(),
        [(frames - 1 + nm - 1) as f64 * 1e-3, 2e-3 * (nm - 1) as f64, 3e-3]
    ));
    assert!(close(t.position(2, 5).unwrap(), [7e-3, 10e-3, 3e-3]));
    t.check_consistent().unwrap();
}

#[test]
fn cortex_files_with_a_cut_off_name_row_read_every_marker_the_rows_carry() {
    // As found: NumMarkers 66 above 33 names, rows of 68 markers.
    let t = parse_trc(&cortex(68, 33, 66, 12), "cortex.trc").unwrap();
    check_cortex(&t, 68, 12);
    assert_eq!(&t.labels[..2], ["Marker0", "Marker1"]);
    assert_eq!(t.labels[32], "Marker32");
    // Stable names for the unnamed, by their 1-based column: the 34th marker is M034.
    assert_eq!(t.labels[33], "M034");
    assert_eq!(t.labels[67], "M068");
    let w = t.warnings.iter().find(|w| w.contains("M034")).expect("a warning");
    assert!(w.starts_with("cortex.trc: ") && w.contains("33") && w.contains("68"), "{w}");
    // From disk, held whole or read back frame by frame: the same.
    let dir = std::env::temp_dir().join(format!("smocap-trc-cortex-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cortex.trc");
    std::fs::write(&path, cortex(68, 33, 66, 12)).unwrap();
    check_cortex(&read_trc(&path).unwrap(), 68, 12);
    let (head, rows) = smocap::io::trc::scan_trc(&path, 3).unwrap();
    assert!(head.positions.is_empty() && head.n_markers() == 68);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&rows.read(0..12).unwrap()), bits(&t.positions));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unlabelled_exports_are_read_with_numbered_markers_and_refused_by_the_solver() {
    let t = parse_trc(&cortex(20, 0, 0, 5), "unlabelled.trc").unwrap();
    check_cortex(&t, 20, 5);
    assert_eq!(t.labels[0], "M001");
    let w = t.warnings.iter().find(|w| w.contains("unlabelled")).expect("a warning");
    assert!(w.starts_with("unlabelled.trc: "), "{w}");
    let ctx = smocap::pipeline::Context::shipped().unwrap();
    let e = smocap::pipeline::input::trial::match_markers(&ctx, "unlabelled", &t).unwrap_err();
    assert!(e.to_string().contains("unlabelled") && e.to_string().contains("20 markers"), "{e}");
}

#[test]
fn unnamed_markers_of_a_cut_off_row_never_match_model_markers() {
    let mut text = cortex(8, 3, 8, 4);
    text = text.replace("Marker0", "LASI").replace("Marker1", "RASI");
    let t = parse_trc(&text, "cut.trc").unwrap();
    let ctx = smocap::pipeline::Context::shipped().unwrap();
    let m = smocap::pipeline::input::trial::match_markers(&ctx, "cut", &t).unwrap();
    let matched: Vec<usize> = m.columns.iter().flatten().copied().collect();
    assert_eq!(matched.len(), 2, "{matched:?}");
    assert!(matched.iter().all(|&c| c < 2));
    assert!(m.unmatched_trial.iter().all(|l| !l.starts_with("LASI")));
}

#[test]
fn rows_wider_than_names_and_num_markers_agree_on_are_still_ragged() {
    // NumMarkers equal to the names: no cut-off, so a wider row is an error with its line.
    let e = parse_trc(&cortex(6, 5, 5, 3), "ragged.trc").unwrap_err();
    assert!(matches!(e, TrcError::RaggedRow { n_markers: 5, .. }), "{e}");
    assert!(e.to_string().starts_with("ragged.trc:"), "{e}");
}
