//! The evaluation suite of METHOD.md ("Evaluation the method is judged by"): throughput and
//! convergence per dataset beside the published and OpenSim figures ([`bench`]), the leakage
//! audit of the joint solve against a stage-wise scale-then-IK baseline ([`audit`]), and the spine
//! ablation poly / nopoly / classical on synthetic data with known truth ([`spine`]). Each part is
//! a library function behind a `smocap` command; `docs/EVALUATION.md` holds their results.

pub mod audit;
pub mod bench;
pub mod spine;
