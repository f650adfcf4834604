//! What a conversion reports: each trial's and dataset's fate, each subject's calibration cost,
//! the run's summary table and where the time went.

use crate::pipeline::stats::P50P90;
use serde::{Deserialize, Serialize};

/// One trial's fate.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrialOutcome {
    pub dataset: String,
    pub subject: String,
    /// Path relative to the dataset root.
    pub trial: String,
    pub output: String,
    /// "ok", "skipped" (already converted, `--resume`), "suspect" (converted, but see `error`:
    /// [`crate::pipeline::results::verdict`]) or "failed".
    pub status: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    pub frames: usize,
    pub solve_s: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ms_per_frame: Option<P50P90>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations: Option<P50P90>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rmse_mm: Option<P50P90>,
    /// The evaluation backend that solved it: `cpu`, or `wgpu: <adapter description>`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backend: Option<String>,
    /// Label quality control events: swaps, jumps, ghosts and what was done
    /// ([`crate::pipeline::input::label_qc`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub label_qc: Vec<crate::pipeline::input::label_qc::LabelEvent>,
    /// Runs of frames no pose fits, their markers and whether the data or the model is to blame
    /// ([`crate::pipeline::running::unfittable`]; the file's `/smocap/unfittable`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unfittable: Vec<crate::pipeline::running::unfittable::Unfittable>,
    /// What the verdict says beyond the status: "the data is bad here: …" for unfittable runs
    /// blamed on the data (the trial is not `failed` for them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// What the post-trial hook (`--robot`: the robot's files and MCAP channels) did with the
    /// converted trial; absent without one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<HookOutcome>,
    /// The body mesh measured on the converted trial (`--body`); absent without it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body: Option<BodyOutcome>,
}

/// The body mesh on a converted trial (`convert --body`: the subject's body shaped, posed at
/// every frame and measured; the whole report in `<trial>.body.json` beside the file).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct BodyOutcome {
    /// `ok`, `suspect` (a figure past its bound: see `note`), `failed` (no body: see `note`) or
    /// `skipped` (measured by an earlier run, `--resume`: its report read back).
    pub status: String,
    /// One line: how the body was shaped, or which figures are past their bounds, or why none.
    pub note: String,
    /// Body height at the bind pose minus the subject's stature (mm).
    pub height_minus_stature_mm: Option<f64>,
    /// Landmark markers' |distance to the skin − marker radius| over all frames: median and
    /// 90th percentile (mm).
    pub landmark_median_off_skin_mm: Option<f64>,
    pub landmark_p90_off_skin_mm: Option<f64>,
    /// Mean distance of the virtual markers (fixed on the skin) from the model's (mm).
    pub virtual_marker_error_mm: Option<f64>,
}

impl BodyOutcome {
    pub fn failed(why: String) -> BodyOutcome {
        BodyOutcome {
            status: "failed".into(),
            note: why,
            height_minus_stature_mm: None,
            landmark_median_off_skin_mm: None,
            landmark_p90_off_skin_mm: None,
            virtual_marker_error_mm: None,
        }
    }
}

pub use crate::archive::hook::HookOutcome;

/// A dataset's fate (skipped ones say why: its root is absent; failed ones too: a bad glob, a
/// synthetic dataset that could not be generated, an unreadable folder).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DatasetNote {
    pub name: String,
    pub root: String,
    pub skipped: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
}

/// The run: every trial found (in this shard), with its status.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ConvertSummary {
    pub smocap_version: String,
    /// `I/N` when sharded.
    pub shard: Option<String>,
    pub datasets: Vec<DatasetNote>,
    pub trials: Vec<TrialOutcome>,
    /// Each calibrated subject's calibration cost, in dataset and subject order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub calibrations: Vec<SubjectCalibration>,
    /// Wall time of the conversion (s: from the trials found, synthetic datasets generated, to
    /// the last trial written).
    #[serde(default)]
    pub wall_seconds: f64,
    /// Workers of the conversion (`--jobs`).
    #[serde(default)]
    pub threads: usize,
}

