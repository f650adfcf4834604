//! `datasets.toml`: the archives that `smocap convert` works through.
//!
//! ```toml
//! [[dataset]]
//! name = "lab"                      # required; outputs go to <out>/<name>/...
//! root = "data/lab"                 # required (but for synthetic datasets); relative to this file
//! trials = ["**/*.c3d"]             # required: globs relative to root
//! subject = "{subject}/{trial}.c3d" # optional: how subject and trial are read from the path
//! static = "{subject}/static*.c3d"  # optional: the static trial of each subject (glob)
//! model = "model.osim"              # optional (the shipped model by default), with
//! markerset, profile, scale_setup, ik_setup, place_markers, qp, units, up
//! rate = 120.0                      # optional: frame rate (Hz) overriding the files'
//! settings = { max_iterations = 30 } # optional: solver settings overridden (a profile's [solver] keys)
//! height = 1.84                     # optional: every subject's height (m), mass (kg), sex
//! subjects = { S01 = { height = 1.84, mass = 92.9, sex = "male" } }  # optional: per subject
//! register = false                  # optional: keep the model's marker positions
//! ```

use crate::pipeline::calibration::subject::SubjectFiles;
use crate::pipeline::input::convention::{InputOptions, Units, UpAxis};
use crate::solve::QpBackend;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Errors reading `datasets.toml`.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}: {source}")]
    Toml { file: String, source: toml::de::Error },
    #[error("{file}: dataset '{name}': {message}")]
    Invalid { file: String, name: String, message: String },
    #[error("{file}: no dataset named '{name}' (it has: {valid})")]
    UnknownDataset { file: String, name: String, valid: String },
}

/// A synthetic dataset generated on the fly from the shipped model (see [`crate::kinematics::synth`]).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyntheticSpec {
    pub subjects: usize,
    /// Motion trials per subject (each subject also gets a static trial).
    pub trials: usize,
    /// Frames per trial, at 100 Hz.
    pub frames: usize,
    #[serde(default = "one")]
    pub seed: u64,
}

fn one() -> u64 {
    1
}

/// Most subjects of a synthetic dataset.
pub const MAX_SYNTHETIC_SUBJECTS: usize = 1000;
/// Most frames one synthetic subject may have, static trial included (`(trials + 1) · frames`):
/// a subject's motion is synthesized whole, about 2.5 kB per frame on the shipped model.
pub const MAX_SYNTHETIC_FRAMES_PER_SUBJECT: usize = 200_000;

impl SyntheticSpec {
    /// Checks the counts: at least one subject, trial and frame; at most
    /// [`MAX_SYNTHETIC_SUBJECTS`] subjects and [`MAX_SYNTHETIC_FRAMES_PER_SUBJECT`] frames per
    /// subject.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=MAX_SYNTHETIC_SUBJECTS).contains(&self.subjects) {
            return Err(format!(
                "synthetic `subjects` = {} must be between 1 and {MAX_SYNTHETIC_SUBJECTS}",
                self.subjects
            ));
        }
        if self.trials == 0 || self.frames == 0 {
            return Err("synthetic `trials` and `frames` must be at least 1".into());
        }
        let per_subject = self.trials.checked_add(1).and_then(|t| t.checked_mul(self.frames));
        if per_subject.is_none_or(|n| n > MAX_SYNTHETIC_FRAMES_PER_SUBJECT) {
            return Err(format!(
                "synthetic (trials + 1) × frames = ({} + 1) × {} exceeds {MAX_SYNTHETIC_FRAMES_PER_SUBJECT} frames per subject",
                self.trials, self.frames
            ));
        }
        Ok(())
    }
}

/// Checks a dataset name: one path component (outputs go to `<out>/<name>/`), without
/// separators, not `.`/`..`, not starting with `.` (reserved for smocap's own files), at most
/// 255 bytes.
pub fn validate_name(name: &str) -> Result<(), String> {
    let bad = |why: &str| Err(format!("name '{}' {why}", name.escape_debug()));
    if name.is_empty() {
        return bad("is empty");
    }
    if name.len() > 255 {
        return bad("is longer than 255 bytes");
    }
    if name.contains(['/', '\\', '\0']) {
        return bad("must be one path component (no `/` or `\\`)");
    }
    if name.starts_with('.') {
        return bad("must not start with `.` (and cannot be `.` or `..`)");
    }
    if name.chars().any(char::is_control) {
        return bad("must not contain control characters");
    }
    Ok(())
}

