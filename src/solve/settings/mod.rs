//! Solver settings with documented defaults. Serialised into every report and output so that a
//! result says how it was obtained; a profile's `[solver]` table overrides any field.

pub mod label_qc;

pub use label_qc::{LabelQcSettings, QcMode};
use serde::{Deserialize, Serialize};

/// Which QP backend solves the trust-region step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum QpBackend {
    /// Projected-Newton box QP (bounds only): the fast default.
    #[default]
    Boxqp,
    /// clarabel interior point (bounds and general linear constraints).
    Clarabel,
}

/// How a frame's first iterate is chosen from the previous frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum WarmStart {
    /// The previous frame's solution (default: measured 2 iterations median against 3 for
    /// extrapolation on 2 mm-noise synthetic data at 100 Hz, where extrapolating amplifies noise).
    #[default]
    Previous,
    /// Linear extrapolation of the two previous solutions (clamped to the proxy ranges).
    Extrapolate,
}

/// When the trial pipeline runs the pre-solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Presolve {
    /// Never: every frame starts from its warm start (the behaviour before pre-solve existed).
    Never,
    /// After a trial is solved, frames whose marker RMSE exceeds median + 6 MAD of the trial's
    /// frames that fit (unfittable frames, bad data, left out) are solved again with pre-solve
    /// from their warm start; the lower-energy result is kept.
    #[default]
    Auto,
    /// Every warm-started frame is pre-solved before its trust-region QP.
    Always,
}

/// What calibration does with the hip centres it finds from the motion
/// ([`crate::pipeline::calibration::joint_centres`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum FunctionalHips {
    /// Not computed.
    Off,
    /// Computed and reported against the model's (`calibration.functional_centres`); the
    /// model's hips stay where its scaling puts them.
    #[default]
    Report,
    /// Where a fit is well determined, the subject's hip joints move to it (in the pelvis frame)
    /// and registration is solved again with them: every later stage, the solved trials and the
    /// exported model use the moved hips (docs/CALIBRATION.md, "Functional hip centres").
    Apply,
}

/// How a static trial's arms are taken in calibration (the static protocol's arm posture).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum StaticArms {
    /// Free: the protocol's arm posture is not known (down, in a T, crossed); the markers alone
    /// pose the arms.
    #[default]
    Free,
    /// The arms hang at the model's neutral (every arm coordinate 0: for the shipped model arms
    /// at the sides, elbows straight, palms toward the thighs, wrists straight): held there with
    /// `static_posture_sd_deg`, as the legs and trunk are. Registration then places the arm and
    /// hand landmarks where that posture sees them, which fixes the forearm's and hand's rotation
    /// that one misplaced styloid or hand marker would otherwise set (docs/CALIBRATION.md).
    Neutral,
}

