//! Solvers: the per-frame trust-region QP ([`trqp`]), its QP backends ([`qp`]), the cold start
//! ([`init`]) and the multi-frame subject calibration ([`calibrate`]).

pub mod calibrate;
pub mod init;
pub mod qp;
pub mod settings;
pub mod trqp;

pub use calibrate::{calibrate, Calibration};
pub use settings::{QpBackend, SolverSettings, WarmStart};
pub use trqp::{FrameSolver, FrameStats, FrameStatus};

/// A QP backend as the settings name it.
pub fn make_qp(kind: QpBackend) -> Box<dyn qp::QpSolver> {
    match kind {
        QpBackend::Boxqp => Box::new(qp::BoxQp::new()),
        QpBackend::Clarabel => Box::new(qp::ClarabelQp::new(Default::default())),
    }
}
