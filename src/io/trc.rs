//! OpenSim / Motion Analysis TRC marker files (`PathFileType 4 (X/Y/Z)`).
//!
//! Layout: line 1 `PathFileType`; line 2 header field names; line 3 their values
//! (read by name); line 4 `Frame# Time` and the marker labels, each followed by two
//! empty cells; line 5 `X1 Y1 Z1 ...`; then one row per frame: `frame time x y z ...`.
//! Positions are converted to metres on reading. Empty cells, `NaN` and missing
//! trailing cells are gaps; if any axis of a marker is missing the whole marker is.

use std::io::{BufRead, BufReader};
use std::path::Path;

mod cells;
mod write;

use super::decimal::parse_f64;
use super::markers::{per_metre, units_to_metres, MarkerTrial};
use cells::{cell_spans, cells, clip, header_pairs, labels_of, parse_frame, Cells};
pub use write::{to_trc_string, write_trc};

/// Why a TRC file could not be read or written. `line` is 1-based.
#[derive(Debug, thiserror::Error)]
pub enum TrcError {
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}:{line}: missing or malformed header: expected {expected}")]
    MissingHeader { file: String, line: usize, expected: String },
    #[error("{file}:{line}: header field {field} = {value:?} is not a positive number")]
    BadHeaderValue { file: String, line: usize, field: String, value: String },
    #[error("{file}:{line}: unknown units {units:?} (expected mm, cm, m or in)")]
    UnknownUnits { file: String, line: usize, units: String },
    #[error("{file}:{line}: column {column} is not a number: {value:?}")]
    NonNumeric { file: String, line: usize, column: usize, value: String },
    #[error(
        "{file}:{line}: row has {found} coordinate cells but {n_markers} markers allow {}: line 4 names {n_markers} \
         markers and NumMarkers agrees (or is absent), so the extra cells are no marker's; to read them, name \
         every marker on line 4 and set NumMarkers to their number, or remove the extra cells",
        3 * n_markers
    )]
    RaggedRow { file: String, line: usize, found: usize, n_markers: usize },
    #[error("{file}:{line}: no data rows")]
    NoData { file: String, line: usize },
    #[error("{file}: cannot write trial: {what}")]
    Unwritable { file: String, what: String },
}

impl TrcError {
    /// The 1-based line the error refers to, if any.
    pub fn line(&self) -> Option<usize> {
        match self {
            TrcError::MissingHeader { line, .. }
            | TrcError::BadHeaderValue { line, .. }
            | TrcError::UnknownUnits { line, .. }
            | TrcError::NonNumeric { line, .. }
            | TrcError::RaggedRow { line, .. }
            | TrcError::NoData { line, .. } => Some(*line),
            TrcError::Io { .. } | TrcError::Unwritable { .. } => None,
        }
    }
}

/// Reads a TRC file; positions in metres. Non-UTF-8 bytes are replaced (with a warning).
///
/// The file is read a line at a time: what is held is the trial's arrays, not its text.
pub fn read_trc(path: &Path) -> Result<MarkerTrial, TrcError> {
    scan_trc(path, usize::MAX).map(|(t, _)| t)
}

/// Where each frame's row starts in a TRC file, to read frames again on demand
/// ([`TrcRows::read`]).
#[derive(Clone, Debug)]
pub struct TrcRows {
    file: String,
    path: std::path::PathBuf,
    /// Byte offset and 1-based line number of each frame's row.
    rows: Vec<(u64, u32)>,
    /// Line breaks: `\n` (a trailing `\r` dropped) or `\r` alone.
    eol: u8,
    per_m: f64,
    n_markers: usize,
}

/// Reads a TRC file as [`read_trc`] does, holding the positions only when the file has at most
/// `keep` frames (otherwise `positions` is empty and frames are read on demand through the
/// returned [`TrcRows`]); every row is parsed, so errors are found here either way.
pub fn scan_trc(path: &Path, keep: usize) -> Result<(MarkerTrial, TrcRows), TrcError> {
    let file = path.display().to_string();
    let io = |source| TrcError::Io { file: file.clone(), source };
    let f = std::fs::File::open(path).map_err(io)?;
    let size = f.metadata().map_or(0, |m| m.len());
    let mut r = BufReader::with_capacity(1 << 16, f);
    // Classic Mac line endings (CR only): each CR ends a line (decided on the first block).
    let first = r.fill_buf().map_err(io)?;
    let eol = if !first.contains(&b'\n') && first.contains(&b'\r') { b'\r' } else { b'\n' };
    let mut buf = Vec::new();
    let mut lossy = false;
    let mut p = Parser::new(&file, size);
    p.keep = keep;
    let mut at = 0u64;
    loop {
        buf.clear();
        let n = r.read_until(eol, &mut buf).map_err(io)?;
        if n == 0 {
            break;
        }
        p.offset = at;
        at += n as u64;
        let line = text_of(trim_eol(&mut buf, eol));
        lossy |= matches!(line, std::borrow::Cow::Owned(_));
        p.line(&line)?;
    }
    let per_m = p.header.as_ref().map_or(1.0, |h| h.per_m);
    let rows = std::mem::take(&mut p.offsets);
    let mut trial = p.finish()?;
    if lossy {
        trial.warnings.push("file is not valid UTF-8; bad bytes replaced".into());
    }
    let n_markers = trial.n_markers();
    Ok((trial, TrcRows { file, path: path.to_path_buf(), rows, eol, per_m, n_markers }))
}