/// One `[[dataset]]` entry; paths as written (see [`Dataset::resolve`]).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dataset {
    pub name: String,
    /// Root folder of the trials (relative to the toml's folder); for a synthetic dataset, where
    /// it is generated (default: `<out>/.synthetic/<name>`).
    pub root: Option<PathBuf>,
    /// Glob patterns of the motion trials, relative to `root`.
    pub trials: Vec<String>,
    /// Path pattern with `{subject}` and `{trial}` placeholders; default: the subject is the
    /// trial's folder.
    pub subject: Option<String>,
    /// Glob of each subject's static trial (`{subject}` is replaced), relative to `root`.
    #[serde(rename = "static")]
    pub static_glob: Option<String>,
    pub model: Option<PathBuf>,
    pub markerset: Option<PathBuf>,
    pub profile: Option<PathBuf>,
    pub scale_setup: Option<PathBuf>,
    pub ik_setup: Option<PathBuf>,
    #[serde(default)]
    pub place_markers: bool,
    pub qp: Option<QpBackend>,
    pub units: Option<Units>,
    pub up: Option<UpAxis>,
    pub synthetic: Option<SyntheticSpec>,
    /// Frame rate (Hz) that overrides the files' rate; frame times become
    /// `t₀ + (frame number − first frame number) / rate` (see [`crate::io::MarkerTrial::set_rate`]).
    pub rate: Option<f64>,
    /// Solver settings overridden for this dataset, applied after the profile, the OpenSim
    /// setups, `place_markers` and `qp` (keys and values as a profile's `[solver]` table; see
    /// [`crate::solve::SolverSettings`]).
    #[serde(default)]
    pub settings: toml::Table,
    /// Every subject's height (m), mass (kg) and sex, for the anthropometric prior.
    pub height: Option<f64>,
    pub mass: Option<f64>,
    pub sex: Option<String>,
    /// Per subject (by the name `subject` extracts): height, mass, sex, overriding the above.
    #[serde(default)]
    pub subjects: std::collections::BTreeMap<String, SubjectKeys>,
    /// Marker registration in calibration (default true).
    pub register: Option<bool>,
}

/// What is known of one subject, as `datasets.toml` writes it.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SubjectKeys {
    pub height: Option<f64>,
    pub mass: Option<f64>,
    pub sex: Option<String>,
}

impl Dataset {
    /// What is known of `subject`: its `subjects` entry over the dataset's keys; a value that
    /// is not plausible (or an unknown sex) is an error naming the subject.
    pub fn subject_info(&self, subject: &str) -> Result<crate::model::anthropometry::SubjectInfo, ConfigError> {
        let own = self.subjects.get(subject).cloned().unwrap_or_default();
        let invalid = |message: String| ConfigError::Invalid {
            file: "datasets.toml".into(),
            name: self.name.clone(),
            message: format!("subject '{subject}': {message}"),
        };
        let sex = own
            .sex
            .as_deref()
            .or(self.sex.as_deref())
            .map(str::parse::<crate::model::anthropometry::Sex>)
            .transpose()
            .map_err(|e| invalid(e.to_string()))?;
        let info = crate::model::anthropometry::SubjectInfo {
            height_m: own.height.or(self.height),
            mass_kg: own.mass.or(self.mass),
            sex,
        };
        info.validate().map_err(|e| invalid(e.to_string()))?;
        Ok(info)
    }

    /// Resolves relative paths against `base` (the toml's folder).
    fn resolve(&mut self, base: &Path) {
        let abs = |p: &mut Option<PathBuf>| {
            if let Some(x) = p.as_mut().filter(|x| x.is_relative()) {
                *x = base.join(&*x);
            }
        };
        for p in [&mut self.root, &mut self.model, &mut self.markerset, &mut self.profile] {
            abs(p);
        }
        abs(&mut self.scale_setup);
        abs(&mut self.ik_setup);
    }

    /// The subject's files; `static_trial` is the subject's static trial when one was found.
    pub fn subject_files(&self, static_trial: Option<PathBuf>) -> SubjectFiles {
        SubjectFiles {
            model: self.model.clone(),
            markerset: self.markerset.clone(),
            profile: self.profile.clone(),
            scale_setup: self.scale_setup.clone(),
            ik_setup: self.ik_setup.clone(),
            static_trial,
            place_markers: self.place_markers,
            no_register: self.register == Some(false),
            subject: Default::default(),
            qp: self.qp,
        }
    }

    pub fn input_options(&self) -> InputOptions {
        InputOptions { up: self.up, units: self.units }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    dataset: Vec<Dataset>,
}

/// Reads `path`, resolving relative paths against its folder; `only` keeps one dataset by name.
pub fn read_datasets(path: &Path, only: Option<&str>) -> Result<Vec<Dataset>, ConfigError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io { file: file.clone(), source })?;
    let parsed: File = toml::from_str(&text).map_err(|source| ConfigError::Toml { file: file.clone(), source })?;
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for mut d in parsed.dataset {
        let invalid =
            |message: &str| ConfigError::Invalid { file: file.clone(), name: d.name.clone(), message: message.into() };
        if let Err(why) = validate_name(&d.name) {
            return Err(invalid(&why));
        }
        if let Some(Err(why)) = d.synthetic.as_ref().map(SyntheticSpec::validate) {
            return Err(invalid(&why));
        }
        if d.trials.is_empty() {
            return Err(invalid("`trials` needs at least one glob"));
        }
        if d.root.is_none() && d.synthetic.is_none() {
            return Err(invalid("`root` is required (but for synthetic datasets)"));
        }
        if d.rate.is_some_and(|r| !(r.is_finite() && r > 0.0)) {
            return Err(invalid("`rate` must be a positive number of frames per second"));
        }
        if let Err(e) = crate::solve::SolverSettings::default().with_overrides(&d.settings) {
            return Err(invalid(&format!("[settings]: {e}")));
        }
        if out.iter().any(|o: &Dataset| o.name == d.name) {
            return Err(invalid("two datasets have this name"));
        }
        d.resolve(base);
        out.push(d);
    }
    match only {
        None => Ok(out),
        Some(name) => match out.iter().position(|d| d.name == name) {
            Some(i) => Ok(vec![out.swap_remove(i)]),
            None => Err(ConfigError::UnknownDataset {
                file,
                name: name.into(),
                valid: out.iter().map(|d| d.name.as_str()).collect::<Vec<_>>().join(", "),
            }),
        },
    }
}
