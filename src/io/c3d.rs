//! C3D motion-capture files: the 3D point (marker) data, as a [`MarkerTrial`].
//!
//! Layout: 512-byte blocks. Block 1 is the header (byte 0: the first parameter block,
//! 1-based); the parameter section starts there (byte 3: processor type 84 Intel,
//! 85 DEC/VAX, 86 MIPS big-endian) and holds groups and parameters; the data start at
//! block `POINT:DATA_START`. Each frame holds `POINT:USED` points of four words
//! (x, y, z, residual/camera word), as int16 scaled by `POINT:SCALE` when the scale is
//! positive or as floats when it is negative, then the frame's analog samples, which
//! are skipped. A negative residual word marks an invalid sample: a gap (NaN).
//! Positions are converted to metres from `POINT:UNITS`, in the file's lab frame.

mod params;
mod subject;

pub use subject::{parse_subject, read_subject, C3dSubject};

use std::path::Path;

use super::markers::{per_metre, units_to_metres, MarkerTrial};
use params::Params;

/// Why a C3D file could not be read; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum C3dError {
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}: truncated: {what} needs {needed} bytes but the file has {len}")]
    Truncated { file: String, what: String, needed: u64, len: usize },
    #[error("{file}: bad parameter-section pointer {pointer} in header byte 1: {why}")]
    BadParameterPointer { file: String, pointer: u8, why: String },
    #[error("{file}: unknown processor type {code} (expected 84 Intel, 85 DEC or 86 MIPS)")]
    UnknownProcessor { file: String, code: u8 },
    #[error("{file}: malformed parameter section at byte {offset}: {what}")]
    BadParameter { file: String, offset: usize, what: String },
    #[error("{file}: unknown POINT:UNITS {units:?} (expected mm, cm, m or in)")]
    UnknownUnits { file: String, units: String },
    #[error("{file}: {what}")]
    BadValue { file: String, what: String },
}

/// Reads a C3D file; positions in metres, in the file's lab frame.
pub fn read_c3d(path: &Path) -> Result<MarkerTrial, C3dError> {
    scan_c3d(path, usize::MAX).map(|(t, _)| t)
}

/// Where a C3D file keeps its point frames, to read them on demand ([`C3dFrames::read`]).
#[derive(Clone, Debug)]
pub struct C3dFrames {
    file: String,
    path: std::path::PathBuf,
    proc: params::Proc,
    /// Byte offset of frame 0 and bytes per frame.
    data_off: u64,
    stride: usize,
    n_points: usize,
    n_frames: usize,
    /// Float frames (`POINT:SCALE` < 0), else int16 times `scale`.
    is_float: bool,
    scale: f64,
    per_m: f64,
}

/// Reads a C3D file as [`read_c3d`] does, a block of frames at a time (the file is never held
/// whole), holding the positions only when it has at most `keep` frames (otherwise `positions`
/// is empty and frames are read on demand through the returned [`C3dFrames`]).
pub fn scan_c3d(path: &Path, keep: usize) -> Result<(MarkerTrial, C3dFrames), C3dError> {
    use std::io::{Read, Seek};
    let file = path.display().to_string();
    let io = |source| C3dError::Io { file: file.clone(), source };
    let mut f = std::fs::File::open(path).map_err(io)?;
    let len = f.metadata().map_err(io)?.len();
    // The header and parameter section: a prefix that grows until the parameters parse (the
    // last try reads the whole file, so errors are as for the whole file).
    let mut want = (64u64 << 10).min(len);
    let (mut trial, frames) = loop {
        let mut prefix = vec![0u8; want as usize];
        f.seek(std::io::SeekFrom::Start(0)).map_err(io)?;
        f.read_exact(&mut prefix).map_err(io)?;
        match layout(&prefix, len, &file) {
            Err(C3dError::Truncated { .. } | C3dError::BadParameterPointer { .. }) if want < len => {
                want = want.saturating_mul(4).min(len);
            }
            other => break other?,
        }
    };
    let mut frames = frames;
    frames.path = path.to_path_buf();
    let n = frames.n_frames;
    if n <= keep {
        trial.positions = frames.read(0..n)?;
    }
    Ok((trial, frames))
}

impl C3dFrames {
    /// Frames in the file.
    pub fn n_frames(&self) -> usize {
        self.n_frames
    }

