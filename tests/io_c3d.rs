//! C3D reader: the c3d.org Sample01 files against ezc3d, hand-built files for each
//! storage variant, and corrupt input.

use std::path::PathBuf;

use smocap::io::c3d::{parse_c3d, read_c3d, C3dError};
use smocap::io::MarkerTrial;

fn sample(name: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets/c3d_sample01").join(name);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("note: {} absent; test skipped", p.display());
        None
    }
}

fn reference() -> Option<serde_json::Value> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/ezc3d-1.7.2/c3d_sample01.json");
    let text = std::fs::read_to_string(&p).ok()?;
    serde_json::from_str(&text).ok()
}

// ---- a tiny C3D writer, test-only ----

#[derive(Clone, Copy, PartialEq)]
enum Proc {
    Intel,
    Dec,
    Mips,
}

enum Val {
    Chars(Vec<&'static str>, usize),
    Int(Vec<i16>),
    Float(Vec<f32>),
}

struct Build {
    proc: Proc,
    params: Vec<(&'static str, &'static str, Val)>,
    first_frame: u16,
    last_frame: u16,
    points: u16,
    analog_per_frame: u16,
    scale: f32,
    rate: f32,
    /// Data words, already in storage order; i16 when `scale > 0`, else f32.
    data: Vec<f64>,
}

impl Build {
    fn i16(&self, v: i16) -> [u8; 2] {
        if self.proc == Proc::Mips {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    }

    fn f32(&self, v: f32) -> [u8; 4] {
        match self.proc {
            Proc::Intel => v.to_le_bytes(),
            Proc::Mips => v.to_be_bytes(),
            Proc::Dec => {
                let b = if v == 0.0 { [0; 4] } else { (v * 4.0).to_le_bytes() };
                [b[2], b[3], b[0], b[1]]
            }
        }
    }

    fn param_section(&self, data_start: i16) -> Vec<u8> {
        let code = match self.proc {
            Proc::Intel => 84,
            Proc::Dec => 85,
            Proc::Mips => 86,
        };
        let mut s = vec![1, 0x50, 0, code];
        let mut groups: Vec<&str> = Vec::new();
        for (g, _, _) in &self.params {
            if !groups.contains(g) {
                groups.push(g);
            }
        }
        if !groups.contains(&"POINT") {
            groups.push("POINT");
        }
        let gid = |g: &str| groups.iter().position(|x| *x == g).unwrap() as i8 + 1;
        for (i, g) in groups.iter().enumerate() {
            s.extend([g.len() as u8, (-(i as i8 + 1)) as u8]);
            s.extend(g.as_bytes());
            s.extend(self.i16(3));
            s.push(0);
        }
        let ds = ("POINT", "DATA_START", Val::Int(vec![data_start]));
        for (g, n, v) in self.params.iter().chain(std::iter::once(&ds)) {
            let mut body = Vec::new();
            match v {
                Val::Chars(strs, w) => {
                    body.extend([-1i8 as u8, 2, *w as u8, strs.len() as u8]);
                    for st in strs {
                        let mut b = st.as_bytes().to_vec();
                        b.resize(*w, b' ');
                        body.extend(b);
                    }
                }
                Val::Int(xs) => {
                    body.extend([2, 1, xs.len() as u8]);
                    xs.iter().for_each(|&x| body.extend(self.i16(x)));
                }
                Val::Float(xs) => {
                    body.extend([4, 1, xs.len() as u8]);
                    xs.iter().for_each(|&x| body.extend(self.f32(x)));
                }
            }
            body.push(0);
            s.extend([n.len() as u8, gid(g) as u8]);
            s.extend(n.as_bytes());
            s.extend(self.i16(body.len() as i16 + 2));
            s.extend(body);
        }
        s.extend([0, 0, 0, 0]);
        let blocks = s.len().div_ceil(512);
        s[2] = blocks as u8;
        s.resize(blocks * 512, 0);
        s
    }

    fn bytes(&self) -> Vec<u8> {
        let blocks = self.param_section(0).len() / 512;
        let data_start = 2 + blocks as i16;
        let mut h = vec![0u8; 512];
        h[0] = 2;
        h[1] = 0x50;
        let words = [
            (2, self.points as i16),
            (4, self.analog_per_frame as i16),
            (6, self.first_frame as i16),
            (8, self.last_frame as i16),
            (16, data_start),
        ];
        for (o, w) in words {
            h[o..o + 2].copy_from_slice(&self.i16(w));
        }
        h[12..16].copy_from_slice(&self.f32(self.scale));
        h[20..24].copy_from_slice(&self.f32(self.rate));
        let mut out = h;
        out.extend(self.param_section(data_start));
        for &v in &self.data {
            if self.scale > 0.0 {
                out.extend(self.i16(v as i16));
            } else {
                out.extend(self.f32(v as f32));
            }
        }
        out
    }
}

/// `n_frames` frames of `points` points (x, y, z, residual); the point parameters filled in.
fn build(proc: Proc, scale: f32, labels: Vec<&'static str>, frames: &[Vec<[f64; 4]>]) -> Build {
    let points = frames.first().map_or(0, Vec::len) as u16;
    let n = frames.len() as i16;
    Build {
        proc,
        params: vec![
            ("POINT", "USED", Val::Int(vec![points as i16])),
            ("POINT", "FRAMES", Val::Int(vec![n])),
            ("POINT", "SCALE", Val::Float(vec![scale])),
            ("POINT", "RATE", Val::Float(vec![100.0])),
            ("POINT", "UNITS", Val::Chars(vec!["mm"], 4)),
            ("POINT", "LABELS", Val::Chars(labels, 4)),
        ],
        first_frame: 1,
        last_frame: n as u16,
        points,
        analog_per_frame: 0,
        scale,
        rate: 100.0,
        data: frames.iter().flatten().flatten().copied().collect(),
    }
}

fn frames_abc() -> Vec<Vec<[f64; 4]>> {
    vec![vec![[10.0, 20.0, 30.0, 1.0], [-4.0, 5.0, 6.0, 0.0]], vec![[11.0, 21.0, 31.0, 1.0], [7.0, 8.0, 9.0, -1.0]]]
}

fn check_abc(t: &MarkerTrial, scale: f64) {
    assert_eq!(t.labels, ["A", "B"]);
    assert_eq!((t.n_frames(), t.rate_hz, t.source_units.as_str()), (2, 100.0, "mm"));
    assert_eq!(t.frame_numbers, [1, 2]);
    assert_eq!(t.times, [0.0, 0.01]);
    let p = t.position(1, 0).unwrap();
    for (a, b) in p.iter().zip([11.0, 21.0, 31.0]) {
        assert!((a - b * scale / 1000.0).abs() < 1e-12, "{p:?}");
    }
    assert_eq!(t.position(0, 1).map(|p| p[0]), Some(-4.0 * scale / 1000.0));
    assert_eq!(t.position(1, 1), None, "negative residual is a gap");
    t.check_consistent().unwrap();
}

#[test]
fn integer_and_float_storage_read_alike_on_every_processor() {
    for proc in [Proc::Intel, Proc::Dec, Proc::Mips] {
        let int = build(proc, 0.5, vec!["A", "B"], &frames_abc()).bytes();
        check_abc(&parse_c3d(&int, "int.c3d").unwrap(), 0.5);
        let float = build(proc, -0.5, vec!["A", "B"], &frames_abc()).bytes();
        check_abc(&parse_c3d(&float, "float.c3d").unwrap(), 1.0);
    }
}

#[test]
fn mips_files_are_big_endian_and_unknown_processors_fail() {
    let mut b = build(Proc::Mips, 0.5, vec!["A", "B"], &frames_abc()).bytes();
    assert_eq!(b[512 + 3], 86);
    check_abc(&parse_c3d(&b, "mips.c3d").unwrap(), 0.5);
    b[512 + 3] = 99;
    let e = parse_c3d(&b, "mips.c3d").unwrap_err();
    assert!(matches!(e, C3dError::UnknownProcessor { code: 99, .. }), "{e}");
}

#[test]
fn labels2_continues_labels_and_missing_labels_are_named() {
    let frame: Vec<[f64; 4]> = (0..4).map(|i| [i as f64, 0.0, 0.0, 0.0]).collect();
    let mut b = build(Proc::Intel, -1.0, vec!["P1", "P2"], std::slice::from_ref(&frame));
    b.params.push(("POINT", "LABELS2", Val::Chars(vec!["P3  "], 4)));
    let t = parse_c3d(&b.bytes(), "l2.c3d").unwrap();
    assert_eq!(t.labels, ["P1", "P2", "P3", "POINT4"]);
    assert!(t.warnings.iter().any(|w| w.contains("POINT<i>")), "{:?}", t.warnings);
    assert_eq!(t.position(0, 3), Some([0.003, 0.0, 0.0]));
}

#[test]
fn analog_samples_between_frames_are_skipped() {
    // 1 point, 2 channels x 3 samples per frame (300 Hz analog, 100 Hz points); analog
    // rate stored as a float and ANALOG:OFFSET as floats, as some writers do.
    let mut b = build(Proc::Intel, 0.25, vec!["A"], &[]);
    b.points = 1;
    b.params[0] = ("POINT", "USED", Val::Int(vec![1]));
    b.params[1] = ("POINT", "FRAMES", Val::Int(vec![3]));
    b.last_frame = 3;
    b.analog_per_frame = 6;
    b.params.push(("ANALOG", "USED", Val::Int(vec![2])));
    b.params.push(("ANALOG", "RATE", Val::Float(vec![300.0])));
    b.params.push(("ANALOG", "OFFSET", Val::Float(vec![2048.0, 0.5])));
    for f in 0..3 {
        b.data.extend([f as f64 * 4.0, 8.0, 12.0, 0.0]);
        b.data.extend([-7.0; 6]);
    }
    let t = parse_c3d(&b.bytes(), "analog.c3d").unwrap();
    assert_eq!(t.n_frames(), 3);
    for f in 0..3 {
        assert_eq!(t.position(f, 0), Some([f as f64 * 1e-3, 2e-3, 3e-3]));
    }
    assert!(t.warnings.is_empty(), "{:?}", t.warnings);
}

#[test]
fn frame_counts_past_65535_come_from_trial_fields() {
    let n: u32 = 70_000;
    let mut b = build(Proc::Intel, 1.0, vec!["A"], &[vec![[1.0, 2.0, 3.0, 0.0]]]);
    b.last_frame = n as u16; // wrapped, as in real files
    b.params[1] = ("POINT", "FRAMES", Val::Int(vec![n as u16 as i16]));
    b.params.push(("TRIAL", "ACTUAL_START_FIELD", Val::Int(vec![1, 0])));
    b.params.push(("TRIAL", "ACTUAL_END_FIELD", Val::Int(vec![(n & 0xffff) as u16 as i16, (n >> 16) as i16])));
    // Only the first frame written: the reader must ask for all 70000.
    let e = parse_c3d(&b.bytes(), "long.c3d").unwrap_err();
    assert!(e.to_string().contains("70000 frames"), "{e}");
    b.data = (0..n).flat_map(|f| [(f % 1000) as f64, 2.0, 3.0, 0.0]).collect();
    let t = parse_c3d(&b.bytes(), "long.c3d").unwrap();
    assert_eq!(t.n_frames(), n as usize);
    assert_eq!(t.frame_numbers.last(), Some(&(n as i64)));
    assert_eq!(t.position(69_999, 0), Some([0.999, 0.002, 0.003]));
}

#[test]
fn sample01_intel_and_dec_files_read_identically() {
    let (Some(pi), Some(vi)) = (sample("Eb015pi.c3d"), sample("Eb015vi.c3d")) else { return };
    let a = read_c3d(&pi).unwrap();
    let b = read_c3d(&vi).unwrap();
    assert_eq!((a.n_frames(), a.n_markers(), a.rate_hz, a.source_units.as_str()), (450, 26, 50.0, "mm"));
    assert_eq!(a.labels, b.labels);
    assert_eq!((a.rate_hz, &a.times, &a.frame_numbers), (b.rate_hz, &b.times, &b.frame_numbers));
    assert_eq!(a.frame_numbers[0], 1);
    let max =
        a.positions.iter().zip(&b.positions).map(|(x, y)| if x.is_nan() && y.is_nan() { 0.0 } else { (x - y).abs() });
    let max = max.fold(0.0, f64::max);
    println!("Intel vs DEC: max |difference| = {max:e} m");
    assert!(max == 0.0, "max difference {max}");
    assert!(a.warnings.is_empty() && b.warnings.is_empty(), "{:?} {:?}", a.warnings, b.warnings);
}

#[test]
fn sample01_matches_ezc3d_reference() {
    let Some(r) = reference() else {
        eprintln!("note: ezc3d reference absent; test skipped");
        return;
    };
    for name in ["Eb015pi.c3d", "Eb015vi.c3d"] {
        let Some(path) = sample(name) else { return };
        let t = read_c3d(&path).unwrap();
        let r = &r[name];
        assert_eq!(t.n_frames() as u64, r["frames"].as_u64().unwrap());
        assert_eq!(t.n_markers() as u64, r["points"].as_u64().unwrap());
        assert_eq!(t.rate_hz, r["point_rate_hz"].as_f64().unwrap());
        assert_eq!(t.source_units, r["units"].as_str().unwrap());
        let labels: Vec<&str> = r["labels"].as_array().unwrap().iter().map(|l| l.as_str().unwrap()).collect();
        assert_eq!(t.labels, labels[..26]);
        let invalid: Vec<usize> =
            r["invalid_samples_per_point"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
        assert_eq!(t.gap_counts(), invalid);
        let mm = |v: f64| v * 1000.0; // the reference is in the file's units, mm
        let (mut d_mean, mut d_f0) = (0.0f64, 0.0f64);
        let mut sum_abs = 0.0;
        for m in 0..26 {
            let valid: Vec<[f64; 3]> = t.trajectory(m).into_iter().flatten().collect();
            for axis in 0..3 {
                let mean = valid.iter().map(|p| mm(p[axis])).sum::<f64>() / valid.len() as f64;
                d_mean = d_mean.max((mean - r["mean_xyz_over_valid_frames"][m][axis].as_f64().unwrap()).abs());
                let f0 = &r["frame0_xyz"][m][axis];
                match (t.position(0, m), f0.as_f64()) {
                    (Some(p), Some(x)) => d_f0 = d_f0.max((mm(p[axis]) - x).abs()),
                    (None, None) => {}
                    (p, x) => panic!("{name} point {m} frame 0: ours {p:?}, ezc3d {x:?}"),
                }
                sum_abs += valid.iter().map(|p| mm(p[axis]).abs()).sum::<f64>();
            }
        }
        let d_sum = (sum_abs - r["sum_abs_valid"].as_f64().unwrap()).abs();
        println!("{name}: max |mean diff| {d_mean:e} mm, frame 0 {d_f0:e} mm, sum |x| diff {d_sum:e} mm");
        assert!(d_mean < 1e-9 && d_f0 < 1e-9 && d_sum < 1e-6, "{d_mean} {d_f0} {d_sum}");
    }
}

#[test]
fn every_truncation_of_sample01_fails_cleanly() {
    let Some(path) = sample("Eb015pi.c3d") else { return };
    let bytes = std::fs::read(path).unwrap();
    let needed = 512 * 10 + 450 * (26 * 4 + 16 * 4) * 2;
    for len in (0..bytes.len()).step_by(97).chain([needed - 1, needed]) {
        match parse_c3d(&bytes[..len], "cut.c3d") {
            Ok(t) => assert!(len >= needed && t.n_frames() == 450, "length {len} read"),
            Err(e) => assert!(e.to_string().starts_with("cut.c3d: "), "{e}"),
        }
    }
}

#[test]
fn random_byte_mutations_never_panic() {
    let Some(path) = sample("Eb015pi.c3d") else { return };
    let bytes = std::fs::read(path).unwrap();
    let mut s: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let (mut ok, mut err) = (0, 0);
    for _ in 0..3000 {
        let mut b = bytes.clone();
        let n = 1 + next() % 8;
        for _ in 0..n {
            // Mostly the header and parameter section, where the structure lives.
            let at = if next() % 4 == 0 { next() as usize % b.len() } else { next() as usize % (512 * 10) };
            b[at] = next() as u8;
        }
        match parse_c3d(&b, "mut.c3d") {
            Ok(t) => {
                t.check_consistent().unwrap();
                ok += 1;
            }
            Err(e) => {
                assert!(e.to_string().starts_with("mut.c3d: "), "{e}");
                err += 1;
            }
        }
    }
    println!("mutations: {ok} read, {err} rejected");
}

// ---- vendor quirks: each tolerance read with a warning naming the file ----

/// Overwrites the value of `POINT:DATA_START` (an int16 after its 10-character name, the
/// next-record offset, type, dimension count and dimension) in a built file.
fn set_data_start_param(bytes: &mut [u8], proc: Proc, v: i16) {
    let at = bytes.windows(10).position(|w| w == b"DATA_START").expect("a DATA_START parameter") + 10 + 5;
    let b = if proc == Proc::Mips { v.to_be_bytes() } else { v.to_le_bytes() };
    bytes[at..at + 2].copy_from_slice(&b);
}

#[test]
fn units_cut_to_their_dimension_read_as_the_unit_they_begin() {
    for (units, width, scale) in [("mete", 4, 1000.0), ("millimete", 9, 1.0), ("centim", 6, 10.0), ("inc", 3, 25.4)] {
        let mut b = build(Proc::Intel, -1.0, vec!["A", "B"], &frames_abc());
        b.params[4] = ("POINT", "UNITS", Val::Chars(vec![units], width));
        let t = parse_c3d(&b.bytes(), "cut_units.c3d").unwrap();
        let p = t.position(1, 0).unwrap();
        assert!((p[0] - 11.0 * scale / 1000.0).abs() < 1e-9, "{units}: {p:?}");
        assert_eq!(t.source_units, units);
        let w = t.warnings.iter().find(|w| w.contains("POINT:UNITS")).expect("a warning");
        assert!(w.starts_with("cut_units.c3d: ") && w.contains(units), "{w}");
    }
    // Too short to say, or no unit at all: still an error naming the file and the units.
    for units in ["me", "furl"] {
        let mut b = build(Proc::Intel, -1.0, vec!["A", "B"], &frames_abc());
        b.params[4] = ("POINT", "UNITS", Val::Chars(vec![units], 4));
        let e = parse_c3d(&b.bytes(), "bad_units.c3d").unwrap_err();
        assert!(matches!(&e, C3dError::UnknownUnits { units: u, .. } if u == units), "{e}");
        assert!(e.to_string().starts_with("bad_units.c3d: "), "{e}");
    }
}

#[test]
fn a_zero_or_wrong_data_start_parameter_gives_way_to_the_header_that_fits_the_file() {
    for proc in [Proc::Intel, Proc::Mips] {
        for param in [0i16, 1, 40] {
            let mut bytes = build(proc, 0.5, vec!["A", "B"], &frames_abc()).bytes();
            set_data_start_param(&mut bytes, proc, param);
            let t = parse_c3d(&bytes, "phoenix.c3d").unwrap();
            check_abc(&t, 0.5);
            let w = t.warnings.iter().find(|w| w.contains("DATA_START")).expect("a warning");
            assert!(w.starts_with("phoenix.c3d: ") && w.contains(&format!("is {param}")), "{w}");
        }
    }
    // Both pointing nowhere sensible: a clean error.
    let mut bytes = build(Proc::Intel, 0.5, vec!["A", "B"], &frames_abc()).bytes();
    set_data_start_param(&mut bytes, Proc::Intel, 0);
    bytes[16..18].copy_from_slice(&0i16.to_le_bytes());
    let e = parse_c3d(&bytes, "nowhere.c3d").unwrap_err();
    assert!(e.to_string().starts_with("nowhere.c3d: ") && e.to_string().contains("data start"), "{e}");
}

#[test]
fn sgi_files_with_a_long_big_endian_parameter_section_read_as_their_intel_twins() {
    // 120 labelled points: LABELS spans several blocks, so next-record offsets exceed 255 and
    // their byte order matters; float and integer data; a subject's parameters too.
    let names: Vec<&'static str> =
        (0..120).map(|i| &*Box::leak(format!("MK{i:03}").into_boxed_str())).collect::<Vec<_>>();
    let frame: Vec<[f64; 4]> = (0..120).map(|i| [i as f64, -(i as f64), 2.0 * i as f64, 1.0]).collect();
    for scale in [0.5f32, -1.0] {
        let build_for = |proc| {
            let mut b = build(proc, scale, names.clone(), &[frame.clone(), frame.clone()]);
            b.params[5] = ("POINT", "LABELS", Val::Chars(names.clone(), 5));
            b.params.push(("SUBJECTS", "NAMES", Val::Chars(vec!["Pat"], 3)));
            b.params.push(("PROCESSING", "Height", Val::Float(vec![1790.0])));
            b.bytes()
        };
        let (sgi, intel) = (build_for(Proc::Mips), build_for(Proc::Intel));
        assert_eq!(sgi[512 + 3], 86);
        let (a, b) = (parse_c3d(&sgi, "sgi.c3d").unwrap(), parse_c3d(&intel, "pc.c3d").unwrap());
        assert_eq!(a.labels.len(), 120);
        assert_eq!(a.labels, b.labels);
        assert_eq!(a.positions, b.positions);
        let s = scale.abs() as f64;
        assert_eq!(a.position(1, 7), Some([7.0 * s / 1000.0, -7.0 * s / 1000.0, 14.0 * s / 1000.0]));
    }
}
