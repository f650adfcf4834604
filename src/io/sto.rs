//! OpenSim `.sto` / `.mot` tables: a header ending in `endheader`, a tab-separated row of column
//! names, then rows of numbers (the first column is usually `time`).

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
