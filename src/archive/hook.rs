//! Work done on each converted trial beside its solve (`smocap convert --robot`: retargeting,
//! which `cli` fills in; this layer knows nothing of robots, only the poses it returns).
//!
//! While a trial is converted, [`TrialHook::on_motion`] gets its solved motion before the file is
//! finished: what it returns goes into the file ([`super::mcap_robot::write_track`]) and, once the
//! file is complete under its final name, [`TrialHook::write`] writes the hook's own files.
//! Resuming, a trial already converted whose hook outputs are not [`TrialHook::done`] gets
//! [`TrialHook::run`] on its complete file instead. Either way the hook's outputs are complete or
//! absent when it returns.

use super::mcap_robot::RobotTrack;
use crate::model::Model;
use nalgebra::UnitQuaternion;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A hook's outcome for a converted trial.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct HookOutcome {
    /// `ok`, `suspect` (written, but see `note`), `failed` (nothing written: see `note`) or
    /// `skipped` (done by an earlier run, `--resume`).
    pub status: String,
    /// One line: what was written, or why not.
    pub note: String,
}

impl HookOutcome {
    pub fn failed(why: String) -> HookOutcome {
        HookOutcome { status: "failed".into(), note: why }
    }
}

/// A trial's solved motion as its file records it: coordinates per frame on the subject's
/// calibrated scales.
pub struct SolvedMotion<'a> {
    /// The trial's name (its file's stem).
    pub name: &'a str,
    pub model: &'a Model,
    /// The calibrated scale factors, `3·body + axis`.
    pub scales: &'a [f64],
    /// Coordinates per frame, in model order (rad or m): `/smocap/state`'s `q`.
    pub q: &'a [Vec<f64>],
    /// Frame times since the trial's first sample (s) and frame indices.
    pub times: &'a [f64],
    pub frames: &'a [usize],
    /// The rotation from `model` to the Z-up `world`.
    pub world_from_model: UnitQuaternion<f64>,
}

/// What [`TrialHook::on_motion`] made of a trial: the poses to add to its file, and what
/// [`TrialHook::write`] needs to write the hook's files.
pub struct HookWork {
    pub track: RobotTrack,
    pub payload: Box<dyn std::any::Any + Send>,
}

/// See the module docs.
pub trait TrialHook: Send + Sync {
    /// Whether the hook's outputs for the trial file `mcap` are complete.
    fn done(&self, mcap: &Path) -> bool;
    /// Runs on the complete trial file `mcap` (resuming): what it gave, or why it failed.
    fn run(&self, mcap: &Path) -> Result<HookOutcome, String>;
    /// Runs on a trial's solved motion while its file is open; `Err`: why it failed (the file
    /// is then finished without the hook's poses).
    fn on_motion(&self, motion: &SolvedMotion<'_>) -> Result<HookWork, String>;
    /// Writes the hook's files for `work` beside the now complete trial file `mcap`.
    fn write(&self, mcap: &Path, work: HookWork) -> HookOutcome;
}

impl std::fmt::Debug for dyn TrialHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TrialHook")
    }
}
