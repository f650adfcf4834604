//! `smocap solve`: calibrate a subject, then solve its trials.

use crate::kinematics::synth::Truth;
use crate::pipeline::calibration::subject::{prepare_subject, Subject, SubjectFiles};
use crate::pipeline::results::report::Report;
use crate::pipeline::session;
use crate::solve::QpBackend;
use anyhow::Context as _;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SolveArgs {
    /// Model: OpenSim `.osim` or MJCF; the shipped full-body model by default.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// OpenSim marker set file (`<MarkerSet>`) attached to the model.
    #[arg(long)]
    pub markerset: Option<PathBuf>,
    /// Solver profile (TOML); the model's default profile when absent.
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// OpenSim Scale tool setup: its scale groups (measurement and manual scale sets), marker
    /// placement and static-pose weights; also its marker set and static trial when
    /// `--markerset` / `--static` are not given.
    #[arg(long)]
    pub scale_setup: Option<PathBuf>,
    /// Place the markers on the static trial after calibration (OpenSim's MarkerPlacer)
    /// instead of registering them.
    #[arg(long)]
    pub place_markers: bool,
    /// Keep the model's marker positions: no marker registration in calibration.
    #[arg(long)]
    pub no_register: bool,
    /// The subject's standing height (m): conditions the anthropometric prior.
    #[arg(long)]
    pub height: Option<f64>,
    /// The subject's body mass (kg): conditions the anthropometric prior and goes into the
    /// scaled model.
    #[arg(long)]
    pub mass: Option<f64>,
    /// Override a solver setting (`KEY=VALUE`, a profile's `[solver]` key and TOML value, e.g.
    /// `--set anthropometric_weight=2`); repeatable, applied after the profile and setups.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// The subject's sex (selects the survey population of the anthropometric prior).
    #[arg(long, value_enum)]
    pub sex: Option<crate::model::anthropometry::Sex>,
    /// Static calibration trial; without one, frames of the motion trials are used.
    #[arg(long = "static")]
    pub static_trial: Option<PathBuf>,
    /// Motion trials (TRC or C3D).
    #[arg(required = true)]
    pub trials: Vec<PathBuf>,
    /// Truth JSON from `smocap synth`, for pose and scale errors (single trial).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Worker threads (segments of a trial solved in parallel).
    #[arg(long)]
    pub threads: Option<usize>,
    /// QP backend for the trust-region step.
    #[arg(long, value_enum)]
    pub qp: Option<QpBackend>,
    /// Write the JSON report here.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
    /// OpenSim IK setup (`<InverseKinematicsTool>`): its marker tasks replace the profile's marker
    /// weights (markers without a task are not used, as in OpenSim); its coordinate tasks hold
    /// coordinates softly at their values.
    #[arg(long)]
    pub ik_setup: Option<PathBuf>,
    /// The marker data's up axis (detected when absent); the data are rotated into the model's.
    #[arg(long, value_enum)]
    pub up: Option<crate::pipeline::input::convention::UpAxis>,
    /// Length units of the marker files, overriding their headers.
    #[arg(long, value_enum)]
    pub units: Option<crate::pipeline::input::convention::Units>,
    /// Write each solved trial's coordinates as an OpenSim motion `<trial stem>.mot` into this
    /// directory (rotations in degrees, translations in metres).
    #[arg(long)]
    pub mot_dir: Option<PathBuf>,
    /// Write the calibrated subject as an OpenSim model (`.osim`: the `--model` .osim file
    /// rescaled, or the model generated), and its scale set beside it (`.scaleset.xml`).
    #[arg(long)]
    pub scaled_model: Option<PathBuf>,
    /// Write each solved trial as a glTF 2.0 binary `<trial stem>.glb` into this directory:
    /// the subject's bodies as nodes, its motion as an animation, bones, markers, observed
    /// markers and cameras (as `smocap export --gltf`).
    #[arg(long)]
    pub gltf_dir: Option<PathBuf>,
    /// Up axis of the glTF scenes (`y`: glTF's convention; `z`: the Z-up world).
    #[arg(long, value_enum, default_value_t = crate::render::scene::Up::Y)]
    pub gltf_up: crate::render::scene::Up,
    /// Camera rig (TOML) of the glTF scenes; default: the built-in two-camera rig per trial.
    #[arg(long)]
    pub gltf_cameras: Option<PathBuf>,
    /// Seed of the default rig's perturbation of camera positions in the glTF scenes.
    #[arg(long, default_value_t = 0)]
    pub gltf_rig_seed: u64,
    /// What the glTF scenes show of the subject (as `smocap export --body`): `mesh` (the body
    /// mesh shaped to the subject and skinned to the body nodes) or `capsules` (bones).
    #[arg(long, value_enum, default_value_t = super::export::BodyKind::Mesh)]
    pub gltf_body: super::export::BodyKind,
    /// Pre-solve (root placement + root-to-leaf local fits before the trust-region QP): `never`;
    /// `auto` re-solves frames whose RMSE is an outlier of their trial (median + 6 MAD); `always`
    /// pre-solves every warm-started frame. Overrides the profile's `presolve` (default `auto`).
    #[arg(long, value_enum)]
    pub presolve: Option<crate::solve::Presolve>,
    /// Label quality control before calibrating and solving: `off`; `flag` reports swapped
    /// labels, jumps and ghosts (the trial is then `suspect`); `repair` (default) exchanges
    /// swapped labels back and masks what cannot be repaired. Overrides the profile's
    /// `label_qc.mode`.
    #[arg(long, value_enum)]
    pub label_qc: Option<crate::pipeline::input::label_qc::QcMode>,
    #[command(flatten)]
    pub backend: super::BackendArgs,
}

