//! From files to results, by stage (`docs/ARCHITECTURE.md`):
//! - [`context`]: the subject context (model, profile, settings) every stage reads, and [`stats`];
//! - [`input`]: a trial's markers brought into the model's conventions, matched to its markers,
//!   screened for label errors, read window by window;
//! - [`calibration`]: a subject's morphology, posture and markers from its static and motion
//!   trials;
//! - [`running`]: solving a calibrated subject's trials frame by frame (lanes, segments, frame
//!   order, gap bridging, the CPU or wgpu backend);
//! - [`results`]: reports, pose plausibility, verdicts, export to OpenSim (`.mot`, scaled `.osim`);
//! - [`session`]: a calibrated subject solving its trials as `solve` does, through all of them.
//!
//! Imports run one way: a stage uses the stages before it, never those after
//! (`tests/architecture.rs`).

pub mod calibration;
pub mod context;
pub mod input;
pub mod results;
pub mod running;
pub mod session;
pub mod stats;

pub use calibration::calibrate_subject;
pub use context::{Context, ContextError};
pub use input::trial::TrialError;
pub use running::sink::SolvedFrame;
pub use running::stream::{solve_trial, solve_trial_streaming, solve_trial_with, StreamedTrial};
pub use running::trial::TrialResult;
