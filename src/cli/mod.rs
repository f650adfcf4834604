//! The `smocap` command line.
//!
//! Exit codes, the same for `solve`, `convert` and `merge-reports` ([`exit_code`]): 0 every
//! trial ok (or, for `convert --resume`, already done); 3 some trials failed or are suspect (see
//! the report) while others succeeded; 1 nothing could run: an error stopped the command (bad
//! input, I/O, a dataset that could not be looked at), every trial failed, or no trial was found
//! (unless `--allow-empty`); 2 usage error.

mod audit;
mod bench;
mod bench_table;
mod compare;
mod convert;
mod demo;
mod eval_presolve;
mod eval_spine;
mod export;
mod inspect;
mod markers;
mod merge;
mod preview;
mod project;
mod render;
mod retarget;
pub mod robot;
pub mod skin_report;
mod solve;
mod synth;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Exit code when some trials failed but the run completed.
pub const EXIT_SOME_FAILED: u8 = 3;
/// Exit code when nothing could run (an error, no trial succeeded, or no trial at all).
pub const EXIT_NOTHING_RAN: u8 = 1;

/// The exit code of a run that found `succeeded + failed` trials (`failed` counts suspect ones
/// and datasets that failed as a whole): 0 all succeeded, 3 some failed, 1 none succeeded; no
/// trial at all is 1 unless `allow_empty`.
pub fn exit_code(succeeded: usize, failed: usize, allow_empty: bool) -> u8 {
    match (succeeded, failed) {
        (0, 0) if allow_empty => 0,
        (0, _) => EXIT_NOTHING_RAN,
        (_, 0) => 0,
        _ => EXIT_SOME_FAILED,
    }
}

#[derive(Parser, Debug)]
#[command(name = "smocap", version, about = "Joint scale–pose canonicalization of marker-based motion capture")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Synthesize a trial from the shipped model, calibrate, solve and print a summary.
    Demo(demo::DemoArgs),
    /// Write a synthetic trial (TRC) and its truth (JSON) from a model.
    Synth(synth::SynthArgs),
    /// Calibrate a subject and solve its trials jointly for scale and pose.
    Solve(Box<solve::SolveArgs>),
    /// What a marker file holds: frames, rate, units, labels, gaps per label, time span.
    Markers(markers::MarkersArgs),
    /// Batched evaluation throughput (frame-evaluations/s) of the shipped model per batch size.
    BenchBatch(bench::BenchArgs),
    /// Throughput and convergence per dataset (datasets.toml) beside the published and OpenSim figures.
    Bench(bench_table::BenchTableArgs),
    /// Leakage audit: the joint solve against a stage-wise scale-then-IK baseline.
    Audit(audit::AuditArgs),
    /// Convert whole archives (datasets.toml) to one MCAP file per trial, each subject calibrated once.
    Convert(convert::ConvertArgs),
    /// What a converted MCAP file holds: channels, message counts, run metadata, attachments.
    Inspect(inspect::InspectArgs),
    /// Join the summaries (`--report-json`) of sharded convert runs into one; exit 3 if any trial failed.
    MergeReports(merge::MergeArgs),
    /// A converted MCAP file's state channel as an OpenSim motion (`--mot`), a CSV table (`--csv`) and/or a glTF scene (`--gltf`).
    Export(export::ExportArgs),
    /// 2D/3D ground truth of converted trials from a camera rig: COCO keypoint JSON, CSV, camera matrices, marker metrics.
    Project(project::ProjectArgs),
    /// The solved people drawn through a camera rig: RGB, segment masks, depth and COCO keypoints with visibility, per camera and frame.
    Render(Box<render::RenderArgs>),
    /// Converted trials onto a humanoid robot (Unitree G1 shipped): GMR pickle, mjlab CSV, NPZ and a quality report per trial.
    Retarget(retarget::RetargetArgs),
    /// A contact sheet (PNG) of a converted trial's projected skeleton and markers, one panel per camera.
    Preview(preview::PreviewArgs),
    /// Joint angles of a solved trial (`.mot`, `.mcap`) against a reference motion (OpenSim/AddBiomechanics `.mot`, Plug-in Gait angles in a C3D): RMSE, offset, waveform, correlation per coordinate.
    Compare(compare::CompareArgs),
    /// Spine ablation on the shipped model: poly vs nopoly vs classical on a synthetic yoga-like trial.
    EvalSpine(eval_spine::EvalSpineArgs),
    /// Pre-solve on the hard synthetic set: outlier rate and overhead with never/auto/always.
    EvalPresolve(eval_presolve::EvalPresolveArgs),
}

