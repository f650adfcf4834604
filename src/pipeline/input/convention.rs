//! Bringing a marker trial into the model's conventions: length units and up axis.
//!
//! Units: given explicitly (`--units`), else the file header's (TRC `Units`, C3D `POINT:UNITS`),
//! else (a C3D file without units) guessed from magnitudes: the spread of the observed markers
//! (RMS distance from their centroid) against the spread of the same model markers at the
//! default pose, taken in mm, cm or m, whichever puts the ratio within a factor of 3 of 1. A
//! header that disagrees with the magnitudes by more than that is kept, with a note.
//!
//! Up axis: given explicitly (`--up`), else detected by rigid (Kabsch) fits of the model's
//! default-pose markers to up to 10 well-populated frames spread over the trial: the model's up
//! vector mapped into the data (averaged over those frames, so that a subject's lean averages
//! out) is the data's up if it lies within 30° of a data axis (either sign); otherwise the data
//! are left as they are and the report says so. The data are then rotated by the smallest proper
//! rotation (det +1) taking their up onto the model's (e.g. Z-up → Y-up: `(x, y, z) → (x, z, −y)`).

use crate::io::markers::units_to_metres;
use crate::io::MarkerTrial;
use crate::kinematics::cpu;
use crate::pipeline::context::Context;
use crate::pipeline::input::frames::{for_each_window, TrialFrames};
use crate::pipeline::input::matching::match_names_with;
use crate::solve::root::kabsch;
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// A data axis (positive direction).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum UpAxis {
    X,
    Y,
    Z,
}

impl UpAxis {
    pub fn vector(self) -> Vector3<f64> {
        match self {
            UpAxis::X => Vector3::x(),
            UpAxis::Y => Vector3::y(),
            UpAxis::Z => Vector3::z(),
        }
    }
}

/// Length units of marker positions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Units {
    Mm,
    Cm,
    M,
}

impl Units {
    pub fn name(self) -> &'static str {
        match self {
            Units::Mm => "mm",
            Units::Cm => "cm",
            Units::M => "m",
        }
    }
    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            Units::Mm => 1e-3,
            Units::Cm => 1e-2,
            Units::M => 1.0,
        }
    }
}

/// What the user asked for; `None` = detect.
#[derive(Clone, Copy, Debug, Default)]
pub struct InputOptions {
    pub up: Option<UpAxis>,
    pub units: Option<Units>,
}

/// What was decided for one trial (for the report and a line on stderr).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct InputConventions {
    /// Units the file's numbers were read in.
    pub units: String,
    /// "command line", "file header", "marker spread" or "assumed".
    pub units_source: String,
    /// The data's up direction as found (`"y"`, `"-z"`, …); `None` when undetermined.
    pub up: Option<String>,
    /// "command line", "detected", or why nothing was decided.
    pub up_source: String,
    /// The model's up direction (model world frame).
    pub model_up: Option<[f64; 3]>,
    /// Rotation applied to every position, row-major (`x' = R x`); `None` when none was.
    pub rotation: Option<[[f64; 3]; 3]>,
    /// Observations worth a look (header units against magnitudes, ambiguous axes).
    pub notes: Vec<String>,
}

impl InputConventions {
    /// One human-readable line.
    pub fn summary(&self) -> String {
        let up = match &self.up {
            Some(u) => format!("up {u} ({})", self.up_source),
            None => format!("up axis not determined ({}), data left as is", self.up_source),
        };
        let action = match (&self.rotation, self.model_up) {
            (Some(_), Some(m)) => format!("; rotated into the model's up [{}, {}, {}]", m[0], m[1], m[2]),
            (None, _) if self.up.is_some() => "; matches the model, not rotated".into(),
            _ => String::new(),
        };
        let mut s = format!("units {} ({}), {up}{action}", self.units, self.units_source);
        for n in &self.notes {
            s += &format!("; note: {n}");
        }
        s
    }
}

/// The C3D reader's warning when a file has no `POINT:UNITS`.
const C3D_NO_UNITS: &str = "no POINT:UNITS";

/// Brings `trial` into the model's units and up axis in place; returns what was decided.
pub fn conform_trial(ctx: &Context, trial: &mut MarkerTrial, opt: &InputOptions) -> InputConventions {
    let (out, conform) = decide_conventions(ctx, &*trial, opt);
    conform.apply(trial);
    out
}

/// What bringing a trial's positions into the model's conventions does to them.
#[derive(Clone, Debug, Default)]
pub struct Conform {
    /// Positions multiplied by this (units other than the file's).
    pub factor: Option<f64>,
    /// Then rotated by this (the data's up axis onto the model's).
    pub rotation: Option<Matrix3<f64>>,
}

