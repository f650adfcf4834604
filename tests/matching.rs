//! Matching model marker names to marker file labels: exact, case-insensitive, subject prefix
//! stripped; ambiguity is an error naming both; unmatched names on both sides are listed.

use smocap::pipeline::input::matching::{match_names, strip_subject_prefix, MatchError, MatchKind};

fn labels(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

#[test]
fn exact_then_case_insensitive_then_prefix_stripped() {
    let model = ["C7", "LASI", "RASI", "T10", "STRN"];
    let file = labels(&["Derrick:T10", "lasi", "C7", "Derrick:rasi", "EXTRA"]);
    let m = match_names(&model, &file).expect("matches");
    assert_eq!(m.columns, [Some(2), Some(1), Some(3), Some(0), None]);
    use MatchKind::*;
    assert_eq!(m.kinds, [Some(Exact), Some(CaseInsensitive), Some(PrefixStripped), Some(PrefixStripped), None]);
    assert_eq!(m.unmatched_model, ["STRN"]);
    assert_eq!(m.unmatched_trial, ["EXTRA"]);
    assert_eq!(m.renamed(&model, &file), [("lasi", "LASI"), ("Derrick:rasi", "RASI"), ("Derrick:T10", "T10")]);
}

#[test]
fn a_stricter_match_wins_and_leaves_the_other_label_unmatched() {
    let model = ["C7"];
    let m = match_names(&model, &labels(&["Derrick:C7", "c7", "C7"])).expect("exact wins");
    assert_eq!(m.columns, [Some(2)]);
    assert_eq!(m.unmatched_trial, ["Derrick:C7", "c7"]);
}

#[test]
fn two_labels_for_one_marker_are_an_error_naming_both() {
    let e = match_names(&["C7"], &labels(&["Derrick:C7", "Other:C7"])).expect_err("ambiguous");
    assert!(matches!(e, MatchError::TwoLabels { .. }));
    let msg = e.to_string();
    assert!(msg.contains("'Derrick:C7'") && msg.contains("'Other:C7'") && msg.contains("'C7'"), "{msg}");
    let m = match_names(&["C7"], &labels(&["c7", "C7 "])).expect("a trailing space makes another label");
    assert_eq!(m.columns, [Some(0)]);
    let e = match_names(&["Knee"], &labels(&["knee", "KNEE"])).expect_err("two case variants");
    assert!(e.to_string().contains("ignoring case"), "{e}");
}

#[test]
fn one_label_for_two_markers_is_an_error_naming_both() {
    let e = match_names(&["Knee", "KNEE"], &labels(&["knee"])).expect_err("ambiguous");
    let msg = e.to_string();
    assert!(matches!(e, MatchError::TwoMarkers { .. }), "{msg}");
    assert!(msg.contains("'Knee'") && msg.contains("'KNEE'") && msg.contains("'knee'"), "{msg}");
}

#[test]
fn prefixes_strip_at_the_last_colon_only_when_present() {
    assert_eq!(strip_subject_prefix("Derrick:C7"), "C7");
    assert_eq!(strip_subject_prefix("a:b:C7"), "C7");
    assert_eq!(strip_subject_prefix("C7"), "C7");
    let m = match_names(&["C7"], &labels(&["Derrick:"])).expect("no match");
    assert_eq!(m.unmatched_model, ["C7"]);
    assert_eq!(m.unmatched_trial, ["Derrick:"]);
}

#[test]
fn nothing_in_common_leaves_everything_unmatched() {
    let m = match_names(&["A", "B"], &labels(&["X"])).expect("no error");
    assert!(m.columns.iter().all(Option::is_none));
    assert_eq!((m.unmatched_model.len(), m.unmatched_trial.len()), (2, 1));
    let m = match_names(&[], &[]).expect("empty");
    assert!(m.columns.is_empty());
}

#[test]
fn plug_in_gait_cmu_and_opensim_spellings_match_through_synonyms() {
    let model = ["LASI", "RASI", "LPSI", "RPSI", "RTIB", "C7"];
    let file = labels(&["Subj:LFWT", "r.ASIS", "L_PSIS", "RBWT", "RSHN", "C7"]);
    let m = match_names(&model, &file).expect("matches");
    assert_eq!(m.columns, vec![Some(0), Some(1), Some(2), Some(3), Some(4), Some(5)]);
    assert_eq!(m.kinds[0], Some(MatchKind::Synonym));
    assert_eq!(m.kinds[5], Some(MatchKind::Exact));
    assert!(m.unmatched_model.is_empty() && m.unmatched_trial.is_empty());
}

#[test]
fn a_stricter_pass_wins_over_a_synonym_and_profiles_add_synonyms() {
    // `LASI` present exactly: the synonym `LFWT` stays unmatched rather than ambiguous.
    let m = match_names(&["LASI"], &labels(&["LFWT", "LASI"])).expect("exact wins");
    assert_eq!(m.columns, vec![Some(1)]);
    assert_eq!(m.unmatched_trial, vec!["LFWT".to_string()]);
    let mut syn = smocap::pipeline::input::matching::Synonyms::default();
    assert!(!syn.equivalent("KNEE_OUT", "RKNE"));
    syn.add_group(["KNEE_OUT", "RKNE"]);
    assert!(syn.equivalent("knee.out", "R.Knee"));
}
