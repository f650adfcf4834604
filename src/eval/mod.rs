//! Evaluation suite: the studies METHOD.md judges the method by, run on synthetic data with
//! known truth (spine ablation poly / nopoly / classical).

pub mod spine;