/// What calibrating one subject cost.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SubjectCalibration {
    pub dataset: String,
    pub subject: String,
    /// Wall time (s).
    pub seconds: f64,
    pub stages: Vec<crate::solve::calibration::StageCost>,
}

impl ConvertSummary {
    /// Trials that failed or are suspect.
    pub fn failed(&self) -> usize {
        self.trials.iter().filter(|t| t.status == "failed" || t.status == "suspect").count()
    }

    /// Datasets that failed as a whole (no trial of theirs could be looked at).
    pub fn failed_datasets(&self) -> usize {
        self.datasets.iter().filter(|d| d.failed.is_some()).count()
    }

    /// Trials converted or already done (`ok` or `skipped`).
    pub fn succeeded(&self) -> usize {
        self.trials.iter().filter(|t| t.status == "ok" || t.status == "skipped").count()
    }

    /// One line per dataset: trials ok/skipped/failed, frames, frames/s, p50/p90 figures.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:<24} {:>5} {:>7} {:>6} {:>8} {:>9} {:>14} {:>12} {:>14}\n",
            "dataset",
            "ok",
            "skipped",
            "failed",
            "frames",
            "frames/s",
            "ms/frame p50/90",
            "iter p50/90",
            "RMSE mm p50/90"
        );
        for d in &self.datasets {
            let ts: Vec<&TrialOutcome> = self.trials.iter().filter(|t| t.dataset == d.name).collect();
            if let Some(why) = &d.failed {
                s += &format!("{:<24} failed: {why}\n", d.name);
                continue;
            }
            if let Some(why) = &d.skipped {
                s += &format!("{:<24} skipped: {why}\n", d.name);
                continue;
            }
            let count =
                |st: &str| ts.iter().filter(|t| t.status == st || st == "failed" && t.status == "suspect").count();
            let solved: Vec<&&TrialOutcome> = ts.iter().filter(|t| t.status == "ok").collect();
            let frames: usize = solved.iter().map(|t| t.frames).sum();
            let secs: f64 = solved.iter().map(|t| t.solve_s).sum();
            let med = |f: fn(&TrialOutcome) -> Option<P50P90>| {
                let v: Vec<P50P90> = solved.iter().filter_map(|t| f(t)).collect();
                if v.is_empty() {
                    return "-".to_string();
                }
                let p50: Vec<f64> = v.iter().map(|x| x.p50).collect();
                let p90: Vec<f64> = v.iter().map(|x| x.p90).collect();
                let m = |x: &[f64]| crate::pipeline::stats::percentile(x, 0.5);
                format!("{:.2}/{:.2}", m(&p50), m(&p90))
            };
            s += &format!(
                "{:<24} {:>5} {:>7} {:>6} {:>8} {:>9.0} {:>14} {:>12} {:>14}\n",
                d.name,
                count("ok"),
                count("skipped"),
                count("failed"),
                frames,
                if secs > 0.0 { frames as f64 / secs } else { 0.0 },
                med(|t| t.ms_per_frame),
                med(|t| t.iterations),
                med(|t| t.rmse_mm),
            );
        }
        s + &self.unfittable_line() + &self.hook_line() + &self.body_line() + &self.throughput()
    }

    /// Trials whose post-trial hook (`--robot`) failed (their robot outputs are absent).
    pub fn hook_failed(&self) -> usize {
        self.trials.iter().filter(|t| t.robot.as_ref().is_some_and(|r| r.status == "failed")).count()
    }

    /// The post-trial hook's outcomes counted by status, when there was a hook.
    pub fn hook_line(&self) -> String {
        let all: Vec<&HookOutcome> = self.trials.iter().filter_map(|t| t.robot.as_ref()).collect();
        if all.is_empty() {
            return String::new();
        }
        let n = |st: &str| all.iter().filter(|r| r.status == st).count();
        format!(
            "robot: {} ok, {} suspect, {} failed, {} skipped (the trials' `robot` in the report)\n",
            n("ok"),
            n("suspect"),
            n("failed"),
            n("skipped")
        )
    }

    /// The bodies' outcomes counted by status and their figures' medians over the trials, when
    /// bodies were measured.
    pub fn body_line(&self) -> String {
        let all: Vec<&BodyOutcome> = self.trials.iter().filter_map(|t| t.body.as_ref()).collect();
        if all.is_empty() {
            return String::new();
        }
        let n = |st: &str| all.iter().filter(|b| b.status == st).count();
        let median = |f: &dyn Fn(&BodyOutcome) -> Option<f64>| {
            let mut v: Vec<f64> = all.iter().filter_map(|b| f(b)).collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).map_or("-".into(), |x| format!("{x:.1}"))
        };
        format!(
            "body: {} ok, {} suspect, {} failed, {} skipped; median over the trials: height − stature {} mm, landmarks off the skin {} mm (p90 {} mm), virtual markers {} mm (the trials' `body` in the report, `<trial>.body.json`)\n",
            n("ok"),
            n("suspect"),
            n("failed"),
            n("skipped"),
            median(&|b| b.height_minus_stature_mm),
            median(&|b| b.landmark_median_off_skin_mm),
            median(&|b| b.landmark_p90_off_skin_mm),
            median(&|b| b.virtual_marker_error_mm),
        )
    }

    /// The runs of unfittable frames over the trials, when there are any: how many, in how many
    /// trials, how many blamed on the data ("the data is bad here").
    pub fn unfittable_line(&self) -> String {
        let runs: Vec<_> = self.trials.iter().flat_map(|t| &t.unfittable).collect();
        if runs.is_empty() {
            return String::new();
        }
        let trials = self.trials.iter().filter(|t| !t.unfittable.is_empty()).count();
        let data = runs.iter().filter(|u| u.cause == "data").count();
        format!(
            "unfittable frames: {} runs in {trials} trials ({data} blamed on the data, {} on the model): the trials' `unfittable` in the report\n",
            runs.len(),
            runs.len() - data
        )
    }

    /// Where the time went: calibration per subject (by stage), end-to-end frames/s against the
    /// solver's capacity (frames/s per worker, summed over solved trials, times the workers).
    pub fn throughput(&self) -> String {
        let mut s = String::new();
        if !self.calibrations.is_empty() {
            let n = self.calibrations.len();
            let total: f64 = self.calibrations.iter().map(|c| c.seconds).sum();
            let mut names: Vec<&str> = Vec::new();
            for c in &self.calibrations {
                for st in &c.stages {
                    if !names.contains(&st.stage.as_str()) {
                        names.push(&st.stage);
                    }
                }
            }
            let per: Vec<String> = names
                .iter()
                .map(|name| {
                    let stages = self.calibrations.iter().flat_map(|c| &c.stages);
                    let t: f64 = stages.filter(|st| st.stage == *name).map(|st| st.seconds).sum();
                    format!("{name} {:.1}", t / n as f64 * 1e3)
                })
                .collect();
            let max = self.calibrations.iter().map(|c| c.seconds).fold(0.0, f64::max);
            s += &format!(
                "calibration: {n} subjects, {:.1} ms per subject (max {:.1}; {:.2} s in all), by stage (ms per subject): {}\n",
                total / n as f64 * 1e3,
                max * 1e3,
                total,
                per.join(", ")
            );
        }
        let solved: Vec<&TrialOutcome> =
            self.trials.iter().filter(|t| t.status == "ok" || t.status == "suspect").collect();
        let frames: usize = solved.iter().map(|t| t.frames).sum();
        let secs: f64 = solved.iter().map(|t| t.solve_s).sum();
        if frames > 0 && secs > 0.0 && self.wall_seconds > 0.0 {
            let end_to_end = frames as f64 / self.wall_seconds;
            let capacity = frames as f64 / secs * self.threads.max(1) as f64;
            s += &format!(
                "throughput: {frames} frames in {:.2} s wall: {end_to_end:.0} frames/s end to end; solver {:.0} frames/s per worker × {} = {capacity:.0}; ratio {:.2}\n",
                self.wall_seconds,
                frames as f64 / secs,
                self.threads.max(1),
                end_to_end / capacity
            );
        }
        s
    }
}