/// `bytes` as text, bad UTF-8 replaced (as `String::from_utf8_lossy`; valid UTF-8, the usual
/// case, is checked faster than `from_utf8_lossy` walks it).
fn text_of(bytes: &[u8]) -> std::borrow::Cow<'_, str> {
    std::str::from_utf8(bytes).map_or_else(|_| String::from_utf8_lossy(bytes), std::borrow::Cow::Borrowed)
}

/// `buf` without its line break.
fn trim_eol(buf: &mut Vec<u8>, eol: u8) -> &[u8] {
    if buf.last() == Some(&eol) {
        buf.pop();
    }
    if eol == b'\n' && buf.last() == Some(&b'\r') {
        buf.pop();
    }
    buf
}

impl TrcRows {
    /// Frames in the file.
    pub fn n_frames(&self) -> usize {
        self.rows.len()
    }

    /// Positions of frames `range` (metres, frame-major as [`MarkerTrial::positions`]), read
    /// again from the file.
    pub fn read(&self, range: std::ops::Range<usize>) -> Result<Vec<f64>, TrcError> {
        let io = |source| TrcError::Io { file: self.file.clone(), source };
        let range = range.start.min(self.rows.len())..range.end.min(self.rows.len());
        let mut p = Parser::new(&self.file, 0);
        p.header = Some(Header { per_m: self.per_m, first_data: 0, num_frames: None });
        p.trial.labels = vec![String::new(); self.n_markers];
        p.trial.positions.reserve_exact(range.len() * 3 * self.n_markers);
        let Some(&(start, _)) = self.rows.get(range.start) else { return Ok(Vec::new()) };
        let mut f = std::fs::File::open(&self.path).map_err(io)?;
        std::io::Seek::seek(&mut f, std::io::SeekFrom::Start(start)).map_err(io)?;
        let mut r = BufReader::with_capacity(1 << 16, f);
        let mut buf = Vec::new();
        for &(_, line) in &self.rows[range.clone()] {
            // Rows are the non-empty lines: skip empty ones between them.
            loop {
                buf.clear();
                if r.read_until(self.eol, &mut buf).map_err(io)? == 0 {
                    return Err(TrcError::NoData { file: self.file.clone(), line: line as usize });
                }
                let text = text_of(trim_eol(&mut buf, self.eol));
                if text.trim().is_empty() {
                    continue;
                }
                p.row(line as usize, &text)?;
                break;
            }
        }
        Ok(p.trial.positions)
    }
}

/// Parses TRC text; `name_for_errors` names the source in errors. Positions in metres.
pub fn parse_trc(text: &str, name_for_errors: &str) -> Result<MarkerTrial, TrcError> {
    let mut p = Parser::new(name_for_errors, text.len() as u64);
    // Classic Mac line endings (CR only): each CR ends a line.
    if text.contains('\r') && !text.contains('\n') {
        text.split('\r').try_for_each(|l| p.line(l))?;
    } else {
        text.lines().try_for_each(|l| p.line(l))?;
    }
    p.finish()
}

/// What the header (lines 1–5) says.
struct Header {
    per_m: f64,
    /// 0-based index of the first data line (4 when line 5 is data, else 5).
    first_data: usize,
    num_frames: Option<f64>,
}

