//! From files to results: the subject context (model, profile, settings), solving whole trials
//! (calibration, warm-started frames, gap bridging, segments in parallel) and reports.

pub mod context;
pub mod device;
pub mod lanes;
pub mod report;
pub mod stats;
pub mod trial;

pub use context::{Context, ContextError};
pub use trial::{calibrate_subject, solve_trial, solve_trial_with, TrialError, TrialResult};
