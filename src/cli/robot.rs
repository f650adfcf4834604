//! A robot set up once per run and applied to converted trials: the retargeting itself
//! ([`crate::retarget`]), its files (`<stem>.pkl`, `.csv`, `.npz`, `.json`) and its channels in
//! the trial's MCAP file ([`crate::archive::mcap_robot`]). Shared by `smocap retarget`,
//! `smocap convert --robot` (as its post-trial hook, [`ConvertHook`]) and the Python package's
//! `Trial.retarget`.

use crate::archive::hook::{HookOutcome, HookWork, SolvedMotion, TrialHook};
use crate::archive::mcap_out::WriterOptions;
use crate::archive::mcap_robot;
use crate::render::Take;
use crate::retarget::{self, files, Human, Mapping, Plan, Report, RetargetError, RetargetSettings, Retargeted, Robot};
use anyhow::Context as _;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// The extensions of a retargeted trial's files, in the order they are written (the report last).
pub const EXTENSIONS: [&str; 4] = ["pkl", "csv", "npz", "json"];

/// A robot, its mapping and settings, read once.
pub struct RobotSetup {
    /// The robot's name: the shipped name (`g1`) or the mapping file's stem; its MCAP frames are
    /// `<name>/<body>` and its files beside a converted trial `<trial>.<name>.<ext>`.
    pub name: String,
    pub mapping: Mapping,
    pub robot: Robot,
    pub settings: RetargetSettings,
    /// The robot's world origin in the trial's `world` (m, Z up): 0 puts the robot where the
    /// human is; `[0, 1, 0]` beside a human walking along +x.
    pub offset: Vector3<f64>,
    /// Also write `<stem>.targets.npz` (what the robot was asked to do).
    pub write_targets: bool,
}

impl RobotSetup {
    /// `robot`: a shipped robot's name or a mapping file (`mjcf` naming its MJCF when the file
    /// does not); `settings`: a TOML file of [`RetargetSettings`] (default: built in).
    pub fn load(robot: &str, mjcf: Option<&Path>, settings: Option<&Path>) -> anyhow::Result<RobotSetup> {
        let (mapping, r) = retarget::load(robot, mjcf)?;
        let settings: RetargetSettings = match settings {
            Some(p) => {
                let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
                toml::from_str(&text).with_context(|| format!("parsing {}", p.display()))?
            }
            None => RetargetSettings::default(),
        };
        let name = match retarget::shipped_names().contains(&robot) {
            true => robot.to_string(),
            false => Path::new(robot).file_stem().map_or("robot".into(), |s| s.to_string_lossy().into_owned()),
        };
        let name: String =
            name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_".contains(c) { c } else { '_' }).collect();
        Ok(RobotSetup { name, mapping, robot: r, settings, offset: Vector3::zeros(), write_targets: false })
    }

    /// Retargets a converted trial.
    pub fn retarget(&self, take: &Take) -> Result<Retargeted, RetargetError> {
        let human = Human {
            model: &take.model,
            scales: &take.scales,
            q: &take.q,
            times: &take.times,
            world_from_model: take.world_from_model,
        };
        self.retarget_human(&human, &take.name)
    }

    /// Retargets the motion `human` of trial `name`.
    pub fn retarget_human(&self, human: &Human<'_>, name: &str) -> Result<Retargeted, RetargetError> {
        let plan = Plan::new(&self.robot, &self.mapping, human)?;
        Ok(retarget::retarget(human, &self.robot, &plan, &self.settings, name))
    }

    /// Writes `<stem>.pkl`, `.csv`, `.npz` and the report `<stem>.json` (each atomically, the
    /// report last).
    pub fn write_files(&self, stem: &Path, done: &Retargeted) -> anyhow::Result<()> {
        let m = &done.motion;
        files::write_gmr_pickle(&beside(stem, "pkl"), m)?;
        files::write_mjlab_csv(&beside(stem, "csv"), m)?;
        files::write_npz(&beside(stem, "npz"), m)?;
        if self.write_targets {
            files::write_targets_npz(&beside(stem, "targets.npz"), &done.targets)?;
        }
        let json = serde_json::to_string_pretty(&done.report)? + "\n";
        crate::render::png_out::write_atomic(&beside(stem, "json"), json.as_bytes())?;
        Ok(())
    }

    /// Adds `done` (retargeted from `take`) to the trial's MCAP file `mcap` as `/robot/tf` and
    /// `/robot/scene`, replacing any robot there.
    pub fn add_to_mcap(&self, mcap: &Path, take: &Take, done: &Retargeted, w: &WriterOptions) -> anyhow::Result<()> {
        let buf = crate::archive::inspect::read_checked(mcap)?;
        self.add_to_bytes(&buf, mcap, take, done, w)
    }

    /// [`Self::add_to_mcap`] with the file's bytes `buf` already read and checked.
    fn add_to_bytes(
        &self,
        buf: &[u8],
        mcap: &Path,
        take: &Take,
        done: &Retargeted,
        w: &WriterOptions,
    ) -> anyhow::Result<()> {
        let track = retarget::track::track(
            &self.robot,
            &self.name,
            (done.poses.clone(), &done.report),
            &take.frames,
            self.offset,
        );
        mcap_robot::add_robot_to(buf, mcap, &track, w)?;
        Ok(())
    }