/// A TRC parser fed one line at a time (without its line break), so that a file is parsed
/// without holding its text.
struct Parser {
    file: String,
    /// Bytes of the input (to reserve the arrays once).
    size: u64,
    /// Lines fed so far.
    lines: usize,
    /// The first five lines, until the header is read.
    head: Vec<String>,
    header: Option<Header>,
    trial: MarkerTrial,
    warnings: Vec<String>,
    time_warned: bool,
    /// Bytes fed so far.
    fed: u64,
    /// Frames whose positions are held (beyond it, rows are parsed and checked only).
    keep: usize,
    /// Byte offset of the line being fed (set by the caller), and that of each frame's row.
    offset: u64,
    offsets: Vec<(u64, u32)>,
    /// Data rows may carry more markers than line 4 names (a cut-off name row or an unlabelled
    /// export): the markers named and `NumMarkers`.
    widen: Option<(usize, Option<f64>)>,
    /// The cells of the row being parsed (byte ranges), kept to reuse its allocation.
    spans: Vec<(usize, usize)>,
    /// The most coordinate cells of any data row (cells after frame and time).
    widest: usize,
}

impl Parser {
    fn new(file: &str, size: u64) -> Parser {
        Parser {
            file: file.to_string(),
            size,
            lines: 0,
            head: Vec::new(),
            header: None,
            trial: MarkerTrial::default(),
            warnings: Vec::new(),
            time_warned: false,
            fed: 0,
            keep: usize::MAX,
            offset: 0,
            offsets: Vec::new(),
            widen: None,
            spans: Vec::new(),
            widest: 0,
        }
    }

    fn line(&mut self, line: &str) -> Result<(), TrcError> {
        self.lines += 1;
        self.fed += line.len() as u64 + 1;
        let line = if self.lines == 1 { line.strip_prefix('\u{feff}').unwrap_or(line) } else { line };
        match &self.header {
            Some(h) if self.lines > h.first_data => return self.row(self.lines, line),
            Some(_) => return Ok(()),
            None => self.head.push(line.to_string()),
        }
        if self.head.len() == 5 {
            self.read_header()?;
            // Line 5 read as data.
            if self.header.as_ref().is_some_and(|h| h.first_data == 4) {
                let l5 = std::mem::take(&mut self.head[4]);
                self.row(5, &l5)?;
            }
            self.head = Vec::new();
        }
        Ok(())
    }

    /// Reads the header from the (up to five) lines in `head`.
    fn read_header(&mut self) -> Result<(), TrcError> {
        let file = self.file.clone();
        let lines = &self.head;
        let missing = |line: usize, expected: &str| TrcError::MissingHeader {
            file: file.clone(),
            line,
            expected: expected.into(),
        };
        let warnings = &mut self.warnings;
        if !lines.first().is_some_and(|l| l.trim_start().starts_with("PathFileType")) {
            return Err(missing(1, "a `PathFileType` line"));
        }
        let names_line = lines.get(1).ok_or_else(|| missing(2, "header field names (DataRate ... Units ...)"))?;
        let values_line = lines.get(2).ok_or_else(|| missing(3, "header field values"))?;
        let pairs = header_pairs(names_line, values_line, warnings);
        let field = |name: &str| pairs.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).map(|(_, v)| v.as_str());
        let has_name = |name: &str| names_line.split_whitespace().any(|n| n.eq_ignore_ascii_case(name));

        let (rate_name, rate_str) = match (field("DataRate"), field("CameraRate")) {
            (Some(v), _) => ("DataRate", v),
            (None, Some(v)) if !has_name("DataRate") => {
                warnings.push("no DataRate field; using CameraRate".into());
                ("CameraRate", v)
            }
            _ if has_name("DataRate") => return Err(missing(3, "a value for DataRate")),
            _ => return Err(missing(2, "a DataRate field")),
        };
        let rate_hz = rate_str.parse::<f64>().ok().filter(|r| r.is_finite() && *r > 0.0).ok_or_else(|| {
            TrcError::BadHeaderValue { file: file.clone(), line: 3, field: rate_name.into(), value: clip(rate_str) }
        })?;
        let units = match field("Units") {
            Some(u) => u.to_string(),
            None if has_name("Units") => return Err(missing(3, "a value for Units")),
            None => return Err(missing(2, "a Units field")),
        };
        let scale = units_to_metres(&units).ok_or_else(|| TrcError::UnknownUnits {
            file: file.clone(),
            line: 3,
            units: clip(&units),
        })?;

        let label_line = lines.get(3).ok_or_else(|| missing(4, "the `Frame# Time <labels>` line"))?;
        if !label_line.trim_start().to_ascii_lowercase().starts_with("frame") {
            return Err(missing(4, "the `Frame# Time <labels>` line"));
        }
        let labels = labels_of(label_line, warnings);
        let nm = labels.len();
        if nm == 0 {
            warnings.push("no marker labels".into());
        }
        let num_markers = field("NumMarkers").and_then(|v| v.parse::<f64>().ok());
        // Cortex cuts the name row at a fixed length (NumMarkers above the names) and writes
        // unlabelled exports as `NumMarkers 0` without names: when NumMarkers and the names
        // disagree (or there are no names), the data rows say how many markers there are (the
        // warning is given once they are read). Names and NumMarkers agreeing, or names alone,
        // bound the rows: a wider row is an error.
        let widen = match num_markers {
            Some(n) => n != nm as f64 || nm == 0,
            None => nm == 0,
        };

