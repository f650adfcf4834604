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

/// A trial fits far worse than its siblings when its calibration frames' median marker RMSE is
/// more than this factor of its siblings' median...
pub const MISFIT_RATIO: f64 = 2.0;
/// ...and more than this much above it (m): a trial of another person (or with markers placed
/// differently) fits the one calibrated morphology by centimetres worse, noise by millimetres.
pub const MISFIT_EXCESS_M: f64 = 0.010;

/// Why some of the trials calibrated together do not belong with the others (empty when none):
/// `fits` holds each motion trial's per-frame marker RMSE (m) on its calibration frames under the
/// calibrated subject; a trial whose median is beyond [`MISFIT_RATIO`] times and
/// [`MISFIT_EXCESS_M`] above the median of its siblings' medians is named. Needs two trials.
pub fn misfits(fits: &[(&str, Vec<f64>)]) -> Vec<String> {
    let median = |v: &mut Vec<f64>| -> Option<f64> {
        v.retain(|x| x.is_finite());
        (!v.is_empty()).then(|| crate::solve::median(v))
    };
    let medians: Vec<Option<f64>> = fits.iter().map(|(_, r)| median(&mut r.clone())).collect();
    let mut out = Vec::new();
    for (i, (name, _)) in fits.iter().enumerate() {
        let Some(own) = medians[i] else { continue };
        let mut others: Vec<f64> =
            medians.iter().enumerate().filter(|(j, _)| *j != i).filter_map(|(_, m)| *m).collect();
        let Some(sib) = median(&mut others) else { continue };
        if own > MISFIT_RATIO * sib && own > sib + MISFIT_EXCESS_M {
            out.push(format!(
                "trial {name} fits the calibrated subject far worse than its siblings (calibration frames' marker RMSE {:.1} mm against {:.1} mm): another person's trial, or its markers placed differently",
                own * 1e3,
                sib * 1e3
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
    fn a_trial_fitting_centimetres_worse_than_its_siblings_is_named_and_noise_is_not() {
        let t = |name: &'static str, mm: f64| (name, vec![mm * 1e-3, mm * 1.1e-3, mm * 0.9e-3]);
        let why = misfits(&[t("a", 7.0), t("b", 8.0), t("c", 7.5), t("other", 28.0)]);
        assert_eq!(why.len(), 1, "{why:?}");
        assert!(why[0].contains("trial other") && why[0].contains("28.0 mm"), "{why:?}");
        // Twice as bad but by millimetres (a clean static against a walk): not named.
        assert!(misfits(&[t("a", 2.0), t("b", 5.0), t("c", 2.5)]).is_empty());
        // One trial has no sibling to compare with.
        assert!(misfits(&[t("a", 30.0)]).is_empty());
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