    /// Positions of frames `range` (metres, frame-major as [`MarkerTrial::positions`]), read
    /// from the file a block at a time.
    pub fn read(&self, range: std::ops::Range<usize>) -> Result<Vec<f64>, C3dError> {
        use std::io::{Read, Seek};
        let io = |source| C3dError::Io { file: self.file.clone(), source };
        let range = range.start.min(self.n_frames)..range.end.min(self.n_frames);
        let mut out = Vec::with_capacity(range.len() * self.n_points * 3);
        if range.is_empty() {
            return Ok(out);
        }
        let mut f = std::fs::File::open(&self.path).map_err(io)?;
        f.seek(std::io::SeekFrom::Start(self.data_off + (range.start * self.stride) as u64)).map_err(io)?;
        let per_block = ((1usize << 20) / self.stride.max(1)).max(1);
        let mut buf = Vec::new();
        let mut at = range.start;
        while at < range.end {
            let k = per_block.min(range.end - at);
            buf.resize(k * self.stride, 0);
            f.read_exact(&mut buf).map_err(io)?;
            self.decode(&buf, &mut out);
            at += k;
        }
        Ok(out)
    }

    /// Appends the positions of the whole frames in `bytes`.
    fn decode(&self, bytes: &[u8], out: &mut Vec<f64>) {
        let proc = self.proc;
        for frame in bytes.chunks_exact(self.stride.max(1)) {
            for p in 0..self.n_points {
                let (xyz, valid) = if self.is_float {
                    let w = &frame[p * 16..p * 16 + 16];
                    let v = [0, 4, 8, 12].map(|o| f64::from(proc.f32(&w[o..o + 4])));
                    ([v[0], v[1], v[2]], v[3] >= 0.0)
                } else {
                    let w = &frame[p * 8..p * 8 + 8];
                    let v = [0, 2, 4, 6].map(|o| proc.i16(&w[o..o + 2]));
                    ([0, 1, 2].map(|a| f64::from(v[a]) * self.scale), v[3] >= 0)
                };
                if valid && xyz.iter().all(|v| v.is_finite()) {
                    out.extend(xyz.map(|v| v / self.per_m));
                } else {
                    out.extend([f64::NAN; 3]);
                }
            }
        }
    }
}

/// Where the header keeps each field (byte offsets of 16-bit words and floats).
mod hdr {
    pub const POINTS: usize = 2;
    pub const ANALOG_PER_FRAME: usize = 4;
    pub const FIRST_FRAME: usize = 6;
    pub const LAST_FRAME: usize = 8;
    pub const SCALE: usize = 12;
    pub const DATA_START: usize = 16;
    pub const RATE: usize = 20;
}

/// Parses the bytes of a C3D file; `name_for_errors` names the source in errors.
pub fn parse_c3d(bytes: &[u8], name_for_errors: &str) -> Result<MarkerTrial, C3dError> {
    let (mut trial, frames) = layout(bytes, bytes.len() as u64, name_for_errors)?;
    let start = frames.data_off as usize;
    frames.decode(&bytes[start..start + frames.n_frames * frames.stride], &mut trial.positions);
    Ok(trial)
}

