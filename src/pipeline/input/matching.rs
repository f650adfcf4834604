//! Matching model marker names to the labels of a marker file, in four passes of decreasing
//! strictness: exact, then case-insensitive, then with a subject prefix stripped from the label
//! (`Derrick:C7` → `C7`, as Vicon writes; compared case-insensitively), then through a table of
//! synonyms ([`Synonyms`]: Vicon Plug-in Gait and its CMU naming, `LFWT ↔ LASI`; OpenSim-style
//! spellings `r.ASIS`, `R_ASIS`, `RASIS` ↔ `RASI`; extensible in a profile). A label is used at
//! most once, and a stricter pass wins; two labels that match one model marker in the same pass
//! (or one label that matches two model markers) are an error naming both.

use crate::pipeline::context::Context;
use serde::{Deserialize, Serialize};

impl Context {
    /// The marker-name synonyms: the built-in table plus the profile's `[markers] synonyms`.
    pub fn synonyms(&self) -> Synonyms {
        let mut s = Synonyms::default();
        for g in &self.profile.markers.synonyms {
            s.add_group(g.iter().map(String::as_str));
        }
        s
    }
}

/// How a model marker found its label.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MatchKind {
    Exact,
    CaseInsensitive,
    PrefixStripped,
    /// Through the synonym table (after case folding, separator removal and prefix stripping).
    Synonym,
}

impl MatchKind {
    const ALL: [MatchKind; 4] =
        [MatchKind::Exact, MatchKind::CaseInsensitive, MatchKind::PrefixStripped, MatchKind::Synonym];

    fn describe(self) -> &'static str {
        match self {
            MatchKind::Exact => "exactly",
            MatchKind::CaseInsensitive => "ignoring case",
            MatchKind::PrefixStripped => "after stripping a subject prefix",
            MatchKind::Synonym => "through a synonym",
        }
    }

    /// Whether `label` matches the model marker `name` in this pass.
    fn matches(self, name: &str, label: &str, synonyms: &Synonyms) -> bool {
        match self {
            MatchKind::Exact => label == name,
            MatchKind::CaseInsensitive => label.eq_ignore_ascii_case(name),
            MatchKind::PrefixStripped => {
                label.contains(':') && !strip_subject_prefix(label).is_empty() && {
                    strip_subject_prefix(label).eq_ignore_ascii_case(name)
                }
            }
            MatchKind::Synonym => synonyms.equivalent(name, strip_subject_prefix(label)),
        }
    }
}

/// Groups of marker names that mean the same marker. Names are compared in a normal form:
/// ASCII lower case without `.`, `_`, `-` and spaces (`r.ASIS`, `R_ASIS`, `RASIS` → `rasis`).
#[derive(Clone, Debug)]
pub struct Synonyms {
    /// For each normalised name, its group's index.
    group: std::collections::BTreeMap<String, usize>,
}