        // Line 5 is normally `X1 Y1 Z1 ...`; if it already looks like data, read it as data.
        let mut first_data = 5;
        if let Some(l5) = lines.get(4) {
            let c = cells(l5.trim());
            if c.first().is_some_and(|s| parse_frame(s).is_some()) {
                warnings.push("line 5 has no X1 Y1 Z1 coordinate names; read as data".into());
                first_data = 4;
            } else {
                let n_axes = c.iter().filter(|s| !s.is_empty()).count();
                if n_axes != 3 * nm && !l5.trim().is_empty() {
                    warnings.push(format!("line 5 names {n_axes} coordinates for {nm} markers"));
                }
            }
        }
        let num_frames = field("NumFrames").and_then(|v| v.parse::<f64>().ok());
        self.trial = MarkerTrial { labels, rate_hz, source_units: units, ..MarkerTrial::default() };
        self.header = Some(Header { per_m: per_metre(scale), first_data, num_frames });
        self.widen = widen.then_some((nm, num_markers));
        Ok(())
    }

    /// Parses data line `line` (1-based).
    fn row(&mut self, line: usize, raw: &str) -> Result<(), TrcError> {
        let row = raw.trim_end();
        if row.trim().is_empty() {
            return Ok(());
        }
        let trial = &mut self.trial;
        let nm = trial.labels.len();
        if trial.times.is_empty() && self.keep > 0 {
            // At most one frame per remaining line of this length: reserved once, so the arrays
            // neither overshoot by doubling nor hold two copies while growing.
            let rows = (self.size.saturating_sub(self.fed) / (raw.len() as u64 + 1)) as usize + 1;
            let rows = (rows + rows / 16 + 16).min(self.keep);
            trial.positions.reserve_exact(rows.saturating_mul(3 * nm));
            trial.times.reserve_exact(rows);
            trial.frame_numbers.reserve_exact(rows);
        }
        if raw.contains('\t') {
            // Trailing empty cells (a marker unseen at the row's end) still count as the file's width.
            self.widest = self.widest.max(raw.bytes().filter(|&b| b == b'\t').count().saturating_sub(1));
        }
        let mut spans = std::mem::take(&mut self.spans);
        cell_spans(row, &mut spans);
        let out = self.row_cells(line, row, &spans);
        self.spans = spans;
        out
    }

    /// Parses data line `line` (1-based), `row`, whose cells are `spans`.
    fn row_cells(&mut self, line: usize, row: &str, spans: &[(usize, usize)]) -> Result<(), TrcError> {
        let trial = &mut self.trial;
        let nm = trial.labels.len();
        let per_m = self.header.as_ref().map_or(1.0, |h| h.per_m);
        let c = Cells { row, spans };
        let file = &self.file;
        let non_numeric =
            |column: usize, value: &str| TrcError::NonNumeric { file: file.clone(), line, column, value: clip(value) };
        self.widest = self.widest.max(c.len().saturating_sub(2));
        if c.len() > 2 + 3 * nm {
            if self.widen.is_none() {
                return Err(TrcError::RaggedRow { file: file.clone(), line, found: c.len() - 2, n_markers: nm });
            }
            let held = if trial.times.len() <= self.keep { trial.times.len() } else { 0 };
            widen_to(trial, (c.len() - 2).div_ceil(3), held);
        }
        let nm = trial.labels.len();
        let frame_cell = c.get(0).unwrap_or("");
        let frame = parse_frame(frame_cell).ok_or_else(|| non_numeric(1, frame_cell))?;
        let time_cell = c.get(1).unwrap_or("");
        let time = parse_f64(time_cell).filter(|t| t.is_finite()).ok_or_else(|| non_numeric(2, time_cell))?;
        if !self.time_warned && trial.times.last().is_some_and(|&prev| time <= prev) {
            self.warnings.push(format!("time does not increase at line {line}"));
            self.time_warned = true;
        }
        for m in 0..nm {
            let mut p = [f64::NAN; 3];
            for (axis, v) in p.iter_mut().enumerate() {
                let col = 2 + 3 * m + axis;
                let s = c.get(col).unwrap_or("");
                if s.is_empty() || s.eq_ignore_ascii_case("nan") {
                    continue;
                }
                let x = parse_f64(s).filter(|x| x.is_finite()).ok_or_else(|| non_numeric(col + 1, s))?;
                *v = x / per_m;
            }
            if p.iter().any(|v| v.is_nan()) {
                p = [f64::NAN; 3];
            }
            if trial.times.len() < self.keep {
                trial.positions.extend_from_slice(&p);
            }
        }
        if trial.times.len() == self.keep {
            // More frames than are held: none are.
            trial.positions = Vec::new();
        }
        self.offsets.push((self.offset, line as u32));
        trial.frame_numbers.push(frame);
        trial.times.push(time);
        Ok(())
    }

    /// The trial, once every line was fed.
    fn finish(mut self) -> Result<MarkerTrial, TrcError> {
        if self.header.is_none() {
            // Fewer than five lines: the header's own checks say what is missing.
            self.read_header()?;
            if self.header.as_ref().is_some_and(|h| h.first_data == 4) {
                let l5 = std::mem::take(&mut self.head[4]);
                self.row(5, &l5)?;
            }
        }
        let mut trial = self.trial;
        if trial.times.is_empty() {
            return Err(TrcError::NoData { file: self.file, line: self.lines + 1 });
        }
        trial.positions.shrink_to_fit();
        trial.times.shrink_to_fit();
        trial.frame_numbers.shrink_to_fit();
        if let Some(n) = self.header.as_ref().and_then(|h| h.num_frames) {
            if n != trial.n_frames() as f64 {
                self.warnings
                    .push(format!("NumFrames says {n} but {} data rows were read; using the rows", trial.n_frames()));
            }
        }
        if let Some((named, num_markers)) = self.widen {
            let nm = trial.n_markers();
            let file = &self.file;
            let said = num_markers.map_or("no NumMarkers".to_string(), |n| format!("NumMarkers {n}"));
            if named == 0 {
                self.warnings.push(format!(
                    "{file}: an unlabelled export ({said}, no marker names): its {nm} markers named \
                     M001–{}; they match no model marker",
                    unnamed_label(nm)
                ));
            } else if nm == named {
                if let Some(n) = num_markers {
                    self.warnings.push(format!("NumMarkers says {n} but line 4 has {nm} labels; using the labels"));
                }
            } else {
                self.warnings.push(format!(
                    "{file}: line 4 names {named} markers ({said}) but the data rows carry {nm}: \
                     markers {}–{nm} named {}–{} (cut-off name row; they match no model marker)",
                    named + 1,
                    unnamed_label(named + 1),
                    unnamed_label(nm)
                ));
            }
        }
        // Rows that all stop short of the markers named (empty trailing cells between tabs count):
        // NumMarkers and line 4 name more markers than the file holds (or its last ones are never
        // seen and the rows lost their empty cells).
        let nm = trial.n_markers();
        let named = self.widen.map_or(nm, |(named, _)| named);
        if nm > 0 && nm == named && self.widest < 3 * nm {
            let first = self.widest / 3 + 1;
            self.warnings.push(format!(
                "{}: every data row is short: at most {} coordinate cells for the {nm} markers line 4 names; \
                 markers {first}–{nm} ({}…) read as gaps throughout (check NumMarkers and line 4)",
                self.file,
                self.widest,
                trial.labels[first - 1]
            ));
        }
        trial.warnings = self.warnings;
        Ok(trial)
    }
}

/// The name of unnamed marker `i` (1-based) of a TRC file whose name row is missing or cut off:
/// `M034`. [`is_unnamed_label`] tells such names, which match no model marker.
pub fn unnamed_label(i: usize) -> String {
    format!("M{i:03}")
}

/// Whether `label` is a name [`unnamed_label`] gives (`M` and three or more digits).
pub fn is_unnamed_label(label: &str) -> bool {
    label.len() >= 4 && label.starts_with('M') && label[1..].bytes().all(|b| b.is_ascii_digit())
}

/// Widens `trial` to `nm` markers, the new ones named by [`unnamed_label`] and unobserved in the
/// `frames` frames held so far.
fn widen_to(trial: &mut MarkerTrial, nm: usize, frames: usize) {
    let old = trial.labels.len();
    if nm <= old {
        return;
    }
    trial.labels.extend((old + 1..=nm).map(unnamed_label));
    {
        let mut wide = Vec::with_capacity(frames * 3 * nm);
        for f in 0..frames {
            wide.extend_from_slice(&trial.positions[f * 3 * old..(f + 1) * 3 * old]);
            wide.resize(wide.len() + 3 * (nm - old), f64::NAN);
        }
        trial.positions = wide;
    }
}