/// Reads a marker file and brings it into the model's units and up axis, saying what was done.
fn read_trial(
    ctx: &crate::pipeline::Context,
    path: &std::path::Path,
    opt: &crate::pipeline::input::convention::InputOptions,
) -> anyhow::Result<(crate::io::MarkerTrial, crate::pipeline::input::convention::InputConventions)> {
    let (t, conv) = session::read_input(ctx, path, opt)?;
    eprintln!("{}: {}", path.display(), conv.summary());
    for w in t.warnings.iter().filter(|w| w.contains("masked as gaps")) {
        eprintln!("warning: {}: {w}", path.display());
    }
    // What a reader assumed to read a vendor's off-standard file (these name the file).
    for w in t.warnings.iter().filter(|w| w.starts_with(&path.display().to_string())) {
        eprintln!("warning: {w}");
    }
    Ok((t, conv))
}

/// Applies `--set KEY=VALUE` overrides to the context's solver settings.
pub fn apply_set(ctx: &mut crate::pipeline::Context, set: &[String]) -> anyhow::Result<()> {
    if set.is_empty() {
        return Ok(());
    }
    let lines: Vec<String> = set.iter().map(|kv| set_line(kv)).collect();
    let table: toml::Table = toml::from_str(&lines.join("\n")).context("--set: expected KEY=VALUE (a TOML value)")?;
    session::apply_overrides(ctx, &table).map_err(|e| anyhow::anyhow!("--set: {e}"))
}

/// One `--set KEY=VALUE` as a TOML line: a VALUE that is not TOML but a bare word
/// (`functional_hips=apply`, as a shell leaves `'…="apply"'` once unquoted) is taken as a string.
fn set_line(kv: &str) -> String {
    let Some((key, value)) = kv.split_once('=') else { return kv.to_string() };
    let bare =
        !value.trim().is_empty() && value.trim().chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    let parses = toml::from_str::<toml::Table>(kv).is_ok();
    if bare && !parses {
        format!("{}=\"{}\"", key.trim(), value.trim())
    } else {
        kv.to_string()
    }
}