impl Conform {
    /// Applies it to `trial`'s positions in place.
    pub fn apply(&self, trial: &mut MarkerTrial) {
        if let Some(factor) = self.factor {
            trial.positions.iter_mut().for_each(|v| *v *= factor);
        }
        if let Some(r) = &self.rotation {
            rotate(trial, r);
        }
    }
}

/// Decides the units and up axis of `trial`'s frames for the model (as [`conform_trial`] does)
/// without changing them.
pub fn decide_conventions(ctx: &Context, frames: &dyn TrialFrames, opt: &InputOptions) -> (InputConventions, Conform) {
    let trial = frames.header();
    let mut conform = Conform::default();
    let mut out =
        InputConventions { model_up: ctx.up.map(|u| [u.x + 0.0, u.y + 0.0, u.z + 0.0]), ..Default::default() };
    let read_scale = units_to_metres(&trial.source_units).unwrap_or(1e-3);
    let fit = Fit::new(ctx, frames);
    // Units.
    let header_missing = trial.warnings.iter().any(|w| w.starts_with(C3D_NO_UNITS));
    let chosen = if let Some(u) = opt.units {
        out.units_source = "command line".into();
        Some(u.metres())
    } else if header_missing {
        match fit.as_ref().map(|f| f.spread_ratio).and_then(|r| units_from_spread(r, read_scale)) {
            Some(u) => {
                out.units_source = "marker spread".into();
                Some(u.metres())
            }
            None => {
                out.units_source = "assumed".into();
                None
            }
        }
    } else {
        out.units_source = "file header".into();
        if let Some(r) = fit.as_ref().map(|f| f.spread_ratio).filter(|r| !(1.0 / 3.0..=3.0).contains(r)) {
            let hint = units_from_spread(r, read_scale).map(|u| format!("; {} would fit (--units)", u.name()));
            out.notes.push(format!(
                "the markers spread {r:.3} times as far as the model's in {}{}",
                trial.source_units,
                hint.unwrap_or_default()
            ));
        }
        None
    };
    out.units = trial.source_units.clone();
    if let Some(metres) = chosen.filter(|m| (m / read_scale - 1.0).abs() > 1e-12) {
        conform.factor = Some(metres / read_scale);
        out.units = [Units::Mm, Units::Cm, Units::M]
            .into_iter()
            .find(|u| u.metres() == metres)
            .map_or(format!("{metres} m"), |u| u.name().into());
    } else if let Some(u) = opt.units {
        out.units = u.name().into();
    }
    // Up axis.
    let Some(model_up) = ctx.up else {
        out.up_source = "the model has no gravity to say which way is up".into();
        return (out, conform);
    };
    let data_up = if let Some(a) = opt.up {
        out.up_source = "command line".into();
        // A confident detection (the fits agree within 15°) that says otherwise is worth a word.
        if let Some(d) =
            fit.as_ref().and_then(|f| f.up_of(&model_up)).and_then(|u| nearest_axis(&u, 15f64.to_radians()))
        {
            if (d - a.vector()).norm() > 1e-9 {
                out.notes.push(format!(
                    "warning: --up {} contradicts the up axis the rigid fits detect ({}); check the data's axes",
                    axis_name(&a.vector()),
                    axis_name(&d)
                ));
            }
        }
        Some(a.vector())
    } else {
        match &fit {
            None => {
                out.up_source = "fewer than 3 model markers observed together".into();
                None
            }
            Some(f) => match f.up_of(&model_up) {
                None => {
                    out.up_source = "the rigid fits disagree or failed".into();
                    None
                }
                Some(u) => match nearest_axis(&u, 30f64.to_radians()) {
                    Some(a) => {
                        out.up_source = "detected".into();
                        Some(a)
                    }
                    None => {
                        out.up_source =
                            format!("ambiguous: the model's up maps to [{:.2}, {:.2}, {:.2}]", u.x, u.y, u.z);
                        None
                    }
                },
            },
        }
    };
    let Some(data_up) = data_up else { return (out, conform) };
    out.up = Some(axis_name(&data_up));
    let r = rotation_between(&data_up, &model_up);
    if (r.matrix() - Matrix3::identity()).abs().max() > 1e-12 {
        conform.rotation = Some(*r.matrix());
        let m = r.matrix();
        out.rotation = Some([0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]]));
    }
    (out, conform)
}

/// Rigid fits of the default-pose model markers to well-populated frames.
struct Fit {
    /// Spread of the data markers over the spread of the same model markers (mean over frames).
    spread_ratio: f64,
    /// Rotations taking model directions to data directions, one per fitted frame.
    rotations: Vec<Matrix3<f64>>,
}