/// Runs the command line; errors are printed with their causes.
pub fn main() -> ExitCode {
    restore_sigpipe();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Synth(a) => synth::run(a),
        Command::Solve(a) => solve::run(*a),
        Command::Markers(a) => markers::run(a),
        Command::Compare(a) => compare::run(a),
        Command::BenchBatch(a) => bench::run(a),
        Command::Bench(a) => bench_table::run(a),
        Command::Audit(a) => audit::run(a),
        Command::Convert(a) => convert::run(a),
        Command::Inspect(a) => inspect::run(a),
        Command::MergeReports(a) => merge::run(a),
        Command::Export(a) => export::run(a),
        Command::Project(a) => project::run(a),
        Command::Render(a) => render::run(*a),
        Command::Retarget(a) => retarget::run(a),
        Command::Preview(a) => preview::run(a),
        Command::EvalSpine(a) => eval_spine::run_cli(a),
        Command::EvalPresolve(a) => eval_presolve::run(a),
    };
    match result {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            let top = e.to_string();
            eprintln!("error: {top}");
            for cause in new_causes(&e) {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::from(1)
        }
    }
}

/// The causes of `e` that its message (and the causes before them) do not already quote.
fn new_causes(e: &anyhow::Error) -> Vec<String> {
    let mut said = e.to_string();
    let mut out = Vec::new();
    for cause in e.chain().skip(1).map(|c| c.to_string()) {
        if !said.contains(cause.as_str()) {
            said += &cause;
            out.push(cause);
        }
    }
    out
}

/// `e` on one line: its message, then each cause it does not already quote (`a: b`), so that
/// an I/O error is not said twice.
pub(crate) fn one_line(e: &anyhow::Error) -> String {
    std::iter::once(e.to_string()).chain(new_causes(e)).collect::<Vec<_>>().join(": ")
}

/// Loads the context named by `--model`/`--profile` (the shipped model by default).
pub(crate) fn load_context(
    model: Option<&std::path::Path>,
    profile: Option<&std::path::Path>,
) -> anyhow::Result<crate::pipeline::Context> {
    load_context_with_markers(model, None, profile)
}

/// As [`load_context`], attaching an OpenSim marker set file to the model when given.
pub(crate) fn load_context_with_markers(
    model: Option<&std::path::Path>,
    marker_set: Option<&std::path::Path>,
    profile: Option<&std::path::Path>,
) -> anyhow::Result<crate::pipeline::Context> {
    let ctx = crate::pipeline::calibration::subject::load_context(model, marker_set, profile)?;
    if model.is_some() {
        for w in &ctx.warnings {
            eprintln!("warning: {w}");
        }
    }
    Ok(ctx)
}

/// Evaluation backend options shared by `solve` and `demo`.
#[derive(clap::Args, Debug, Clone)]
pub struct BackendArgs {
    /// Evaluation backend: `auto` uses wgpu only on a real (discrete or integrated) GPU;
    /// `wgpu-f64` runs the shaders in f64 (adapters offering SHADER_F64).
    #[arg(long, value_enum, default_value_t = crate::pipeline::running::device::BackendChoice::Auto)]
    pub backend: crate::pipeline::running::device::BackendChoice,
    /// Lanes of the scheduler (segments in flight); default: the thread count on the CPU
    /// backend, 4096 on wgpu. A trial of n frames is cut into max(1, n / 200) segments (each
    /// walked from 10 frames before its start), whatever the lane and thread counts: they change
    /// the speed, not the result.
    #[arg(long)]
    pub lanes: Option<usize>,
}

impl BackendArgs {
    /// The chosen backend (printing why `auto` fell back) and the lane count.
    pub fn choose(
        &self,
        ctx: &crate::pipeline::Context,
        threads: usize,
    ) -> anyhow::Result<(crate::pipeline::running::device::Chosen, usize)> {
        use crate::pipeline::running::device::choose;
        let chosen = choose(self.backend, &ctx.evaluator(), crate::kinematics::gpu::DEFAULT_CAP)?;
        if let Some(note) = chosen.note() {
            eprintln!("note: {note}");
        }
        if let Some(l) = self.lanes {
            anyhow::ensure!((1..=1 << 20).contains(&l), "--lanes {l}: expected 1 to {}", 1 << 20);
        }
        let lanes = self.lanes.unwrap_or_else(|| chosen.default_lanes(threads));
        Ok((chosen, lanes.max(1)))
    }
}

/// Default thread count: the machine's available parallelism.
pub(crate) fn default_threads() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}

/// Output piped into a reader that stops early (`smocap markers F | head`) ends the process
/// quietly, as other command-line tools do, instead of `println!` panicking on a broken pipe
/// (Rust ignores SIGPIPE by default).
///
/// A file-size limit (`ulimit -f`) makes a write fail (EFBIG) instead of killing the process with
/// SIGXFSZ, so that a writer cleans up its temporary file and the trial is reported failed.
fn restore_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called first thing in main, before any thread exists; SIG_DFL and SIG_IGN are valid
    // handlers.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}
