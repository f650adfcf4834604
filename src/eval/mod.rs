//! Evaluations of the method (METHOD.md, "Evaluation"): command-line studies that measure, on
//! synthetic or shared data, what the tests cannot (rates, overheads, comparisons).

pub mod hard;
pub mod presolve;