impl Fit {
    /// Frames fitted at most.
    const FRAMES: usize = 10;

    fn new(ctx: &Context, frames: &dyn TrialFrames) -> Option<Fit> {
        let names: Vec<&str> = ctx.model.markers.iter().map(|m| m.name.as_str()).collect();
        let map = match_names_with(&names, &frames.header().labels, &ctx.synonyms()).ok()?.columns;
        let count =
            |t: &MarkerTrial, f: usize| map.iter().filter(|c| c.and_then(|c| t.position(f, c)).is_some()).count();
        let mut counts: Vec<usize> = Vec::with_capacity(frames.header().n_frames());
        for_each_window(frames, |_, w| counts.extend((0..w.n_frames()).map(|f| count(w, f)))).ok()?;
        let most = counts.iter().copied().max().unwrap_or(0);
        if most < 3 {
            return None;
        }
        let good: Vec<usize> = (0..counts.len()).filter(|&f| 5 * counts[f] >= 4 * most && counts[f] >= 3).collect();
        let n = good.len().min(Self::FRAMES);
        let mut ws = cpu::Workspace::new(&ctx.model);
        cpu::forward(&ctx.model, &ctx.proxy.state(&ctx.proxy.default_proxies()), &mut ws);
        let (mut ratios, mut rotations) = (Vec::new(), Vec::new());
        for f in (0..n).map(|i| good[i * good.len() / n]) {
            let trial = frames.window(f..f + 1).ok()?;
            let (a, b): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) = map
                .iter()
                .enumerate()
                .filter_map(|(m, c)| c.and_then(|c| trial.position(0, c)).map(|p| (ws.marker(m), Vector3::from(p))))
                .unzip();
            let (sa, sb) = (spread(&a), spread(&b));
            if sa > 0.0 && sb > 0.0 {
                ratios.push(sb / sa);
                rotations.extend(kabsch(&a, &b).map(|(r, _)| r));
            }
        }
        (!ratios.is_empty()).then(|| Fit { spread_ratio: ratios.iter().sum::<f64>() / ratios.len() as f64, rotations })
    }

    /// The model direction `u` mapped into the data, averaged over the fitted frames.
    fn up_of(&self, u: &Vector3<f64>) -> Option<Vector3<f64>> {
        self.rotations.iter().map(|r| r * u).sum::<Vector3<f64>>().try_normalize(1e-9)
    }
}

/// RMS distance of points from their centroid.
fn spread(p: &[Vector3<f64>]) -> f64 {
    let c = p.iter().sum::<Vector3<f64>>() / p.len() as f64;
    (p.iter().map(|x| (x - c).norm_squared()).sum::<f64>() / p.len() as f64).sqrt()
}

/// The units (mm, cm, m) that bring a spread ratio measured with positions read at
/// `read_scale` metres per unit within a factor of 3 of 1.
fn units_from_spread(ratio: f64, read_scale: f64) -> Option<Units> {
    [Units::Mm, Units::Cm, Units::M]
        .into_iter()
        .map(|u| (u, crate::model::math::ln(ratio * u.metres() / read_scale).abs()))
        .filter(|(_, d)| *d < crate::model::math::ln(3.0))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(u, _)| u)
}

/// The signed unit data axis within `tol` of direction `u`.
fn nearest_axis(u: &Vector3<f64>, tol: f64) -> Option<Vector3<f64>> {
    let u = u.try_normalize(1e-12)?;
    let (k, c) = (0..3).map(|k| (k, u[k])).max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))?;
    (c.abs() >= crate::model::math::cos(tol)).then(|| {
        let mut e = Vector3::zeros();
        e[k] = c.signum();
        e
    })
}

fn axis_name(e: &Vector3<f64>) -> String {
    let k = (0..3).max_by(|&a, &b| e[a].abs().total_cmp(&e[b].abs())).unwrap_or(2);
    format!("{}{}", if e[k] < 0.0 { "-" } else { "" }, ["x", "y", "z"][k])
}

/// The smallest proper rotation taking unit `from` onto unit `to` (a half turn about a
/// perpendicular axis when they are opposite).
pub fn rotation_between(from: &Vector3<f64>, to: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(crate::model::math::rotation_between(from, to))
}

/// Rotates every observed position of `trial` by `r`.
pub fn rotate(trial: &mut MarkerTrial, r: &Matrix3<f64>) {
    for p in trial.positions.chunks_exact_mut(3) {
        if p.iter().all(|v| v.is_finite()) {
            let v = r * Vector3::new(p[0], p[1], p[2]);
            p.copy_from_slice(&[v.x, v.y, v.z]);
        }
    }
}
