//! OpenSim `.sto` / `.mot` tables: a header ending in `endheader`, a tab-separated row of column
//! names, then rows of numbers (the first column is usually `time`). Read with [`read_sto`],
//! written with [`write_sto`] (OpenSim 4 storage format, as its tools write `.mot` files).

use std::path::Path;

/// A table read from an `.sto` / `.mot` file.
#[derive(Clone, Debug, Default)]
pub struct Table {
    /// Header lines of the form `key=value`, in file order (e.g. `inDegrees=yes`).
    pub header: Vec<(String, String)>,
    /// Column names, including `time`.
    pub columns: Vec<String>,
    /// Rows of values, one per line, as many as columns.
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// Index of column `name`.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }
    /// Value of header key `key`.
    pub fn header_value(&self, key: &str) -> Option<&str> {
        self.header.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }
    /// `inDegrees=yes` in the header (rotational coordinates in degrees); `None` when absent.
    pub fn in_degrees(&self) -> Option<bool> {
        self.header_value("inDegrees").map(|v| v.eq_ignore_ascii_case("yes") || v.eq_ignore_ascii_case("true"))
    }
}

/// Errors reading a table. Lines are 1-based.
#[derive(Debug, thiserror::Error)]
pub enum StoError {
    #[error("{file}: cannot read: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}:{line}: {message}")]
    Parse { file: String, line: usize, message: String },
    #[error("{file}: cannot write: {source}")]
    Write { file: String, source: std::io::Error },
}

/// Reads an `.sto` / `.mot` file.
pub fn read_sto(path: &Path) -> Result<Table, StoError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| StoError::Io { file: file.clone(), source })?;
    parse_sto(&text, &file)
}

/// Parses `.sto` / `.mot` text; `file_name` is used in messages.
pub fn parse_sto(text: &str, file_name: &str) -> Result<Table, StoError> {
    let err = |line: usize, message: String| StoError::Parse { file: file_name.to_string(), line, message };
    let mut lines = text.lines().enumerate();
    let mut table = Table::default();
    loop {
        let Some((_, l)) = lines.next() else {
            return Err(err(0, "no 'endheader' line".into()));
        };
        let l = l.trim();
        if l.eq_ignore_ascii_case("endheader") {
            break;
        }
        if let Some((k, v)) = l.split_once('=') {
            table.header.push((k.trim().to_string(), v.trim().to_string()));
        }
    }
    let Some((_, names)) = lines.by_ref().find(|(_, l)| !l.trim().is_empty()) else {
        return Err(err(0, "no column names after 'endheader'".into()));
    };
    table.columns = names.split('\t').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect();
    for (i, l) in lines {
        if l.trim().is_empty() {
            continue;
        }
        let row: Result<Vec<f64>, _> = l.split_whitespace().map(str::parse::<f64>).collect();
        let row = row.map_err(|e| err(i + 1, format!("bad number: {e}")))?;
        if row.len() != table.columns.len() {
            return Err(err(i + 1, format!("{} values for {} columns", row.len(), table.columns.len())));
        }
        table.rows.push(row);
    }
    Ok(table)
}

/// Formats a table in OpenSim 4 storage format: the table `name` line, `version=1`, `nRows=`,
/// `nColumns=`, the other header entries (e.g. `inDegrees=yes`; any `version`, `nRows` or
/// `nColumns` of `table.header` are replaced), `endheader`, the tab-separated column names, then
/// one tab-separated line per row. Numbers are written so that they read back exactly.
pub fn format_sto(name: &str, table: &Table) -> String {
    use std::fmt::Write as _;
    let mut out = String::with_capacity(64 + table.rows.len() * table.columns.len() * 12);
    let name = name.lines().next().unwrap_or("").trim();
    let _ = write!(out, "{}\nversion=1\nnRows={}\nnColumns={}\n", name, table.rows.len(), table.columns.len());
    for (k, v) in &table.header {
        if !["version", "nRows", "nColumns"].contains(&k.as_str()) {
            let _ = writeln!(out, "{k}={v}");
        }
    }
    out.push_str("endheader\n");
    out.push_str(&table.columns.join("\t"));
    out.push('\n');
    for row in &table.rows {
        for (i, v) in row.iter().enumerate() {
            if i > 0 {
                out.push('\t');
            }
            push_number(&mut out, *v);
        }
        out.push('\n');
    }
    out
}

/// Writes [`format_sto`] to `path`.
pub fn write_sto(path: &Path, name: &str, table: &Table) -> Result<(), StoError> {
    std::fs::write(path, format_sto(name, table))
        .map_err(|source| StoError::Write { file: path.display().to_string(), source })
}

/// Appends `v` in the shortest form that reads back exactly, with an exponent only for very small
/// or very large magnitudes (`NaN` as `NaN`, as OpenSim writes it).
pub(crate) fn push_number(out: &mut String, v: f64) {
    use std::fmt::Write as _;
    let a = v.abs();
    let _ = if v.is_nan() {
        write!(out, "NaN")
    } else if v.is_infinite() {
        write!(out, "{}", if v > 0.0 { "Inf" } else { "-Inf" })
    } else if a == 0.0 || (1e-5..1e15).contains(&a) {
        write!(out, "{v}")
    } else {
        write!(out, "{v:e}")
    };
}
