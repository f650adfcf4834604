//! Solvers: the per-frame trust-region QP ([`trqp`]), its QP backends ([`qp`]), the cold start
//! ([`init`]), the pre-solve warm start ([`presolve`]) and the multi-frame subject calibration
//! ([`calibrate`]).

pub mod calibrate;
pub mod calibration;
pub mod init;
pub mod joint;
pub mod placement;
pub mod presolve;
pub mod prior;
pub mod qp;
pub mod root;
mod schur;
pub mod settings;
pub mod trqp;

pub use calibrate::calibrate;
pub use calibration::{Calibration, StageCost};
pub use presolve::Presolver;
pub use settings::{FunctionalHips, Presolve, QpBackend, SolverSettings, StaticArms, WarmStart};
pub use trqp::{FrameSolver, FrameStats, FrameStatus};

/// The median of `v` (reordered in place; the mean of the two middle values for an even count;
/// NaN when empty).
pub fn median(v: &mut [f64]) -> f64 {
    // Selection, not a sort: O(n), in place, no allocation (a stable sort was ~10 % of a
    // synthetic conversion's profile, through the label screen). The same value either way.
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    let (lower, mid, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    let mid = *mid;
    if n % 2 == 1 {
        mid
    } else {
        let below = lower.iter().copied().max_by(f64::total_cmp).unwrap_or(mid);
        0.5 * (below + mid)
    }
}

/// A QP backend as the settings name it.
pub fn make_qp(kind: QpBackend) -> Box<dyn qp::QpSolver> {
    match kind {
        QpBackend::Boxqp => Box::new(qp::BoxQp::new()),
        QpBackend::Clarabel => Box::new(qp::ClarabelQp::new(Default::default())),
    }
}

/// The backend that can solve this proxy map's steps: clarabel when the profile has general
/// linear constraints (the box QP handles bounds only), else the one asked for.
pub fn backend_for(kind: QpBackend, proxy: &crate::model::proxy::ProxyMap) -> QpBackend {
    if proxy.constraints.is_empty() {
        kind
    } else {
        QpBackend::Clarabel
    }
}
