//! Finding the trials of a dataset: files under its root matched by its globs, grouped by subject
//! (read from the path pattern, or the trial's folder), each subject with its static trial.

use super::config::Dataset;
use globset::{Glob, GlobSet, GlobSetBuilder};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Errors finding trials.
#[derive(Debug, thiserror::Error)]
pub enum DiscoverError {
    #[error("dataset '{dataset}': bad glob '{glob}': {source}")]
    Glob { dataset: String, glob: String, source: globset::Error },
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{root}: more than {max} files and folders below it; is `root` right?")]
    TooMany { root: String, max: usize },
}

/// One motion trial.
#[derive(Clone, Debug)]
pub struct TrialEntry {
    pub path: PathBuf,
    /// Path relative to the dataset root, `/`-separated (mirrored under the output folder).
    pub rel: String,
    /// Frame count from the file header (an estimate from the file size when it has none).
    pub frames: u64,
}

/// The trials of one subject.
#[derive(Clone, Debug)]
pub struct SubjectGroup {
    /// Index of the dataset in the list given to [`discover`].
    pub dataset: usize,
    pub subject: String,
    pub static_trial: Option<PathBuf>,
    pub trials: Vec<TrialEntry>,
}

impl SubjectGroup {
    pub fn frames(&self) -> u64 {
        self.trials.iter().map(|t| t.frames).sum()
    }
}

/// Most directory entries discovery looks at under one dataset root (files and folders).
pub const MAX_ENTRIES: usize = 1_000_000;
/// Deepest folder level below a dataset root that discovery descends to.
pub const MAX_DEPTH: usize = 64;

/// Every regular file under `root` (a symbolic link to a regular file counts; links to folders
/// are not followed, so link loops cannot make a walk endless; FIFOs, sockets and devices are
/// left), as `/`-separated paths relative to it, sorted; the walk stays on `root`'s file
/// system and stops with an error past [`MAX_ENTRIES`] entries.
fn walk(root: &Path) -> Result<Vec<String>, DiscoverError> {
    walk_bounded(root, MAX_ENTRIES)
}