/// The built-in synonym groups: Vicon Plug-in Gait names first, then their variants (CMU's
/// naming of the Plug-in Gait set, common OpenSim spellings).
pub const BUILTIN_SYNONYMS: &[&[&str]] = &[
    &["LASI", "LASIS", "LFWT", "L.ASIS"],
    &["RASI", "RASIS", "RFWT", "R.ASIS"],
    &["LPSI", "LPSIS", "LBWT", "L.PSIS"],
    &["RPSI", "RPSIS", "RBWT", "R.PSIS"],
    &["LTIB", "LSHN", "L.Shank"],
    &["RTIB", "RSHN", "R.Shank"],
    &["RBAK", "RBAC"],
    &["LTHI", "L.Thigh"],
    &["RTHI", "R.Thigh"],
    &["LKNE", "L.Knee", "L.Knee.Lat", "L_knee_lat"],
    &["RKNE", "R.Knee", "R.Knee.Lat", "R_knee_lat"],
    &["LANK", "L.Ankle", "L.Ankle.Lat", "L.Malleolus", "L_ankle_lat"],
    &["RANK", "R.Ankle", "R.Ankle.Lat", "R.Malleolus", "R_ankle_lat"],
    &["LHEE", "L.Heel", "L_calc", "LHEEL"],
    &["RHEE", "R.Heel", "R_calc", "RHEEL"],
    &["LTOE", "L.Toe", "L.Toe.Tip"],
    &["RTOE", "R.Toe", "R.Toe.Tip"],
    &["LMT5", "L.MT5", "L5MT", "L_5meta", "LVMH"],
    &["RMT5", "R.MT5", "R5MT", "R_5meta", "RVMH"],
    &["LSHO", "L.Shoulder", "L.Acromion", "L.Acromium", "LACR"],
    &["RSHO", "R.Shoulder", "R.Acromion", "R.Acromium", "RACR"],
    &["LELB", "L.Elbow", "L.Elbow.Lat", "L_elbow_lat"],
    &["RELB", "R.Elbow", "R.Elbow.Lat", "R_elbow_lat"],
    &["LMEL", "L.Elbow.Med", "L_elbow_med"],
    &["RMEL", "R.Elbow.Med", "R_elbow_med"],
    &["LWRA", "L.Wrist.Radius", "L_wrist_radius"],
    &["RWRA", "R.Wrist.Radius", "R_wrist_radius"],
    &["LWRB", "L.Wrist.Ulna", "L_wrist_ulna"],
    &["RWRB", "R.Wrist.Ulna", "R_wrist_ulna"],
    &["STRN", "Sternum", "XIPH"],
    &["CLAV", "Clavicle", "JUGU"],
    &["C7", "CV7", "C.7"],
    &["T10", "TV10"],
    &["SACR", "Sacral", "V.Sacral", "SACRUM"],
];

/// The normal form names are compared in.
pub fn normalise(name: &str) -> String {
    name.chars().filter(|c| !matches!(c, '.' | '_' | '-' | ' ')).map(|c| c.to_ascii_lowercase()).collect()
}

impl Default for Synonyms {
    fn default() -> Self {
        Synonyms::new(BUILTIN_SYNONYMS.iter().map(|g| g.iter().copied()))
    }
}

impl Synonyms {
    /// Synonym groups from lists of names; a name in two groups joins them.
    pub fn new<'a, G: IntoIterator<Item = &'a str>>(groups: impl IntoIterator<Item = G>) -> Synonyms {
        let mut s = Synonyms { group: Default::default() };
        for g in groups {
            s.add_group(g);
        }
        s
    }

    /// Adds one group (a profile's `[markers] synonyms` entry); groups sharing a name merge.
    pub fn add_group<'a>(&mut self, names: impl IntoIterator<Item = &'a str>) {
        let names: Vec<String> = names.into_iter().map(normalise).filter(|n| !n.is_empty()).collect();
        let existing: Vec<usize> = names.iter().filter_map(|n| self.group.get(n).copied()).collect();
        let id = existing.first().copied().unwrap_or_else(|| self.group.values().max().map_or(0, |m| m + 1));
        for g in self.group.values_mut() {
            if existing.contains(g) {
                *g = id;
            }
        }
        for n in names {
            self.group.insert(n, id);
        }
    }

    /// Whether `a` and `b` name the same marker: equal in normal form, or in one group.
    pub fn equivalent(&self, a: &str, b: &str) -> bool {
        let (a, b) = (normalise(a), normalise(b));
        if a.is_empty() || b.is_empty() {
            return false;
        }
        a == b || matches!((self.group.get(&a), self.group.get(&b)), (Some(x), Some(y)) if x == y)
    }
}

/// The label without a subject prefix: the part after the last `:` (`Derrick:C7` → `C7`).
pub fn strip_subject_prefix(label: &str) -> &str {
    label.rsplit(':').next().unwrap_or(label).trim()
}

