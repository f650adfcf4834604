//! Splitting a TRC line into its cells (tabs, or runs of spaces in files that lost their tabs),
//! the header's name/value pairs and the marker-label row.

/// At most 40 characters of `s`, for error messages.
pub(super) fn clip(s: &str) -> String {
    match s.char_indices().nth(40) {
        Some((i, _)) => format!("{}...", &s[..i]),
        None => s.to_string(),
    }
}

/// Splits a row into cells: on tabs when it has any, else on runs of whitespace.
pub(super) fn cells(line: &str) -> Vec<&str> {
    if line.contains('\t') {
        line.split('\t').map(str::trim).collect()
    } else {
        line.split_whitespace().collect()
    }
}

/// [`cells`] of `line` as byte ranges into it, into `out` (reused: no allocation per row).
/// ASCII lines are split on bytes (the same cells: on ASCII, `char::is_whitespace` is
/// [`is_space`]); others go through [`cells`].
pub(super) fn cell_spans(line: &str, out: &mut Vec<(usize, usize)>) {
    out.clear();
    if !line.is_ascii() {
        let base = line.as_ptr() as usize;
        out.extend(cells(line).iter().map(|c| {
            let a = c.as_ptr() as usize - base;
            (a, a + c.len())
        }));
        return;
    }
    let b = line.as_bytes();
    if b.contains(&b'\t') {
        let mut a = 0;
        loop {
            let end = b[a..].iter().position(|&c| c == b'\t').map_or(b.len(), |k| a + k);
            let (mut x, mut y) = (a, end);
            while x < y && is_space(b[x]) {
                x += 1;
            }
            while y > x && is_space(b[y - 1]) {
                y -= 1;
            }
            out.push((x, y));
            if end == b.len() {
                break;
            }
            a = end + 1;
        }
    } else {
        let mut k = 0;
        while k < b.len() {
            while k < b.len() && is_space(b[k]) {
                k += 1;
            }
            let x = k;
            while k < b.len() && !is_space(b[k]) {
                k += 1;
            }
            if k > x {
                out.push((x, k));
            }
        }
    }
}

/// A row's cells: `spans` into `row`.
pub(super) struct Cells<'a> {
    pub(super) row: &'a str,
    pub(super) spans: &'a [(usize, usize)],
}

impl<'a> Cells<'a> {
    pub(super) fn len(&self) -> usize {
        self.spans.len()
    }

    pub(super) fn get(&self, i: usize) -> Option<&'a str> {
        self.spans.get(i).map(|&(a, b)| &self.row[a..b])
    }
}

/// `char::is_whitespace` on an ASCII byte (tab, line feed, vertical tab, form feed, carriage
/// return, space).
pub(super) fn is_space(c: u8) -> bool {
    matches!(c, b'\t' | b'\n' | 0x0B | 0x0C | b'\r' | b' ')
}

/// Header name/value pairs of lines 2 and 3, tolerant of doubled tabs.
pub(super) fn header_pairs(names_line: &str, values_line: &str, warnings: &mut Vec<String>) -> Vec<(String, String)> {
    let names: Vec<&str> = names_line.split('\t').flat_map(str::split_whitespace).collect();
    let by_tab: Vec<&str> = values_line.trim_end().split('\t').map(str::trim).collect();
    let values: Vec<&str> = if by_tab.len() == names.len() { by_tab } else { values_line.split_whitespace().collect() };
    if values.len() != names.len() {
        warnings.push(format!("header has {} field names but {} values", names.len(), values.len()));
    }
    names.iter().zip(values).map(|(n, v)| (n.to_string(), v.to_string())).collect()
}

/// Marker labels of line 4: at columns 2, 5, 8, ... (0-based), each followed by two
/// empty cells; labels off that grid are taken in order with a warning.
pub(super) fn labels_of(line: &str, warnings: &mut Vec<String>) -> Vec<String> {
    let c = cells(line.trim_end());
    let named: Vec<(usize, &str)> =
        c.iter().enumerate().skip(2).filter(|(_, s)| !s.is_empty()).map(|(i, s)| (i, *s)).collect();
    if named.iter().any(|(i, _)| (i - 2) % 3 != 0) {
        warnings.push("marker labels are not each followed by two empty cells; taken in order".into());
        return named.iter().map(|(_, s)| s.to_string()).collect();
    }
    let n = c.len().saturating_sub(2).div_ceil(3);
    (0..n)
        .map(|m| match c.get(2 + 3 * m).copied().filter(|s| !s.is_empty()) {
            Some(s) => s.to_string(),
            None => {
                warnings.push(format!("marker {} has no label; named Unnamed{}", m + 1, m + 1));
                format!("Unnamed{}", m + 1)
            }
        })
        .collect()
}

/// Parses a whole-number frame cell (`12` or `12.0`).
pub(super) fn parse_frame(s: &str) -> Option<i64> {
    s.parse::<i64>().ok().or_else(|| {
        let v: f64 = s.parse().ok()?;
        (v.is_finite() && v.fract() == 0.0 && v.abs() < 9.0e15).then_some(v as i64)
    })
}