/// [`walk`] stopping past `max_entries` entries.
fn walk_bounded(root: &Path, max_entries: usize) -> Result<Vec<String>, DiscoverError> {
    let mut out = Vec::new();
    let walker = walkdir::WalkDir::new(root).follow_links(false).same_file_system(true).max_depth(MAX_DEPTH);
    for (n, e) in walker.into_iter().enumerate() {
        if n >= max_entries {
            return Err(DiscoverError::TooMany { root: root.display().to_string(), max: max_entries });
        }
        let e = e.map_err(|e| {
            let path = e.path().unwrap_or(root).display().to_string();
            let source = e.into_io_error().unwrap_or_else(|| std::io::Error::other("unreadable entry"));
            DiscoverError::Io { path, source }
        })?;
        let t = e.file_type();
        let regular = t.is_file() || t.is_symlink() && std::fs::metadata(e.path()).is_ok_and(|m| m.is_file());
        if !regular {
            continue;
        }
        if let Ok(rel) = e.path().strip_prefix(root) {
            out.push(rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/"));
        }
    }
    out.sort();
    Ok(out)
}

fn glob_set(dataset: &str, globs: &[String]) -> Result<GlobSet, DiscoverError> {
    let mut b = GlobSetBuilder::new();
    for g in globs {
        let glob =
            Glob::new(g).map_err(|source| DiscoverError::Glob { dataset: dataset.into(), glob: g.clone(), source })?;
        b.add(glob);
    }
    b.build().map_err(|source| DiscoverError::Glob { dataset: dataset.into(), glob: globs.join(", "), source })
}

/// Matches `path` against a pattern of literal text and `{name}` placeholders (each matching one
/// or more characters other than `/`); returns the placeholders' values.
pub fn match_pattern(pattern: &str, path: &str) -> Option<BTreeMap<String, String>> {
    fn go(pat: &str, s: &str, vars: &mut BTreeMap<String, String>) -> bool {
        match pat.find('{') {
            None => pat == s,
            Some(i) => {
                let Some(rest) = s.strip_prefix(&pat[..i]) else { return false };
                let Some(close) = pat[i..].find('}') else { return pat == s };
                let name = &pat[i + 1..i + close];
                let tail = &pat[i + close + 1..];
                let limit = rest.find('/').unwrap_or(rest.len());
                for end in (1..=limit).rev() {
                    if go(tail, &rest[end..], vars) {
                        vars.insert(name.to_string(), rest[..end].to_string());
                        return true;
                    }
                }
                false
            }
        }
    }
    let mut vars = BTreeMap::new();
    go(pattern, path, &mut vars).then_some(vars)
}

/// Frame count from a TRC (`NumFrames`) or C3D (header first/last frame) header; otherwise an
/// estimate from the file size (one frame per kilobyte).
pub fn estimate_frames(path: &Path) -> u64 {
    let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let fallback = (size / 1000).max(1);
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let head = |n: usize| {
        use std::io::Read;
        let mut buf = vec![0u8; n];
        let got = std::fs::File::open(path).and_then(|mut f| f.read(&mut buf)).unwrap_or(0);
        buf.truncate(got);
        buf
    };
    let from_header = match ext.as_str() {
        "trc" => {
            let text = String::from_utf8_lossy(&head(4096)).into_owned();
            let lines: Vec<&str> = text.lines().collect();
            let (names, values) = (lines.get(1).copied().unwrap_or(""), lines.get(2).copied().unwrap_or(""));
            let i = names.split('\t').position(|n| n.trim() == "NumFrames");
            i.and_then(|i| values.split('\t').nth(i)).and_then(|v| v.trim().parse::<u64>().ok())
        }
        "c3d" => {
            let h = head(10);
            (h.len() == 10 && h[1] == 0x50).then(|| {
                let word = |k: usize| u16::from_le_bytes([h[k], h[k + 1]]) as u64;
                word(8).saturating_sub(word(6)) + 1
            })
        }
        _ => None,
    };
    from_header.filter(|&n| n > 0 && n < 100_000_000).unwrap_or(fallback)
}

/// The subjects of dataset `index` (rooted at `root`), sorted by subject then trial path.
pub fn discover(index: usize, d: &Dataset, root: &Path) -> Result<Vec<SubjectGroup>, DiscoverError> {
    let trials = glob_set(&d.name, &d.trials)?;
    let files = walk(root)?;
    let statics: Vec<&String> = match &d.static_glob {
        Some(g) if !g.contains("{subject}") => {
            let set = glob_set(&d.name, std::slice::from_ref(g))?;
            files.iter().filter(|f| set.is_match(f.as_str())).collect()
        }
        _ => Vec::new(),
    };
    let mut groups: BTreeMap<String, Vec<TrialEntry>> = BTreeMap::new();
    for f in &files {
        if !trials.is_match(f.as_str()) || statics.contains(&f) {
            continue;
        }
        let subject = match &d.subject {
            Some(p) => match match_pattern(p, f).and_then(|v| v.get("subject").cloned()) {
                Some(s) => s,
                None => continue,
            },
            None => f.rsplit_once('/').map_or(String::new(), |(dir, _)| dir.to_string()),
        };
        let path = root.join(f);
        groups.entry(subject).or_default().push(TrialEntry { frames: estimate_frames(&path), path, rel: f.clone() });
    }
    let mut out = Vec::new();
    for (subject, mut list) in groups {
        let static_trial = match &d.static_glob {
            None => None,
            Some(g) => {
                let set = glob_set(&d.name, &[g.replace("{subject}", &subject)])?;
                files.iter().find(|f| set.is_match(f.as_str())).map(|f| root.join(f))
            }
        };
        list.retain(|t| Some(&t.path) != static_trial.as_ref());
        if !list.is_empty() {
            out.push(SubjectGroup { dataset: index, subject, static_trial, trials: list });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_walk_past_its_entry_bound_stops_with_an_error() {
        let root = std::env::temp_dir().join(format!("smocap-walk-bound-{}", std::process::id()));
        std::fs::create_dir_all(root.join("a/b")).unwrap();
        for i in 0..20 {
            std::fs::write(root.join(format!("a/b/t{i}.trc")), "").unwrap();
        }
        assert_eq!(walk_bounded(&root, 100).unwrap().len(), 20);
        let e = walk_bounded(&root, 10).unwrap_err().to_string();
        assert!(e.contains("more than 10 files and folders"), "{e}");
        let _ = std::fs::remove_dir_all(&root);
    }
}
