//! Joining the summaries of sharded runs (`smocap convert --shard I/N --report-json`) into one:
//! every trial once, datasets merged, the shards recorded.

use super::convert::{ConvertSummary, DatasetNote};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// Errors merging summaries.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error("no summaries to merge")]
    Empty,
    #[error("trial '{dataset}/{trial}' is in both {first} and {second} (pass --keep-last to keep the later one)")]
    Duplicate { dataset: String, trial: String, first: String, second: String },
}

/// One merged summary: where it came from and what it held.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ShardSource {
    /// The summary's file (as given).
    pub file: String,
    /// Its `I/N`, when the run was sharded.
    pub shard: Option<String>,
    pub trials: usize,
}

/// Summaries merged: a [`ConvertSummary`] (its `shard` empty) with the shards it joins.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MergedSummary {
    #[serde(flatten)]
    pub summary: ConvertSummary,
    pub merged_from: Vec<ShardSource>,
}

/// Merges `reports` (file name, summary), in order. A trial (same dataset and path) in two
/// summaries is an error, or with `keep_last` the later one replaces the earlier one (with a
/// warning). A dataset is skipped in the result only if every summary skipped it. Returns the
/// merged summary and warnings (duplicates kept, shards missing from an `I/N` set, differing
/// smocap versions).
pub fn merge(
    reports: &[(String, ConvertSummary)],
    keep_last: bool,
) -> Result<(MergedSummary, Vec<String>), MergeError> {
    let first = reports.first().ok_or(MergeError::Empty)?;
    let mut warnings = Vec::new();
    let mut datasets: Vec<DatasetNote> = Vec::new();
    let mut trials = BTreeMap::new();
    let mut from: BTreeMap<(String, String), &str> = BTreeMap::new();
    for (file, r) in reports {
        for d in &r.datasets {
            match datasets.iter_mut().find(|x| x.name == d.name) {
                Some(x) if x.skipped.is_some() && d.skipped.is_none() => *x = d.clone(),
                Some(_) => {}
                None => datasets.push(d.clone()),
            }
        }
        for t in &r.trials {
            let key = (t.dataset.clone(), t.trial.clone());
            if let Some(prev) = from.insert(key.clone(), file) {
                if !keep_last {
                    let (dataset, trial) = key;
                    return Err(MergeError::Duplicate { dataset, trial, first: prev.into(), second: file.clone() });
                }
                warnings.push(format!("{}/{}: {file} replaces {prev}", t.dataset, t.trial));
            }
            trials.insert(key, t.clone());
        }
    }
    let versions: BTreeSet<&str> = reports.iter().map(|(_, r)| r.smocap_version.as_str()).collect();
    if versions.len() > 1 {
        warnings.push(format!("summaries from different smocap versions: {versions:?}"));
    }
    warnings.extend(missing_shards(reports));
    let summary = ConvertSummary {
        smocap_version: first.1.smocap_version.clone(),
        shard: None,
        datasets,
        trials: trials.into_values().collect(),
        calibrations: {
            let mut c: Vec<_> = reports.iter().flat_map(|(_, r)| r.calibrations.iter().cloned()).collect();
            c.sort_by(|a, b| (&a.dataset, &a.subject).cmp(&(&b.dataset, &b.subject)));
            c
        },
        wall_seconds: 0.0,
        threads: 0,
    };
    let merged_from = reports
        .iter()
        .map(|(file, r)| ShardSource { file: file.clone(), shard: r.shard.clone(), trials: r.trials.len() })
        .collect();
    Ok((MergedSummary { summary, merged_from }, warnings))
}

/// Warnings for shards of an `I/N` set that no summary covers, and for mixed shard counts.
fn missing_shards(reports: &[(String, ConvertSummary)]) -> Vec<String> {
    let mut warnings = Vec::new();
    let mut shards: Vec<(usize, usize)> = Vec::new();
    for (file, r) in reports {
        let Some(text) = r.shard.as_deref() else { continue };
        match text.parse::<super::shard::Shard>() {
            Ok(s) => shards.push((s.index, s.count)),
            Err(e) => warnings.push(format!("{file}: {e}")),
        }
    }
    let counts: BTreeSet<usize> = shards.iter().map(|s| s.1).collect();
    match counts.len() {
        0 => {}
        1 => {
            // `n` is at most MAX_SHARDS (the parse checks it).
            let n = *counts.first().expect("one count");
            let present: BTreeSet<usize> = shards.iter().map(|s| s.0).collect();
            let missing: Vec<usize> = (0..n).filter(|i| !present.contains(i)).collect();
            if !missing.is_empty() {
                let mut list: Vec<String> = missing.iter().take(20).map(|i| format!("{i}/{n}")).collect();
                if missing.len() > 20 {
                    list.push(format!("and {} more", missing.len() - 20));
                }
                warnings.push(format!("no summary for shard(s) {}", list.join(", ")));
            }
        }
        _ => warnings.push(format!("summaries from runs cut into different numbers of shards: {counts:?}")),
    }
    warnings
}
