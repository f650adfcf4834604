//! Garbage in is not "ok" out: a solved trial is judged on its frames (implausible marker
//! positions were masked and unsolvable trials refused in [`crate::pipeline::input::trial`]): a non-finite result fails it, most frames at the iteration cap make it `suspect`.

use crate::solve::{FrameStats, FrameStatus};

/// A trial is `suspect` when more than this fraction of its solved frames stopped at the
/// iteration cap.
pub const SUSPECT_CAP_FRACTION: f64 = 0.5;

/// What the frames of a solved trial say about it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Verdict {
    Ok,
    /// Solved, but not to be trusted: why.
    Suspect(String),
    /// Not a result: why.
    Failed(String),
}

impl Verdict {
    /// The report status: "ok", "suspect" or "failed".
    pub fn status(&self) -> &'static str {
        match self {
            Verdict::Ok => "ok",
            Verdict::Suspect(_) => "suspect",
            Verdict::Failed(_) => "failed",
        }
    }

    pub fn reason(&self) -> Option<String> {
        match self {
            Verdict::Ok => None,
            Verdict::Suspect(w) | Verdict::Failed(w) => Some(w.clone()),
        }
    }
}

/// Running judgement of a trial's frames, fed in frame order.
#[derive(Clone, Debug, Default)]
pub struct Judge {
    solved: usize,
    at_cap: usize,
    /// First frame with a non-finite proxy or energy/RMSE.
    nonfinite: Option<usize>,
}

impl Judge {
    /// Records frame `f` (`bridged` frames are not solved; their proxies are checked only).
    pub fn frame(&mut self, f: usize, proxies: &[f64], stats: &FrameStats, bridged: bool) {
        let finite = proxies.iter().all(|v| v.is_finite());
        let solved = !bridged && stats.status != FrameStatus::TooFewMarkers;
        if solved {
            self.solved += 1;
            self.at_cap += (stats.status == FrameStatus::MaxIterations) as usize;
        }
        if self.nonfinite.is_none() && (!finite || solved && !(stats.rmse_m.is_finite() && stats.energy.is_finite())) {
            self.nonfinite = Some(f);
        }
    }

    /// The first frame with a non-finite result, if any.
    pub fn nonfinite(&self) -> Option<usize> {
        self.nonfinite
    }

    pub fn verdict(&self) -> Verdict {
        if let Some(f) = self.nonfinite {
            return Verdict::Failed(format!("frame {f}: the solver's result is not finite"));
        }
        if self.solved == 0 {
            return Verdict::Failed("no frame could be solved".into());
        }
        if self.at_cap as f64 > SUSPECT_CAP_FRACTION * self.solved as f64 {
            return Verdict::Suspect(format!(
                "{} of {} solved frames stopped at the iteration cap",
                self.at_cap, self.solved
            ));
        }
        Verdict::Ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(status: FrameStatus, rmse_m: f64) -> FrameStats {
        FrameStats { iterations: 3, accepted: 3, energy: 1.0, rmse_m, markers_used: 10, status }
    }

    #[test]
    fn most_frames_at_the_cap_are_suspect_and_a_nan_fails() {
        let mut j = Judge::default();
        j.frame(0, &[0.0], &stats(FrameStatus::MaxIterations, 0.01), false);
        j.frame(1, &[0.0], &stats(FrameStatus::Converged, 0.01), false);
        assert_eq!(j.verdict(), Verdict::Ok);
        j.frame(2, &[0.0], &stats(FrameStatus::MaxIterations, 0.01), false);
        assert_eq!(j.verdict().status(), "suspect");
        j.frame(3, &[0.0], &stats(FrameStatus::Converged, f64::NAN), false);
        assert_eq!(j.verdict().status(), "failed");
        let mut j = Judge::default();
        j.frame(0, &[0.0], &stats(FrameStatus::TooFewMarkers, f64::NAN), true);
        assert_eq!(j.verdict(), Verdict::Failed("no frame could be solved".into()));
    }
}