/// Two names that match the same counterpart equally well.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum MatchError {
    #[error("ambiguous marker labels: '{first}' and '{second}' both match model marker '{marker}' {how}")]
    TwoLabels { marker: String, first: String, second: String, how: &'static str },
    #[error("ambiguous marker label '{label}': it matches model markers '{first}' and '{second}' {how}")]
    TwoMarkers { label: String, first: String, second: String, how: &'static str },
}

/// Result of matching model markers to file labels.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MarkerMatch {
    /// For each model marker, the index of its label in the file.
    pub columns: Vec<Option<usize>>,
    /// For each model marker, how it was matched.
    pub kinds: Vec<Option<MatchKind>>,
    /// Model markers with no label, in model order.
    pub unmatched_model: Vec<String>,
    /// File labels matching no model marker, in file order.
    pub unmatched_trial: Vec<String>,
}

impl MarkerMatch {
    /// `(file label, model marker)` for the markers matched other than exactly.
    pub fn renamed<'a>(&self, model: &[&'a str], labels: &'a [String]) -> Vec<(&'a str, &'a str)> {
        (0..model.len())
            .filter(|&m| self.kinds[m].is_some_and(|k| k != MatchKind::Exact))
            .filter_map(|m| self.columns[m].map(|c| (labels[c].as_str(), model[m])))
            .collect()
    }
}

/// Matches `model` marker names to file `labels` with the built-in synonyms (see the module docs).
pub fn match_names(model: &[&str], labels: &[String]) -> Result<MarkerMatch, MatchError> {
    match_names_with(model, labels, &Synonyms::default())
}

/// Matches `model` marker names to file `labels` with the given synonym table.
pub fn match_names_with(model: &[&str], labels: &[String], synonyms: &Synonyms) -> Result<MarkerMatch, MatchError> {
    let mut columns: Vec<Option<usize>> = vec![None; model.len()];
    let mut kinds: Vec<Option<MatchKind>> = vec![None; model.len()];
    // Markers a reader named itself (a TRC name row cut off, an unlabelled export) match nothing.
    let mut used: Vec<bool> = labels.iter().map(|l| crate::io::trc::is_unnamed_label(l)).collect();
    for kind in MatchKind::ALL {
        // Candidates of this pass, checked in both directions before any is taken.
        let mut claimed: Vec<Option<usize>> = vec![None; labels.len()];
        let mut found: Vec<(usize, usize)> = Vec::new();
        for (m, name) in model.iter().enumerate().filter(|(m, _)| columns[*m].is_none()) {
            let mut hit: Option<usize> = None;
            for (c, label) in labels.iter().enumerate().filter(|(c, _)| !used[*c]) {
                if !kind.matches(name, label, synonyms) {
                    continue;
                }
                if let Some(prev) = hit {
                    return Err(MatchError::TwoLabels {
                        marker: name.to_string(),
                        first: labels[prev].clone(),
                        second: label.clone(),
                        how: kind.describe(),
                    });
                }
                if let Some(other) = claimed[c] {
                    return Err(MatchError::TwoMarkers {
                        label: label.clone(),
                        first: model[other].to_string(),
                        second: name.to_string(),
                        how: kind.describe(),
                    });
                }
                hit = Some(c);
                claimed[c] = Some(m);
            }
            if let Some(c) = hit {
                found.push((m, c));
            }
        }
        for (m, c) in found {
            columns[m] = Some(c);
            kinds[m] = Some(kind);
            used[c] = true;
        }
    }
    let unmatched_model = model.iter().zip(&columns).filter(|(_, c)| c.is_none()).map(|(n, _)| n.to_string()).collect();
    let unmatched_trial = labels.iter().zip(&used).filter(|(_, u)| !**u).map(|(l, _)| l.clone()).collect();
    Ok(MarkerMatch { columns, kinds, unmatched_model, unmatched_trial })
}
