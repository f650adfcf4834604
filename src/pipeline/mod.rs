//! From files to results: the subject context (model, profile, settings), solving whole trials
//! (calibration, warm-started frames, gap bridging, segments in parallel), reports, and export to
//! OpenSim (`.mot` motions, scaled `.osim` models).

pub mod calibration;
pub mod calibration_frames;
pub mod context;
pub mod continuity;
pub mod convention;
pub mod device;
pub mod export;
pub mod feet_flat;
pub mod file_frames;
pub mod frames;
pub mod functional_hips;
pub mod ik_tasks;
pub mod joint_centres;
pub mod label_qc;
pub mod lanes;
pub mod marker_errors;
pub mod matching;
pub mod order;
pub mod plausibility;
pub mod registration;
pub mod report;
pub mod session;
pub mod stats;
pub mod stream;
pub mod subject;
pub mod subject_check;
pub mod trial;
pub mod verdict;

pub use context::{Context, ContextError};
pub use stream::{solve_trial, solve_trial_streaming, solve_trial_with, SolvedFrame, StreamedTrial};
pub use trial::{calibrate_subject, TrialError, TrialResult};
