//! What marker files say of their subject (C3D `SUBJECTS:NAMES`, Vicon's `PROCESSING:Height` and
//! `Bodymass`): the anthropometric prior's height and mass when the user gives none, and a check
//! that the trials grouped as one subject are one person.

use crate::io::c3d::{read_subject, C3dSubject};
use crate::model::anthropometry::SubjectInfo;
use std::path::Path;

/// Recorded heights further apart than this (m) are two people (a person's own sessions agree
/// to a centimetre or two).
pub const HEIGHT_TOLERANCE_M: f64 = 0.05;

/// The subject records of the C3D files among `paths` (other files, and C3D files whose
/// parameters say nothing of the subject or cannot be read, left out).
pub fn subject_records(paths: &[&Path]) -> Vec<(String, C3dSubject)> {
    paths
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("c3d")))
        .filter_map(|p| read_subject(p).ok().filter(|s| !s.is_empty()).map(|s| (p.display().to_string(), s)))
        .collect()
}

/// Fills the height and mass of `subject` that the user did not give from the first record that
/// has them; returns a line saying what was taken from which file (`None` when nothing was).
pub fn fill_from_records(subject: &mut SubjectInfo, records: &[(String, C3dSubject)]) -> Option<String> {
    let mut taken = Vec::new();
    if subject.height_m.is_none() {
        if let Some((file, h)) = records.iter().find_map(|(f, s)| s.height_m.map(|h| (f, h))) {
            subject.height_m = Some(h);
            taken.push(format!("height {h:.3} m from {file} (PROCESSING:Height)"));
        }
    }
    if subject.mass_kg.is_none() {
        if let Some((file, m)) = records.iter().find_map(|(f, s)| s.mass_kg.map(|m| (f, m))) {
            subject.mass_kg = Some(m);
            taken.push(format!("mass {m:.1} kg from {file} (PROCESSING:Bodymass)"));
        }
    }
    if subject.validate().is_err() {
        // Not a person's measurements: the prior stays as the user left it.
        *subject = SubjectInfo { height_m: None, mass_kg: None, ..*subject };
        return None;
    }
    (!taken.is_empty()).then(|| format!("anthropometric prior: subject {}", taken.join(", ")))
}

/// Why the trials of `records` are not one person (empty when nothing says so): they name
/// different subjects, or record heights more than [`HEIGHT_TOLERANCE_M`] apart.
pub fn inconsistencies(records: &[(String, C3dSubject)]) -> Vec<String> {
    let mut out = Vec::new();
    let mut names: Vec<(String, &str)> = Vec::new();
    for (file, s) in records {
        for n in &s.names {
            if !names.iter().any(|(m, _)| m.eq_ignore_ascii_case(n)) {
                names.push((n.clone(), file));
            }
        }
    }
    if names.len() > 1 {
        let list: Vec<String> = names.iter().map(|(n, f)| format!("{n} ({f})")).collect();
        out.push(format!("the trials name different subjects (SUBJECTS:NAMES): {}", list.join(", ")));
    }
    let heights: Vec<(f64, &str)> = records.iter().filter_map(|(f, s)| s.height_m.map(|h| (h, f.as_str()))).collect();
    let lo = heights.iter().min_by(|a, b| a.0.total_cmp(&b.0));
    let hi = heights.iter().max_by(|a, b| a.0.total_cmp(&b.0));
    if let (Some(lo), Some(hi)) = (lo, hi) {
        if hi.0 - lo.0 > HEIGHT_TOLERANCE_M {
            out.push(format!(
                "the trials record different heights (PROCESSING:Height): {:.3} m ({}) and {:.3} m ({})",
                lo.0, lo.1, hi.0, hi.1
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(name: &str, h: f64) -> (String, C3dSubject) {
        (format!("{name}.c3d"), C3dSubject { names: vec![name.into()], height_m: Some(h), ..Default::default() })
    }

    #[test]
    fn one_persons_trials_are_consistent_and_two_peoples_are_not() {
        assert!(inconsistencies(&[rec("Ann", 1.79), rec("ann", 1.785)]).is_empty());
        let why = inconsistencies(&[rec("Ann", 1.505), rec("Bob", 1.79)]);
        assert_eq!(why.len(), 2, "{why:?}");
        assert!(why[0].contains("Ann") && why[0].contains("Bob") && why[1].contains("1.505"));
    }

    #[test]
    fn recorded_height_and_mass_fill_only_what_the_user_did_not_give() {
        let mut r = rec("Ann", 1.76);
        r.1.mass_kg = Some(74.0);
        let mut s = SubjectInfo { height_m: Some(1.8), ..Default::default() };
        let note = fill_from_records(&mut s, &[r]).unwrap();
        assert_eq!((s.height_m, s.mass_kg), (Some(1.8), Some(74.0)));
        assert!(note.contains("mass 74.0 kg") && !note.contains("height"), "{note}");
    }
}
