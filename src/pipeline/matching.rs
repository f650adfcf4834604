//! Matching model marker names to the labels of a marker file, in three passes of decreasing
//! strictness: exact, then case-insensitive, then with a subject prefix stripped from the label
//! (`Derrick:C7` → `C7`, as Vicon writes; compared case-insensitively). A label is used at most
//! once, and a stricter pass wins; two labels that match one model marker in the same pass (or
//! one label that matches two model markers) are an error naming both.

use serde::{Deserialize, Serialize};

/// How a model marker found its label.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MatchKind {
    Exact,
    CaseInsensitive,
    PrefixStripped,
}

impl MatchKind {
    const ALL: [MatchKind; 3] = [MatchKind::Exact, MatchKind::CaseInsensitive, MatchKind::PrefixStripped];

    fn describe(self) -> &'static str {
        match self {
            MatchKind::Exact => "exactly",
            MatchKind::CaseInsensitive => "ignoring case",
            MatchKind::PrefixStripped => "after stripping a subject prefix",
        }
    }

    /// Whether `label` matches the model marker `name` in this pass.
    fn matches(self, name: &str, label: &str) -> bool {
        match self {
            MatchKind::Exact => label == name,
            MatchKind::CaseInsensitive => label.eq_ignore_ascii_case(name),
            MatchKind::PrefixStripped => {
                label.contains(':') && !strip_subject_prefix(label).is_empty() && {
                    strip_subject_prefix(label).eq_ignore_ascii_case(name)
                }
            }
        }
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

/// Matches `model` marker names to file `labels` (see the module docs).
pub fn match_names(model: &[&str], labels: &[String]) -> Result<MarkerMatch, MatchError> {
    let mut columns: Vec<Option<usize>> = vec![None; model.len()];
    let mut kinds: Vec<Option<MatchKind>> = vec![None; model.len()];
    let mut used = vec![false; labels.len()];
    for kind in MatchKind::ALL {
        // Candidates of this pass, checked in both directions before any is taken.
        let mut claimed: Vec<Option<usize>> = vec![None; labels.len()];
        let mut found: Vec<(usize, usize)> = Vec::new();
        for (m, name) in model.iter().enumerate().filter(|(m, _)| columns[*m].is_none()) {
            let mut hit: Option<usize> = None;
            for (c, label) in labels.iter().enumerate().filter(|(c, _)| !used[*c]) {
                if !kind.matches(name, label) {
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