pub fn run(a: SolveArgs) -> anyhow::Result<u8> {
    anyhow::ensure!(a.markerset.is_none() || a.model.is_some(), "--markerset needs --model");
    let files = SubjectFiles {
        model: a.model.clone(),
        markerset: a.markerset.clone(),
        profile: a.profile.clone(),
        scale_setup: a.scale_setup.clone(),
        ik_setup: a.ik_setup.clone(),
        static_trial: a.static_trial.clone(),
        place_markers: a.place_markers,
        no_register: a.no_register,
        subject: crate::model::anthropometry::SubjectInfo { height_m: a.height, mass_kg: a.mass, sex: a.sex },
        qp: a.qp,
    };
    let Subject { mut ctx, static_path, notes } = prepare_subject(&files)?;
    apply_set(&mut ctx, &a.set)?;
    if let Some(mode) = a.presolve {
        ctx.settings.presolve = mode;
    }
    if let Some(mode) = a.label_qc {
        ctx.settings.label_qc.mode = mode;
    }
    for n in &notes {
        eprintln!("{n}");
    }
    // What C3D files say of their subject: the prior's height and mass when none was given,
    // and whether the trials are one person.
    let mut paths: Vec<&std::path::Path> = a.trials.iter().map(|p| p.as_path()).collect();
    paths.extend(static_path.as_deref());
    let records = crate::pipeline::calibration::subject_check::subject_records(&paths);
    let subject_note = crate::pipeline::calibration::subject_check::fill_from_records(&mut ctx.subject, &records);
    if let Some(n) = &subject_note {
        eprintln!("{n}");
    }
    let not_one_person = crate::pipeline::calibration::subject_check::inconsistencies(&records);
    let input_opt = crate::pipeline::input::convention::InputOptions { up: a.up, units: a.units };
    if let Some(t) = a.threads {
        anyhow::ensure!((1..=4096).contains(&t), "--threads {t}: expected 1 to 4096 threads");
    }
    let threads = a.threads.unwrap_or_else(super::default_threads).max(1);
    prepare_outputs(&a)?;
    anyhow::ensure!(
        a.truth.is_none() || a.trials.len() == 1,
        "--truth describes one trial, but {} trials were given",
        a.trials.len()
    );
    let truth: Option<Truth> = match &a.truth {
        Some(p) => Some(
            serde_json::from_str(&std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?)
                .with_context(|| format!("parsing truth {}", p.display()))?,
        ),
        None => None,
    };
    let mut report = Report::new(&ctx, threads);
    let static_trial = match &static_path {
        Some(p) => {
            let (mut t, conv) = read_trial(&ctx, p, &input_opt)?;
            report.static_input = Some(conv);
            // Its labels are screened as every trial's are: a swap in the static trial would
            // become the subject's morphology.
            let qc = session::screen_labels(&ctx, &p.display().to_string(), &mut t);
            for line in qc.iter().flat_map(|q| q.lines(&p.display().to_string())) {
                eprintln!("{line}");
            }
            report.static_label_qc = qc;
            Some(t)
        }
        None => None,
    };
    let mut loaded = Vec::new();
    for p in &a.trials {
        let name = p.display().to_string();
        match read_trial(&ctx, p, &input_opt) {
            Ok((mut t, conv)) => {
                let qc = session::screen_labels(&ctx, &name, &mut t);
                loaded.push((name, t, conv, qc));
            }
            Err(e) => report.push(Report::failed(&name, super::one_line(&e))),
        }
    }
    // The subject's morphology from all its data: the static trial (when there is one) and
    // frames of every motion trial.
    let statics: Vec<(&str, &crate::io::MarkerTrial)> = match (&static_path, &static_trial) {
        (Some(p), Some(st)) => vec![(p.to_str().unwrap_or("static"), st)],
        _ => Vec::new(),
    };
    let motions: Vec<(&str, &crate::io::MarkerTrial)> = loaded.iter().map(|(n, t, ..)| (n.as_str(), t)).collect();
    let mut calibrated = if statics.is_empty() && motions.is_empty() {
        None
    } else {
        Some(session::calibrate(&ctx, &statics, &motions))
    };
    if let Some(Ok(c)) = &mut calibrated {
        c.report.subject_from_files = subject_note;
        let mut why = not_one_person;
        why.extend(report.static_label_qc.iter().flat_map(|q| q.suspect.iter()).map(|w| format!("static trial: {w}")));
        c.mark_subject_suspect(why);
    }
    if let Some(Ok(c)) = &calibrated {
        eprintln!("{}", c.report.summary());
        for w in &c.report.warnings {
            eprintln!("warning: calibration: {w}");
        }
        report.calibration = Some(c.report.clone());
    }
    // Marker placement moved the subject's markers: solve with them.
    let ctx = match &calibrated {
        Some(Ok(c)) => &c.ctx,
        _ => &ctx,
    };
    // The backend holds the model (on the GPU for wgpu): chosen once the markers are final.
    let (mut chosen, lanes) = a.backend.choose(ctx, threads)?;
    report.set_backend(&chosen, lanes);
    let mut solved = Vec::new();
    for (name, t, conv, qc) in &loaded {
        let result = match &calibrated {
            Some(Ok(c)) => session::solve_judged(c, name, t, conv, threads, lanes, chosen.backend(), truth.as_ref()),
            Some(Err(e)) => Err(format!("calibration failed: {e}")),
            None => Err("no calibration".into()),
        };
        match result {
            Ok(mut j) => {
                session::attach_label_qc(&mut j, qc.clone());
                for n in &j.notes {
                    eprintln!("{n}");
                }
                report.push(j.report);
                solved.push((t, j.result));
            }
            Err(e) => report.push(Report::failed(name, e)),
        }
    }
    print!("{}", report.table());
    if let Some(path) = &a.report_json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    export(&a, ctx, &solved, calibrated.as_ref().and_then(|c| c.as_ref().ok()).map(|c| &c.calibration))?;
    let failed = report.trials.iter().filter(|t| t.status != "ok").count();
    if failed > 0 {
        eprintln!("{failed} of {} trials failed or are suspect", report.trials.len());
        // Every trial suspect (e.g. a suspect calibration) is exit 3, not an error.
        if report.trials.iter().all(|t| t.status == "failed") {
            anyhow::bail!(
                "every trial failed: {}",
                report.trials.iter().filter_map(|t| t.error.clone()).collect::<Vec<_>>().join("; ")
            );
        }
    }
    if failed == report.trials.len() {
        // Results, all suspect: exit 3 (some results are not trustworthy), not "nothing ran".
        return Ok(super::EXIT_SOME_FAILED);
    }
    Ok(super::exit_code(report.trials.len() - failed, failed, false))
}