/// The trial without its positions and where its frames are, from the file's first bytes
/// (`bytes`, at least the header and the parameter section) and its length `len`.
fn layout(bytes: &[u8], len: u64, name_for_errors: &str) -> Result<(MarkerTrial, C3dFrames), C3dError> {
    let file = name_for_errors.to_string();
    let bad = |what: String| C3dError::BadValue { file: file.clone(), what };
    if bytes.len() < 512 {
        let what = "the 512-byte header".to_string();
        return Err(C3dError::Truncated { file, what, needed: 512, len: len as usize });
    }
    let mut warnings = Vec::new();
    if bytes[1] != 0x50 {
        warnings.push(format!("header byte 2 is {} instead of 80 (0x50)", bytes[1]));
    }
    let params = Params::parse(bytes, &file)?;
    let proc = params.proc;
    let u16_at = |off: usize| proc.i16(&bytes[off..off + 2]) as u16;
    let f32_at = |off: usize| proc.f32(&bytes[off..off + 4]);

    let n_points = params.uint("POINT", "USED").unwrap_or_else(|| u64::from(u16_at(hdr::POINTS))) as usize;
    let scale = params.float("POINT", "SCALE").unwrap_or_else(|| f64::from(f32_at(hdr::SCALE)));
    let rate_hz = params.float("POINT", "RATE").unwrap_or_else(|| f64::from(f32_at(hdr::RATE)));
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(bad(format!("point rate {rate_hz} Hz is not a positive finite number")));
    }
    if !scale.is_finite() {
        return Err(bad(format!("POINT:SCALE {scale} is not finite")));
    }
    if scale == 0.0 && n_points > 0 {
        warnings.push("POINT:SCALE is 0; integer coordinates read as 0".into());
    }

    // Frame count and first frame number: TRIAL fields (32-bit) when present, else
    // POINT:FRAMES / the header.
    let first_hdr = u64::from(u16_at(hdr::FIRST_FRAME));
    let last_hdr = u64::from(u16_at(hdr::LAST_FRAME));
    let trial = (params.u32_pair("TRIAL", "ACTUAL_START_FIELD"), params.u32_pair("TRIAL", "ACTUAL_END_FIELD"));
    let (first_frame, n_frames) = match trial {
        (Some(s), Some(e)) if e >= s => {
            if s != first_hdr {
                warnings.push(format!("TRIAL:ACTUAL_START_FIELD {s} differs from header first frame {first_hdr}"));
            }
            (s, e - s + 1)
        }
        _ => {
            let n = params.uint("POINT", "FRAMES").unwrap_or_else(|| (last_hdr + 1).saturating_sub(first_hdr));
            (first_hdr, n)
        }
    };

    // Analog words per frame, skipped.
    let channels = params.uint("ANALOG", "USED").unwrap_or(0);
    let hdr_analog = u64::from(u16_at(hdr::ANALOG_PER_FRAME));
    let analog_words = match params.float("ANALOG", "RATE") {
        Some(ar) if channels > 0 && ar.is_finite() && ar >= 0.0 => {
            let per = ar / rate_hz;
            if (per - per.round()).abs() > 1e-6 {
                warnings.push(format!("ANALOG:RATE {ar} is not a whole multiple of POINT:RATE {rate_hz}"));
            }
            let w = channels.saturating_mul(per.round().min(1e9) as u64);
            if w != hdr_analog && w < 65536 {
                warnings.push(format!("header says {hdr_analog} analog samples per frame, parameters {w}"));
            }
            w
        }
        _ => hdr_analog,
    };

    let units = match params.string("POINT", "UNITS") {
        Some(u) if !u.is_empty() => u,
        _ => {
            warnings.push("no POINT:UNITS; assuming mm".into());
            "mm".into()
        }
    };
    let unit_scale = match units_to_metres(&units) {
        Some(s) => s,
        None => {
            let (name, s) = truncated_units(&units)
                .ok_or_else(|| C3dError::UnknownUnits { file: file.clone(), units: clip(&units) })?;
            warnings.push(format!("{file}: POINT:UNITS {units:?} read as {name} (a unit name cut to its dimension)"));
            s
        }
    };
    let per_m = per_metre(unit_scale);

    // Data block and size checks before any allocation sized by the file's counts.
    let is_float = scale < 0.0;
    let word = if is_float { 4u64 } else { 2 };
    let stride = (n_points as u64 * 4).saturating_add(analog_words).saturating_mul(word);
    let header_start = u64::from(u16_at(hdr::DATA_START));
    let start_block = match params.uint("POINT", "DATA_START") {
        None => header_start,
        Some(p) if p == header_start => p,
        Some(p) => {
            let first_param = u64::from(bytes[0]);
            let chosen = data_start(p, header_start, first_param, stride.saturating_mul(n_frames), len);
            if chosen != p {
                warnings.push(format!(
                    "{file}: POINT:DATA_START is {p} but the header names block {header_start}; \
                     block {chosen} read (the one consistent with the file's size)"
                ));
            }
            chosen
        }
    };
    if start_block < 2 {
        return Err(bad(format!("data start block {start_block} is before the parameter section")));
    }
    let data_off = (start_block - 1) * 512;
    let needed = data_off.saturating_add(stride.saturating_mul(n_frames));
    if needed > len {
        let what = format!(
            "{n_frames} frames of {n_points} points and {analog_words} analog samples from block {start_block}"
        );
        return Err(C3dError::Truncated { file, what, needed, len: len as usize });
    }
    if stride == 0 && n_frames > len {
        return Err(bad(format!("{n_frames} frames without points or analog data")));
    }
    let (n_frames, data_off, stride) = (n_frames as usize, data_off as usize, stride as usize);

    let labels = point_labels(&params, n_points, &mut warnings);
    let frame_numbers = (0..n_frames).map(|i| (first_frame + i as u64) as i64).collect();
    let times = (0..n_frames).map(|i| i as f64 / rate_hz).collect();
    warnings.extend(params.warnings);
    let trial =
        MarkerTrial { labels, rate_hz, times, frame_numbers, positions: Vec::new(), source_units: units, warnings };
    let frames = C3dFrames {
        path: file.clone().into(),
        file,
        proc,
        data_off: data_off as u64,
        stride,
        n_points,
        n_frames,
        is_float,
        scale,
        per_m,
    };
    Ok((trial, frames))
}

