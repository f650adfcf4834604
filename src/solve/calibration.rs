//! What calibrating a subject gives ([`Calibration`]: scales, markers, calibration poses and their
//! reports) and what each of its stages cost ([`StageCost`]).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// What calibration found.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Calibration {
    /// Full proxy vector whose scale entries are the subject's morphology (pose entries: the
    /// last calibration frame's pose).
    pub proxies: Vec<f64>,
    /// Frames used.
    pub frames: usize,
    /// Outer iterations run (all stages).
    pub iterations: u32,
    /// Mean marker RMSE over the calibration frames (m).
    pub rmse_m: f64,
    /// Markers whose offsets were registered.
    #[serde(default)]
    pub registered: usize,
    /// Wall time of the calibration (s).
    #[serde(default)]
    pub seconds: f64,
    /// The calibrated subject against its priors: each scale's z-score, bounds, stature.
    #[serde(default)]
    pub prior: super::prior::PriorReport,
    /// Final proxies of every calibration frame (shared scales, own pose).
    #[serde(skip)]
    pub frame_proxies: Vec<Vec<f64>>,
    /// Every model marker's unit-scale offset (body frame, m) after registration or marker
    /// placement; `None` when the offsets stayed the model's.
    #[serde(skip)]
    pub marker_offsets: Option<Vec<Vector3<f64>>>,
    /// Calibration frames from static trials (the first ones of `frame_proxies`).
    #[serde(default)]
    pub static_frames: usize,
    /// The static frames' posture, and what makes it implausible for a standing subject.
    #[serde(default)]
    pub posture: super::prior::StaticPostureReport,
    /// Each marker's move by registration or placement, and the landmarks moved too far.
    #[serde(default)]
    pub registration_report: super::prior::RegistrationReport,
    /// The root's joints (the hips) found from the motion against the calibrated model's.
    #[serde(default)]
    pub functional_centres: Vec<super::prior::FunctionalCentre>,
    /// The hip joints moved to their functional centres (`functional_hips = "apply"`); the
    /// subject's model ([`crate::pipeline::Context::pinned_to`]) has them there.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub joint_moves: Vec<super::prior::JointMove>,
    /// With `functional_hips = "apply"`: the hips' functional centres in the pelvis frame of the
    /// first stage (landmarks at the model's offsets, before registration), which the moves
    /// are made from.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub landmark_centres: Vec<super::prior::FunctionalCentre>,
    /// Motion trials whose calibration frames the calibrated subject fits far worse than their
    /// siblings' (`pipeline::subject_check::misfits`): another person's trial, or markers placed
    /// differently. Makes the calibration suspect.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub trial_misfits: Vec<String>,
    /// What each stage cost (tracking, each joint solve, the report), in order.
    #[serde(default)]
    pub stages: Vec<StageCost>,
}

/// The cost of one calibration stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct StageCost {
    /// `track` (pose-only tracking to the chosen frames), `initial` (their poses at the starting
    /// scales), `scales` (scales and poses on the first-stage markers), `scales_reweighed`
    /// (again under the re-weighed priors, without registration), `registration` (scales,
    /// poses and offsets), `placement` (OpenSim's MarkerPlacer), `report` (posture, functional
    /// centres, priors).
    pub stage: String,
    /// Frames the stage works on.
    pub frames: usize,
    /// Frame solves (`track`, `initial`) or accepted Levenberg–Marquardt steps (joint solves).
    pub iterations: u32,
    /// Rejected Levenberg–Marquardt steps (joint solves).
    #[serde(default)]
    pub rejected: u32,
    /// Wall time (s).
    pub seconds: f64,
}

impl StageCost {
    /// A stage that started at `started`.
    pub fn new(stage: &str, frames: usize, iterations: u32, rejected: u32, started: std::time::Instant) -> StageCost {
        StageCost { stage: stage.into(), frames, iterations, rejected, seconds: started.elapsed().as_secs_f64() }
    }

    /// One line: `stage 12.3 ms (frames, iterations[+rejected])` per stage.
    pub fn summary(stages: &[StageCost]) -> String {
        stages
            .iter()
            .map(|s| {
                let rej = if s.rejected > 0 { format!("+{}", s.rejected) } else { String::new() };
                format!("{} {:.1} ms ({} fr, {}{rej} it)", s.stage, s.seconds * 1e3, s.frames, s.iterations)
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

impl Calibration {
    /// Why this calibration cannot be trusted (empty when it can): a non-finite result, or a
    /// scale factor at an end of its range (the data could not determine it, or pulled it
    /// somewhere a person is not).
    pub fn suspect(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.proxies.iter().any(|v| !v.is_finite()) || !self.rmse_m.is_finite() {
            out.push("the calibration is not finite".to_string());
        }
        for s in self.prior.scales.iter().filter(|s| s.at_bound) {
            out.push(format!("scale {} = {:.3} is at its bound [{}, {}]", s.name, s.value, s.range.0, s.range.1));
        }
        out.extend(self.posture.suspect.iter().cloned());
        out.extend(self.registration_report.suspect.iter().cloned());
        out.extend(self.trial_misfits.iter().cloned());
        out
    }

    /// [`Calibration::suspect`], plus scales beyond 3 standard deviations of their prior.
    pub fn warnings(&self) -> Vec<String> {
        let mut out = self.suspect();
        for s in self.prior.scales.iter().filter(|s| s.z.abs() > 3.0) {
            let of = s
                .dimension
                .as_deref()
                .map_or("the stature-ratio prior".to_string(), |d| format!("its dimension '{d}'"));
            out.push(format!("scale {} = {:.3} is {:.1} standard deviations from {of}", s.name, s.value, s.z));
        }
        out.extend(self.registration_report.warnings.iter().cloned());
        for c in self.functional_centres.iter().filter(|c| c.distance_mm > 30.0) {
            out.push(format!(
                "{}'s joint centre from the motion is {:.0} mm from the calibrated model's",
                c.body, c.distance_mm
            ));
        }
        out
    }
}
