//! Where solved frames go: the sink a trial's frames are handed to in frame order, the frame
//! itself, and why a run of frames stopped.

use crate::kinematics::backend::BackendError;
use crate::pipeline::input::trial::{SinkError, TrialError};
use crate::solve::FrameStats;

/// Where solved frames go.
pub type FrameSink<'a> = dyn FnMut(SolvedFrame) -> Result<(), SinkError> + Send + 'a;

/// One solved frame.
#[derive(Clone, Debug)]
pub struct SolvedFrame {
    /// Frame index in the trial (0-based).
    pub index: usize,
    pub proxies: Vec<f64>,
    /// Statistics (a bridged frame has status `TooFewMarkers`).
    pub stats: FrameStats,
    /// Solve time (s, wall), as [`crate::pipeline::running::trial::TrialResult::frame_seconds`].
    pub seconds: f64,
    /// Bridged from its neighbours because too few markers were observed.
    pub bridged: bool,
    /// The frame's observed markers in model-marker order (3 per marker, m, NaN where not
    /// observed), as the solver read them.
    pub observed: Vec<f64>,
}

pub(crate) enum Stop {
    Backend(BackendError),
    Sink(usize, SinkError),
    Read(String),
    /// Every trial of the run failed: nothing left to solve for.
    AllFailed,
}

impl Stop {
    /// The trial's error.
    pub(crate) fn into_error(self, trial: &str) -> TrialError {
        let trial = trial.into();
        match self {
            Stop::Backend(source) => TrialError::Backend { trial, source },
            Stop::Sink(frame, source) => TrialError::Output { trial, frame, source },
            Stop::Read(why) => TrialError::Read { trial, why },
            Stop::AllFailed => TrialError::Read { trial, why: "stopped".into() },
        }
    }

    /// The same stop, for each of the trials a backend error stopped (only a backend error is
    /// shared).
    pub(crate) fn copy(&self) -> Stop {
        match self {
            Stop::Backend(BackendError::NoAdapter(m)) => Stop::Backend(BackendError::NoAdapter(m.clone())),
            Stop::Backend(BackendError::Device { adapter, message }) => {
                Stop::Backend(BackendError::Device { adapter: adapter.clone(), message: message.clone() })
            }
            Stop::Backend(BackendError::Shape(m)) => Stop::Backend(BackendError::Shape(m.clone())),
            Stop::Sink(_, e) => Stop::Read(e.to_string()),
            Stop::Read(why) => Stop::Read(why.clone()),
            Stop::AllFailed => Stop::AllFailed,
        }
    }
}

impl From<BackendError> for Stop {
    fn from(e: BackendError) -> Stop {
        Stop::Backend(e)
    }
}