/// Trust-region QP settings (units: metres, radians; scale factors dimensionless).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverSettings {
    /// Cap on trust-region iterations (QP solves) per frame. Default 20.
    pub max_iterations: u32,
    /// Stop when the marker RMSE falls below this (m). Default 1e-6.
    pub residual_tol_m: f64,
    /// Stop when an accepted step lowers `E` by less than this fraction of `E`. Default 1e-2:
    /// at that point the optimisation error left is far below the noise of the estimate itself
    /// (noise alone leaves `E` a fraction ≈ (3M − np)/3M of the residual energy); noise-free data
    /// still converge fully through `residual_tol_m`.
    pub rel_decrease_tol: f64,
    /// Stop after an accepted, undamped step whose actual decrease matched the predicted one to
    /// within this fraction of the new `E` (the linearisation is exact to that level, so another
    /// step gains no more). 0 disables. Default 0.01: measured on 2 mm-noise synthetic trials,
    /// it halves the iterations (median 2 → 1) with unchanged joint-angle and scale errors.
    pub model_error_tol: f64,
    /// Stop when the largest step component is below this (proxy units). Default 1e-9.
    pub step_tol: f64,
    /// Step box half-width for rotational proxies (rad). Default 0.5.
    pub step_rotation_rad: f64,
    /// Step box half-width for translational proxies (m). Default 0.25.
    pub step_translation_m: f64,
    /// Step box half-width for scale proxies. Default 0.1.
    pub step_scale: f64,
    /// Initial Levenberg–Marquardt damping `λ`; `W_damp = λ·diag(max(H_kk, damping_floor))`. Default 1e-4.
    pub damping_init: f64,
    /// Smallest damping. Default 1e-9.
    pub damping_min: f64,
    /// Largest damping; a frame that needs more stops. Default 1e8.
    pub damping_max: f64,
    /// Floor on the diagonal that `λ` scales. Default 1e-6.
    pub damping_floor: f64,
    /// `ε_ρ` in `ρ = Δf_act / (Δf_pred + ε_ρ)`. Default 1e-15.
    pub rho_eps: f64,
    /// Weight on `(q − q_warm)²` that keeps unobserved coordinates determined (m²/rad²). Default 1e-6.
    pub pose_prior_weight: f64,
    /// Weight on `(s − s_calibrated)²` in motion frames (m² per unit scale²). Default 1.0.
    pub scale_tracking_weight: f64,
    /// Frames with fewer observed markers are reported and bridged. Default 3.
    pub min_markers: usize,
    pub warm_start: WarmStart,
    pub qp: QpBackend,
    /// Frames used by calibration from a subject's static trials (all of them together); 0 uses
    /// every frame with enough markers. Default 12: with `calibration_frames_motion` 56 it keeps
    /// the share of standing frames the former 20 of 96 had. That share sets how much the static
    /// posture weighs against the motion: 20 with 56 moved the Plug-in Gait subject's hip
    /// flexion 0.7° (its offset from Vicon's +5.6° → +6.3°), 12 gives +5.7°; 10 with 96 moved the
    /// Rajagopal subject's angles 0.06° away from OpenSim's (docs/CALIBRATION.md, "Cost").
    pub calibration_frames: usize,
    /// Weight of the prior pulling scale factors toward 1 during calibration. Default 1e-6.
    pub calibration_scale_prior: f64,
    /// Cap on the accepted Levenberg–Marquardt steps of each stage of the multi-frame
    /// calibration (rejected steps are not counted: a run of them ends when the damping passes
    /// 1e8). A safety net: stages stop on `calibration_rel_tol` (the shipped model's synthetic
    /// subjects in 2–4 steps, the OpenCap subject in 5–20). Default 50.
    pub calibration_max_iterations: u32,
    /// Calibration stops on the objective's relative progress: when an accepted step lowers it
    /// by less than this fraction, when two accepted steps in a row, each as its model predicted,
    /// leave less than this fraction to gain at their rate of progress, or when a rejected step's
    /// damped model predicts less than this fraction to gain (or when a kept step moves no scale
    /// factor or offset by 1e-5, a rejected one by 1e-4). Default 1e-5: the
    /// OpenCap subject's figures are those of 1e-6 to the reported digits (docs/CALIBRATION.md,
    /// "Cost") in half the time; the scales then move by far less than their uncertainty.
    pub calibration_rel_tol: f64,
    /// Levenberg–Marquardt damping of calibration from the gain ratio (Nielsen's rule: `λ` follows
    /// how well the damped model predicted each kept step) instead of the fixed rule (÷3 after a
    /// kept step, ×4 after a rejected one). Default false: both converge since poses at an end of
    /// their range are held there (docs/CALIBRATION.md, "Cost"); the gain-ratio rule's Rajagopal
    /// subject had a foot scale 3.16 σ from its prior.
    pub calibration_gain_ratio: bool,
    /// Marker placement after calibration (OpenSim's MarkerPlacer): every marker not flagged
    /// `fixed` moves to where the calibration frames observed it on its body. When some markers
    /// are flagged fixed, only those inform the scales (the others are untrusted until placed).
    /// Default false.
    pub marker_placement: bool,
    /// Pre-solve (METHOD.md; `src/solve/presolve.rs`): root placement and root-to-leaf sweeps
    /// of local joint fits before the trust-region QP. Default `auto`: only frames whose marker
    /// RMSE is an outlier of their trial (median + 6 MAD) are solved again with it, which leaves
    /// ordinary frames untouched and costs time only where a frame went wrong (`smocap
    /// eval-presolve` measures both; `docs/EVALUATION.md`).
    pub presolve: Presolve,
    /// Root-to-leaf sweeps per pre-solve. Default 2 (the second corrects parents for their
    /// children's new poses, as the overlapping subproblems share markers).
    pub presolve_sweeps: u32,
    /// Frames used by calibration from a subject's motion trials, spread evenly over each trial
    /// (this many shared between them, rounded up per trial). Default 56 (96 before): with the
    /// default tracking, the OpenCap subject's every trial mean and worst core angle against
    /// AddBiomechanics is better than with 96 and its pooled marker RMSE lower (12.43 against
    /// 12.47 mm); 48 made every trial worse, 64 about as 96 (docs/CALIBRATION.md, "Cost");
    /// calibration time grows linearly.
    pub calibration_frames_motion: usize,
    /// Time between the frames tracked (pose only, each warm-started from the one before) from a
    /// trial's first usable frame to its calibration frames, so that each calibration frame
    /// starts in the motion's basin (s). Every frame at or below `1 / rate`; calibration frames are
    /// always tracked. Default 0.1 (every tenth frame at 100 Hz, every sixth at 60 Hz; 0 tracks
    /// every frame, as before; what it changes: docs/CALIBRATION.md, "Cost").
    pub calibration_track_step_s: f64,
    /// Trust-region iterations of each frame tracked between calibration frames (those only carry
    /// the pose forward as the next frame's start; the calibration frames themselves are always
    /// solved to convergence); 0 solves them to convergence too (`max_iterations`). Default 1:
    /// half the tracking's iterations on the synthetic subjects; the OpenCap subject's
    /// calibration lands in an equally good minimum (trial marker RMSE 12.4712 mm against
    /// 12.4649 with 0, every trial's mean core angle 0.004–0.044° better, the worst up to 0.003°
    /// worse; docs/CALIBRATION.md, "Cost").
    pub calibration_track_iterations: u32,
    /// Coverage radius of the calibration frames' choice (m): a candidate frame (one per
    /// `calibration_track_step_s`) joins the calibration when its markers' pose (about their
    /// centroid, rotated onto the first candidate's) is farther than this RMS distance from every
    /// frame chosen before it, at most `calibration_frames` / `calibration_frames_motion` in all
    /// (farthest first when more qualify); so a repetitive archive gives fewer frames than a
    /// varied one, and a standing trial few. 0 spreads the frames evenly over time in each trial.
    /// Default 0: on the OpenCap subject the net's frames (more of the poses' extremes, fewer of
    /// the walks' common poses) made every trial's mean core angle 0.1–0.25° worse and the pooled
    /// marker RMSE 12.95 mm; a standing trial's single frame weighs too little (docs/CALIBRATION.md,
    /// "Cost").
    pub calibration_coverage_m: f64,
    /// Marker registration: calibration estimates every marker's body-frame offset together with
    /// the scales and the calibration poses, offsets held near the model's (anatomical markers
    /// strongly, tracking markers weakly). Default true; off with `--no-register`, and an
    /// OpenSim Scale setup's `MarkerPlacer` decides instead when one is given.
    pub registration: bool,
    /// Standard deviation of a landmark's (anatomical marker's) offset about the model's (m),
    /// weighed like the scale priors: one standard deviation costs what `prior_fraction ×
    /// (calibration frames)` frames with one marker missed by `prior_noise_sd_m` cost, so landmarks
    /// stay within millimetres however many frames calibration uses. Default 0.004 (measured in
    /// docs/CALIBRATION.md against AddBiomechanics' IK, Vicon's Plug-in Gait angles and synthetic
    /// truth: 3, 4 and 6 mm; 4 mm was best or equal on all three). A prior of one frame's weight
    /// washed out: 96 frames moved knee and ASIS markers by 20–40 mm and bent the joints.
    pub registration_anatomical_sd_m: f64,
    /// Standard deviation of a tracking marker's offset about the model's (m). Default 0.1.
    pub registration_tracking_sd_m: f64,
    /// Largest move of a marker's offset from the model's, per axis (m). Default 0.35: generic
    /// models put cluster markers at placeholder positions (OpenCap's shank cluster sits 0.23 m
    /// from where the subject wore it; a bound of 0.2 m left that shank 26 mm off its markers and
    /// its hip 4° out of plane). Landmarks are held far closer by their prior.
    pub registration_bound_m: f64,
    /// Marker noise `σ_n` (m) that puts the priors in the marker objective's units: one standard
    /// deviation of a prior costs what one marker missed by `σ_n` in one frame costs. Default
    /// 0.01. The offset priors of registration use it as it is; the scale priors use it for the
    /// first stage, then the marker RMSE that stage reaches (within 2–30 mm: empirical Bayes).
    pub prior_noise_sd_m: f64,
    /// Weight of the subject-level priors on the scales (anthropometric, stature ratio,
    /// anisotropy) relative to the calibration data: one standard deviation costs what
    /// `prior_fraction × (calibration frames)` frames with one marker missed by the data's noise
    /// cost, so the priors' say does not depend on how many frames calibration picks. Default 0.1:
    /// the frames of a motion are far from independent observations (skin motion and model error
    /// repeat from frame to frame). Measured (docs/CALIBRATION.md): on the OpenCap/AddBiomechanics
    /// subject (96 motion frames) ~0.01 leaves an upper arm 3.3 σ long and a 1.81 m stature (true
    /// 1.84 m), 0.1 gives every scale within 2.7 σ; on the synthetic audit (20 static frames, scales
    /// drawn independently, not in human proportions) 0.5 raised the scale error from 4.6 to 4.8 mm.
    pub prior_fraction: f64,
    /// Weight of the anthropometric prior (ANSUR II dimensions conditioned on the subject's
    /// sex, height and mass), relative to `prior_fraction`; 0 disables it. Default 1.
    pub anthropometric_weight: f64,
    /// Standard deviation (dimensionless) of a scale factor of a body no survey dimension
    /// measures, about the subject's stature ratio to the generic model. Default 0.1.
    pub scale_prior_sd: f64,
    /// Standard deviation of the difference between two axes' factors of one body (`xyz`
    /// scale groups; the anisotropy penalty). Default 0.05.
    pub anisotropy_sd: f64,
    /// Standard deviation (degrees) of a static trial's joint angles about the anatomical
    /// neutral (or an OpenSim Scale setup's coordinate values) in calibration: the subject is
    /// known to stand upright, so what the markers cannot tell (a thigh's rotation under a
    /// free wand, a pose traded against registered marker offsets) is taken from the posture.
    /// Default 5 (a standing subject's knees, hips and ankles lie within a few degrees of
    /// neutral); 0 disables it.
    pub static_posture_sd_deg: f64,
    /// Standard deviation (degrees) of a static trial's feet about level: a standing subject's
    /// soles rest on the floor, so each foot's coordinates below its shank (ankle, subtalar) are
    /// pulled toward the values that level it in the frame's pose, instead of toward 0 (which
    /// tilts the sole when the shank leans). Registration then places heel and toe markers at
    /// the heights a flat foot gives them (Plug-in Gait's "foot flat" option). Default 2; 0
    /// leaves the feet to the posture prior (a subject who cannot stand flat-footed). Not used
    /// where an OpenSim Scale setup gives the static pose.
    pub static_feet_flat_sd_deg: f64,
    /// A landmark (anatomical marker) that registration moved further than this (mm, at the
    /// subject's scale) makes the calibration `suspect`; half of it is a warning. Default 50:
    /// placement on a bony landmark errs by 10–20 mm, and a generic model's landmark sits up to
    /// 35–45 mm from a subject's (OpenSim's own MarkerPlacer moves gait2354's acromion markers
    /// 34–35 mm and its knee markers up to 45 mm for subject01); beyond that, the marker is not
    /// where the model thinks (a mislabelled or misplaced marker, or a model that does not fit).
    pub registration_suspect_mm: f64,
    /// Functional hip centres (`off`, `report`, `apply`): a sphere fit of the thigh markers in the
    /// pelvis frame over the calibration frames; with `apply`, a fit over at least
    /// `joint_centres::MIN_ROM_DEG` of motion, within `joint_centres::APPLY_MAX_MM` of the model's
    /// centre, moves the hip joint (with registration only: an OpenSim Scale setup scales as
    /// OpenSim does). Default `report` (docs/CALIBRATION.md gives what `apply` changes).
    pub functional_hips: FunctionalHips,
    /// With `functional_hips = "apply"`: both hips move by the symmetric part of their two
    /// functional offsets (mirrored across the pelvis's mid-plane), which an error of the
    /// pelvis's solved orientation does not reach. Default true (docs/CALIBRATION.md).
    pub functional_hips_symmetric: bool,
    /// The static protocol's arm posture (`free`, `neutral`): with `neutral` a static trial's arm
    /// coordinates are held at the model's neutral like the legs and trunk. Default `free`
    /// (protocols differ: arms down, in a T, crossed).
    pub static_arms: StaticArms,
    /// Label quality control of every trial before it is calibrated and solved (swapped labels,
    /// jumps, ghosts: `crate::pipeline::input::label_qc`); `--label-qc` sets its mode.
    pub label_qc: label_qc::LabelQcSettings,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            max_iterations: 20,
            residual_tol_m: 1e-6,
            rel_decrease_tol: 1e-2,
            model_error_tol: 0.01,
            step_tol: 1e-9,
            step_rotation_rad: 0.5,
            step_translation_m: 0.25,
            step_scale: 0.1,
            damping_init: 1e-4,
            damping_min: 1e-9,
            damping_max: 1e8,
            damping_floor: 1e-6,
            rho_eps: 1e-15,
            pose_prior_weight: 1e-6,
            scale_tracking_weight: 1.0,
            min_markers: 3,
            warm_start: WarmStart::default(),
            qp: QpBackend::default(),
            calibration_frames: 12,
            calibration_scale_prior: 1e-6,
            calibration_max_iterations: 50,
            calibration_rel_tol: 1e-5,
            calibration_gain_ratio: false,
            marker_placement: false,
            presolve: Presolve::default(),
            presolve_sweeps: 2,
            calibration_frames_motion: 56,
            calibration_track_step_s: 0.1,
            calibration_track_iterations: 1,
            calibration_coverage_m: 0.0,
            registration: true,
            registration_anatomical_sd_m: 0.004,
            registration_tracking_sd_m: 0.1,
            registration_bound_m: 0.35,
            prior_noise_sd_m: 0.01,
            prior_fraction: 0.1,
            anthropometric_weight: 1.0,
            scale_prior_sd: 0.1,
            anisotropy_sd: 0.05,
            static_posture_sd_deg: 5.0,
            static_feet_flat_sd_deg: 2.0,
            registration_suspect_mm: 50.0,
            functional_hips: FunctionalHips::default(),
            functional_hips_symmetric: true,
            static_arms: StaticArms::default(),
            label_qc: Default::default(),
        }
    }
}

impl SolverSettings {
    /// Defaults overridden by a profile's `[solver]` table.
    pub fn from_table(table: &toml::Table) -> Result<SolverSettings, String> {
        toml::Value::Table(table.clone()).try_into().map_err(|e: toml::de::Error| format!("[solver]: {e}"))
    }

    /// These settings with the fields in `table` (same keys and values as a profile's `[solver]`
    /// table) replaced; an unknown key or a bad value is an error that names the valid keys.
    pub fn with_overrides(&self, table: &toml::Table) -> Result<SolverSettings, String> {
        let mut merged = toml::Table::try_from(self).map_err(|e| e.to_string())?;
        for (k, v) in table {
            if !merged.contains_key(k) {
                let valid: Vec<&str> = merged.keys().map(String::as_str).collect();
                return Err(format!("unknown solver setting `{k}` (valid: {})", valid.join(", ")));
            }
            merged.insert(k.clone(), v.clone());
        }
        toml::Value::Table(merged).try_into().map_err(|e: toml::de::Error| {
            let keys: Vec<&str> = table.keys().map(String::as_str).collect();
            format!("solver settings {}: {}", keys.join(", "), e.to_string().trim())
        })
    }
}
