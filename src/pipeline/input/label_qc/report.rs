//! What the label screen found and did: its events (swaps, jumps, ghosts; repaired, masked or
//! flagged) and the trial's summary, and applying the repairs to a window of frames.

use crate::io::MarkerTrial;
use crate::solve::settings::QcMode;
use serde::{Deserialize, Serialize};

/// What kind of labelling error an event is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// Two labels exchanged.
    Swap,
    /// A marker away from its body.
    Jump,
    /// A label that reappeared far from where its marker was.
    Ghost,
}

/// What was done about an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Action {
    /// The labels were exchanged back over the span.
    Repaired,
    /// The markers were treated as missing over the span.
    Masked,
    /// Reported only (`mode = flag`).
    Flagged,
}

/// One labelling error found.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LabelEvent {
    pub kind: EventKind,
    /// Model marker names (two for a swap).
    pub markers: Vec<String>,
    /// First and last frame of the span (0-based, inclusive).
    pub first_frame: usize,
    pub last_frame: usize,
    /// Frames of the span in which the screen detected it.
    pub detected_frames: usize,
    pub action: Action,
    /// Mean score (mm, see [`self`]) of its markers over the detected frames, before and after
    /// the exchange (swaps only; a mask leaves nothing to score).
    pub residual_before_mm: f64,
    pub residual_after_mm: Option<f64>,
}

/// The label quality control of one trial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LabelQc {
    pub mode: QcMode,
    /// Rigid marker pairs the screen used.
    pub rigid_pairs: usize,
    pub events: Vec<LabelEvent>,
    /// Frames with a marker masked, and their share of the trial's frames.
    pub masked_frames: usize,
    pub masked_share: f64,
    /// Why the trial is `suspect` because of its labels (`None` when it is not).
    pub suspect: Option<String>,
    /// Per event: its model markers (`a`, and `b` for a swap), for [`LabelQc::apply`].
    #[serde(skip)]
    pub(crate) ops: Vec<(usize, Option<usize>)>,
}

impl LabelQc {
    /// Nothing screened (`mode = off`).
    pub fn off() -> LabelQc {
        LabelQc {
            mode: QcMode::Off,
            rigid_pairs: 0,
            events: Vec::new(),
            masked_frames: 0,
            masked_share: 0.0,
            suspect: None,
            ops: Vec::new(),
        }
    }

    /// Whether it changes the data.
    pub fn changes(&self) -> bool {
        self.events.iter().any(|e| e.action != Action::Flagged)
    }

    /// Applies the repairs and masks to `w`, a window of the trial whose frame 0 is the trial's
    /// frame `first`, its columns matched to model markers by `columns`.
    pub fn apply(&self, w: &mut MarkerTrial, first: usize, columns: &[Option<usize>]) {
        let nl = w.labels.len();
        let n = w.n_frames();
        for (e, &(a, b)) in self.events.iter().zip(&self.ops) {
            let (f0, f1) = (e.first_frame.max(first), (e.last_frame + 1).min(first + n));
            if f0 >= f1 || e.action == Action::Flagged {
                continue;
            }
            let ca = columns[a];
            let cb = b.and_then(|b| columns[b]);
            for f in f0 - first..f1 - first {
                let at = |c: usize| (f * nl + c) * 3;
                match (e.action, ca, cb) {
                    (Action::Repaired, Some(ca), Some(cb)) => {
                        for k in 0..3 {
                            w.positions.swap(at(ca) + k, at(cb) + k);
                        }
                    }
                    (Action::Masked, _, _) => {
                        for c in [ca, cb].into_iter().flatten() {
                            w.positions[at(c)..at(c) + 3].fill(f64::NAN);
                        }
                    }
                    _ => {}
                }
            }
        }
    }

    /// One line per event, for stderr and the convert summary.
    pub fn lines(&self, trial: &str) -> Vec<String> {
        self.events
            .iter()
            .map(|e| {
                let after = e.residual_after_mm.map(|a| format!(" → {a:.1} mm")).unwrap_or_default();
                format!(
                    "{trial}: label QC: {} {} frames {}–{} ({} detected): {} (misfit {:.1} mm{after})",
                    e.kind.as_str(),
                    e.markers.join("/"),
                    e.first_frame,
                    e.last_frame,
                    e.detected_frames,
                    e.action.as_str(),
                    e.residual_before_mm
                )
            })
            .collect()
    }
}

impl EventKind {
    pub fn as_str(self) -> &'static str {
        match self {
            EventKind::Swap => "swap",
            EventKind::Jump => "jump",
            EventKind::Ghost => "ghost",
        }
    }
}

impl Action {
    pub fn as_str(self) -> &'static str {
        match self {
            Action::Repaired => "repaired",
            Action::Masked => "masked",
            Action::Flagged => "flagged",
        }
    }
}
