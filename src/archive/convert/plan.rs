//! Stage 1 of a conversion, the plan: every dataset generated (synthetic ones) and discovered,
//! where each trial's output goes and which outputs are contested, and per subject which trials
//! are still to convert (`--resume` skips those whose output records the same input).

use super::{failed, outcome, ConvertOptions, DatasetNote, TrialOutcome};
use crate::archive::config::Dataset;
use crate::archive::discover::{discover, SubjectGroup, TrialEntry};
use crate::archive::inspect::recorded_run;
use crate::archive::mcap_out::partial_path;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A trial still to convert: its entry, its output path and its input's SHA-256.
pub(super) type Todo<'g> = (&'g TrialEntry, PathBuf, String);

/// Every dataset generated (synthetic) and discovered: a note per dataset, and the subjects found.
pub(super) fn discover_all(
    datasets: &[Dataset],
    opt: &ConvertOptions,
    log: &(dyn Fn(&str) + Sync),
) -> (Vec<DatasetNote>, Vec<SubjectGroup>) {
    let mut notes = Vec::new();
    let mut groups: Vec<SubjectGroup> = Vec::new();
    for (i, d) in datasets.iter().enumerate() {
        let root = match (&d.synthetic, &d.root) {
            (Some(_), Some(r)) => r.clone(),
            (Some(_), None) => opt.out.join(".synthetic").join(&d.name),
            (None, r) => r.clone().unwrap_or_default(),
        };
        let mut note =
            DatasetNote { name: d.name.clone(), root: root.display().to_string(), skipped: None, failed: None };
        if let Err(why) = crate::archive::config::validate_name(&d.name) {
            note.failed = Some(why);
        } else if d.synthetic.is_none() && !root.is_dir() {
            let why = format!("root {} not found", root.display());
            log(&format!("note: dataset '{}' skipped: {why}", d.name));
            note.skipped = Some(why);
        } else {
            let found = match &d.synthetic {
                Some(spec) => crate::archive::synthetic::generate(spec, &root).map_err(|e| {
                    let (top, cause) = (e.to_string(), e.root_cause().to_string());
                    if top.contains(&cause) {
                        format!("generating it: {top}")
                    } else {
                        format!("generating it: {top}: {cause}")
                    }
                }),
                None => Ok(()),
            }
            .and_then(|()| discover(i, d, &root).map_err(|e| e.to_string()));
            match found {
                Ok(g) => groups.extend(g),
                Err(why) => note.failed = Some(why),
            }
        }
        if let Some(why) = &note.failed {
            log(&format!("error: dataset '{}' failed: {why}", d.name));
        }
        notes.push(note);
    }
    (notes, groups)
}

/// Where a trial's output goes: `<out>/<dataset>/<rel with its extension replaced by .mcap>`.
pub fn output_path(out: &Path, dataset: &str, rel: &str) -> PathBuf {
    out.join(dataset).join(Path::new(rel).with_extension("mcap"))
}

/// True when `path` lies inside `out`: `out` followed by plain names only (no `..`, no root, no
/// prefix), as [`output_path`] gives for a valid dataset name and a discovered trial.
pub fn inside(out: &Path, path: &Path) -> bool {
    use std::path::Component;
    path.strip_prefix(out).is_ok_and(|rel| {
        rel.components().next().is_some() && rel.components().all(|c| matches!(c, Component::Normal(_)))
    })
}

/// Trials that cannot be converted because of where their output would go, with the reason:
/// outside `--out`, or the same output as another trial (`walk01.trc` and `walk01.TRC`, or
/// `walk01.c3d` and `walk01.trc`, both give `walk01.mcap`; on a case-insensitive file system,
/// so do `walk01.trc` and `WALK01.trc`). Keyed by (dataset index, trial path).
pub(super) fn output_conflicts(
    datasets: &[Dataset],
    groups: &[SubjectGroup],
    out: &Path,
) -> BTreeMap<(usize, String), String> {
    let mut by_output: BTreeMap<String, Vec<(usize, &TrialEntry)>> = BTreeMap::new();
    let mut bad = BTreeMap::new();
    for g in groups {
        for t in &g.trials {
            let o = output_path(out, &datasets[g.dataset].name, &t.rel);
            if !inside(out, &o) {
                bad.insert((g.dataset, t.rel.clone()), format!("its output {} would lie outside --out", o.display()));
                continue;
            }
            by_output.entry(o.to_string_lossy().to_lowercase()).or_default().push((g.dataset, t));
        }
    }
    for list in by_output.values().filter(|l| l.len() > 1) {
        let names: Vec<String> = list.iter().map(|(_, t)| t.path.display().to_string()).collect();
        for (d, t) in list {
            let o = output_path(out, &datasets[*d].name, &t.rel);
            bad.insert(
                (*d, t.rel.clone()),
                format!("output collision: {} would all write {}; rename one", names.join(" and "), o.display()),
            );
        }
    }
    bad
}

/// A subject's trials sorted into those settled without solving (contested outputs, unreadable
/// inputs, done ones when resuming: their outcomes) and those to convert.
pub(super) fn pending<'g>(
    d: &Dataset,
    g: &'g SubjectGroup,
    opt: &ConvertOptions,
    conflicts: &BTreeMap<(usize, String), String>,
) -> (Vec<TrialOutcome>, Vec<Todo<'g>>) {
    let mut outcomes = Vec::new();
    let mut todo = Vec::new();
    for t in &g.trials {
        let out = output_path(&opt.out, &d.name, &t.rel);
        if let Some(why) = conflicts.get(&(g.dataset, t.rel.clone())) {
            // Nothing is written or removed at a contested (or outside) path.
            outcomes.push(outcome(d, g, t, &out, "failed", Some(why.clone())));
            continue;
        }
        let hash = crate::archive::sha256_file(&t.path);
        match hash {
            Err(e) => outcomes.push(failed(d, g, t, &out, format!("{}: {e}", t.path.display()))),
            Ok(h) => {
                // Done when the output is complete (verified) and records this input.
                let done = (opt.resume && out.is_file())
                    .then(|| recorded_run(&out))
                    .flatten()
                    .filter(|run| run.get("input_sha256") == Some(&h));
                match done {
                    Some(run) => {
                        // A temporary file left by an interrupted run is not needed.
                        let _ = std::fs::remove_file(partial_path(&out));
                        // A suspect result stays suspect (the same input gives the same result).
                        let (status, why) = match run.get("verdict").map(String::as_str) {
                            Some("suspect") => ("suspect", run.get("verdict_reason").cloned()),
                            _ => ("skipped", None),
                        };
                        let robot = super::hook_outcome(opt, &out, true);
                        outcomes.push(TrialOutcome { robot, ..outcome(d, g, t, &out, status, why) });
                    }
                    None => todo.push((t, out, h)),
                }
            }
        }
    }
    (outcomes, todo)
}