/// Of the data start blocks named by `POINT:DATA_START` (`param`) and the header (`header`), the
/// one consistent with a file of `len` bytes holding `data` bytes of frames after the parameter
/// section (which starts at block `first_param`): past the parameter section, and the frames
/// fitting in the file with the least left over; the parameter when neither or both fit alike.
fn data_start(param: u64, header: u64, first_param: u64, data: u64, len: u64) -> u64 {
    let slack = |b: u64| {
        let end = b.saturating_sub(1).saturating_mul(512).saturating_add(data);
        (b > first_param && end <= len).then(|| len - end)
    };
    match (slack(param), slack(header)) {
        (None, Some(_)) => header,
        (Some(p), Some(h)) if h < p => header,
        _ => param,
    }
}

/// A length unit cut short (C3D stores `POINT:UNITS` in as many characters as its dimension
/// says: `mete`, `millimete`, `centim`), when at least three characters name one unit: its
/// short name and metres per unit.
fn truncated_units(units: &str) -> Option<(&'static str, f64)> {
    let u = units.trim().to_ascii_lowercase();
    if u.len() < 3 {
        return None;
    }
    let families: [(&str, f64, &[&str]); 4] = [
        ("mm", 1e-3, &["millimeters", "millimetres"]),
        ("cm", 1e-2, &["centimeters", "centimetres"]),
        ("m", 1.0, &["meters", "metres"]),
        ("in", 0.0254, &["inches"]),
    ];
    let hits: Vec<(&'static str, f64)> =
        families.iter().filter(|(_, _, long)| long.iter().any(|l| l.starts_with(&u))).map(|f| (f.0, f.1)).collect();
    match hits.as_slice() {
        [one] => Some(*one),
        _ => None,
    }
}

/// `POINT:LABELS`, `LABELS2`, `LABELS3`, ... concatenated, cut or padded (`POINT<i>`,
/// 1-based) to `n` names.
fn point_labels(params: &Params, n: usize, warnings: &mut Vec<String>) -> Vec<String> {
    let mut all = params.strings("POINT", "LABELS").unwrap_or_default();
    for k in 2.. {
        if all.len() >= n {
            break;
        }
        match params.strings("POINT", &format!("LABELS{k}")) {
            Some(more) => all.extend(more),
            None => break,
        }
    }
    all.truncate(n);
    let mut unnamed = Vec::new();
    let labels: Vec<String> = (0..n)
        .map(|i| match all.get(i).filter(|s| !s.is_empty()) {
            Some(s) => s.clone(),
            None => {
                unnamed.push(i + 1);
                format!("POINT{}", i + 1)
            }
        })
        .collect();
    if !unnamed.is_empty() {
        warnings.push(format!("{} of {n} points have no label; named POINT<i>: {unnamed:?}", unnamed.len()));
    }
    let mut seen = std::collections::HashSet::new();
    for l in &labels {
        if !seen.insert(l.clone()) {
            warnings.push(format!("duplicate point label {l:?}"));
        }
    }
    labels
}

/// At most 40 characters of `s`, for error messages.
fn clip(s: &str) -> String {
    match s.char_indices().nth(40) {
        Some((i, _)) => format!("{}...", &s[..i]),
        None => s.to_string(),
    }
}