/// Creates the folders the outputs go to, and finds `.mot` name clashes, before any work.
fn prepare_outputs(a: &SolveArgs) -> anyhow::Result<()> {
    let parent = |p: &std::path::Path| p.parent().filter(|d| !d.as_os_str().is_empty()).map(|d| d.to_path_buf());
    let mut dirs: Vec<PathBuf> =
        [a.report_json.as_deref(), a.scaled_model.as_deref()].into_iter().flatten().filter_map(parent).collect();
    dirs.extend(a.mot_dir.clone());
    dirs.extend(a.gltf_dir.clone());
    for d in dirs {
        std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    }
    for (flag, dir, ext) in [("--mot-dir", &a.mot_dir, "mot"), ("--gltf-dir", &a.gltf_dir, "glb")] {
        let Some(dir) = dir else { continue };
        let mut by_path: std::collections::BTreeMap<PathBuf, &std::path::Path> = std::collections::BTreeMap::new();
        for t in &a.trials {
            let path = dir.join(out_name(&t.display().to_string(), ext));
            if let Some(other) = by_path.insert(path.clone(), t) {
                anyhow::bail!("{flag}: {} and {} would both write {}", other.display(), t.display(), path.display());
            }
        }
    }
    Ok(())
}

/// The output file name of a trial: its stem with extension `ext` (`mot`, `glb`).
fn out_name(trial: &str, ext: &str) -> String {
    let stem = std::path::Path::new(trial).file_stem().map_or("trial".into(), |s| s.to_string_lossy());
    format!("{stem}.{ext}")
}

/// Writes the OpenSim outputs asked for: one `.mot` per solved trial, the scaled model.
fn export(
    a: &SolveArgs,
    ctx: &crate::pipeline::Context,
    solved: &[(&crate::io::MarkerTrial, crate::pipeline::TrialResult)],
    calibration: Option<&crate::solve::Calibration>,
) -> anyhow::Result<()> {
    use crate::pipeline::results::export::{write_mot, write_scaled_model};
    if let Some(dir) = &a.mot_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let mut written = std::collections::HashSet::new();
        for (trial, r) in solved {
            let path = dir.join(out_name(&r.name, "mot"));
            anyhow::ensure!(written.insert(path.clone()), "--mot-dir: two trials would both write {}", path.display());
            write_mot(ctx, r, trial, &path)?;
            eprintln!("wrote {}", path.display());
        }
    }
    if let Some(dir) = &a.gltf_dir {
        let mut written = std::collections::HashSet::new();
        for (trial, r) in solved {
            let path = dir.join(out_name(&r.name, "glb"));
            anyhow::ensure!(written.insert(path.clone()), "--gltf-dir: two trials would both write {}", path.display());
            let take = crate::render::Take::from_solve(ctx, r, trial)?;
            let cams = crate::render::cameras(&take, a.gltf_cameras.as_deref(), a.gltf_rig_seed)?;
            let sub =
                crate::body::SubjectBody { stature_m: calibration.and_then(|c| c.prior.stature_m), info: ctx.subject };
            let body = match a.gltf_body {
                super::export::BodyKind::Capsules => None,
                super::export::BodyKind::Mesh => super::export::dress_or_note(&take, &sub)?,
            };
            std::fs::write(&path, crate::render::scene::glb_with_body(&take, &cams, a.gltf_up, body.as_ref())?)
                .with_context(|| format!("writing {}", path.display()))?;
            eprintln!("wrote {}", path.display());
        }
    }
    match (&a.scaled_model, calibration) {
        (Some(out), Some(c)) => {
            let (warnings, set) = write_scaled_model(ctx, c, a.model.as_deref(), out)?;
            for w in warnings {
                eprintln!("note: {w}");
            }
            eprintln!("wrote {} and {}", out.display(), set.display());
        }
        (Some(out), None) => eprintln!("{}: not written: no calibrated subject", out.display()),
        (None, _) => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn set_takes_a_bare_word_as_a_string_and_leaves_toml_values_alone() {
        assert_eq!(super::set_line("functional_hips=apply"), "functional_hips=\"apply\"");
        assert_eq!(super::set_line("static_arms=\"neutral\""), "static_arms=\"neutral\"");
        assert_eq!(super::set_line("anthropometric_weight=2"), "anthropometric_weight=2");
        assert_eq!(super::set_line("registration=false"), "registration=false");
        assert_eq!(super::set_line("label_qc.step_mm=30"), "label_qc.step_mm=30");
    }
}
