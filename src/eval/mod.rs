//! The evaluation suite of METHOD.md ("Evaluation the method is judged by"): throughput and
//! convergence per dataset beside the published and OpenSim figures ([`bench`]), the leakage
//! audit of the joint solve against a stage-wise scale-then-IK baseline ([`audit`]), the spine
//! ablation poly / nopoly / classical ([`spine`]), joint angles against a reference motion
//! ([`compare`]), and pre-solve on the hard synthetic set
//! ([`hard`], [`presolve`]). Each part is a library function behind a `smocap` command;
//! `docs/EVALUATION.md` holds their results.

pub mod audit;
pub mod bench;
pub mod compare;
pub mod hard;
pub mod presolve;
pub mod spine;