    /// Retargets the converted trial `mcap`; writes its files at `stem` when given and adds the
    /// robot to `mcap` when `into_mcap`. Returns the report and the retargeting time (s).
    pub fn trial(
        &self,
        mcap: &Path,
        stem: Option<&Path>,
        into_mcap: Option<&WriterOptions>,
    ) -> anyhow::Result<(Report, f64)> {
        // Read once, for the trial and for the rewrite.
        let buf = crate::archive::inspect::read_checked(mcap)?;
        let rec = crate::archive::export::parse_trial_record(&buf, &mcap.display().to_string())?;
        let take = Take::from_record(&rec, mcap)?;
        let start = std::time::Instant::now();
        let done = self.retarget(&take)?;
        let seconds = start.elapsed().as_secs_f64();
        if let Some(stem) = stem {
            self.write_files(stem, &done)?;
        }
        if let Some(w) = into_mcap {
            self.add_to_bytes(&buf, mcap, &take, &done, w)?;
        }
        Ok((done.report, seconds))
    }
}

/// `<stem>.<ext>` (the stem's own dots kept).
pub fn beside(stem: &Path, ext: &str) -> PathBuf {
    let mut s = stem.as_os_str().to_owned();
    s.push(".");
    s.push(ext);
    PathBuf::from(s)
}

/// `--robot-offset`: `X,Y` or `X,Y,Z` (m, world, Z up).
pub fn parse_offset(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> =
        s.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
    match v[..] {
        [x, y] if x.is_finite() && y.is_finite() => Ok([x, y, 0.0]),
        [x, y, z] if v.iter().all(|a| a.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("'{s}': expected X,Y or X,Y,Z in metres")),
    }
}

/// `smocap convert --robot`: each converted trial's robot files beside its MCAP file
/// (`<trial>.<robot>.<ext>`) and the robot's channels in it: retargeted from the solved motion
/// while the trial's file is written ([`TrialHook::on_motion`]), or from the file (resuming).
pub struct ConvertHook {
    pub setup: RobotSetup,
    pub writer: WriterOptions,
}

impl ConvertHook {
    /// `<trial>.<robot>` beside the trial's `<trial>.mcap`.
    fn stem(&self, mcap: &Path) -> PathBuf {
        beside(&mcap.with_extension(""), &self.setup.name)
    }
}

impl TrialHook for ConvertHook {
    fn done(&self, mcap: &Path) -> bool {
        let stem = self.stem(mcap);
        EXTENSIONS.iter().all(|e| beside(&stem, e).is_file())
            && mcap_robot::recorded_robot(mcap).as_deref() == Some(self.setup.name.as_str())
    }

    fn run(&self, mcap: &Path) -> Result<HookOutcome, String> {
        let stem = self.stem(mcap);
        match self.setup.trial(mcap, Some(&stem), Some(&self.writer)) {
            Ok((r, seconds)) => Ok(self.outcome(&r, seconds)),
            Err(e) => {
                self.remove_files(mcap);
                Err(format!("{}: {e:#}", self.setup.name))
            }
        }
    }

    fn on_motion(&self, m: &SolvedMotion<'_>) -> Result<HookWork, String> {
        let human =
            Human { model: m.model, scales: m.scales, q: m.q, times: m.times, world_from_model: m.world_from_model };
        let start = std::time::Instant::now();
        let mut done = self.setup.retarget_human(&human, m.name).map_err(|e| format!("{}: {e}", self.setup.name))?;
        let seconds = start.elapsed().as_secs_f64();
        // The poses go into the file's track; the files that follow need the rest.
        let poses = std::mem::take(&mut done.poses);
        let track = retarget::track::track(
            &self.setup.robot,
            &self.setup.name,
            (poses, &done.report),
            m.frames,
            self.setup.offset,
        );
        Ok(HookWork { track, payload: Box::new((done, seconds)) })
    }

    fn write(&self, mcap: &Path, work: HookWork) -> HookOutcome {
        let Ok(b) = work.payload.downcast::<(Retargeted, f64)>() else {
            return HookOutcome::failed(format!("{}: not a retargeted motion", self.setup.name));
        };
        let (done, seconds) = *b;
        match self.setup.write_files(&self.stem(mcap), &done) {
            Ok(()) => self.outcome(&done.report, seconds),
            Err(e) => {
                self.remove_files(mcap);
                HookOutcome::failed(format!("{}: {e:#}", self.setup.name))
            }
        }
    }
}

impl ConvertHook {
    /// The outcome of a trial retargeted in `seconds` with report `r`.
    fn outcome(&self, r: &Report, seconds: f64) -> HookOutcome {
        let mut note = format!(
            "{}: {} frames in {seconds:.2} s, end effectors {:.1} mm median",
            self.setup.name, r.frames, r.end_effector_median_mm
        );
        if !r.reasons.is_empty() {
            note += &format!(": {}", r.reasons.join("; "));
        }
        HookOutcome { status: r.status.clone(), note }
    }

    /// Complete or absent: what this run wrote of the trial's robot files goes.
    fn remove_files(&self, mcap: &Path) {
        let stem = self.stem(mcap);
        for ext in EXTENSIONS {
            let _ = std::fs::remove_file(beside(&stem, ext));
        }
    }
}
