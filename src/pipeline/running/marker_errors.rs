//! Per-marker error table of a solved trial: each marker's RMSE and maximum distance between the
//! model's marker and the observed one over the solved frames, anatomical and tracking markers
//! separately, and the worst frames (issue 21, item 3).

use crate::kinematics::Workspace;
use crate::model::MarkerClass;
use crate::pipeline::context::Context;
use crate::pipeline::running::unfittable::{unfittable_runs, FrameFit};
use crate::solve::Calibration;
use serde::{Deserialize, Serialize};

/// How many worst frames the table lists.
pub const WORST_FRAMES: usize = 5;

/// One marker's fit over a trial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MarkerError {
    pub marker: String,
    /// Solved frames in which it was observed (and weighted).
    pub frames: usize,
    pub rmse_mm: f64,
    pub max_mm: f64,
    /// The frame of its maximum (0-based).
    pub max_frame: usize,
}

/// One of a trial's worst frames: its marker RMSE and its worst marker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorstFrame {
    pub frame: usize,
    pub rmse_mm: f64,
    pub marker: String,
    pub marker_mm: f64,
}

/// The per-marker error table of a trial.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerErrorTable {
    pub anatomical: Vec<MarkerError>,
    pub tracking: Vec<MarkerError>,
    /// Frames with the largest marker RMSE, worst first.
    pub worst_frames: Vec<WorstFrame>,
    /// Runs of frames the model could not fit ([`crate::pipeline::running::unfittable`]); the
    /// report lists them as the trial's `unfittable`.
    #[serde(skip)]
    pub unfittable: Vec<crate::pipeline::running::unfittable::Unfittable>,
}

/// Accumulates the table frame by frame.
pub struct MarkerErrors {
    ctx: Context,
    y: Vec<f64>,
    dphi: Vec<f64>,
    kin: Workspace,
    /// Per marker: samples, Σ d², max d, frame of max.
    acc: Vec<(usize, f64, f64, usize)>,
    /// Per solved frame: (RMSE, frame, worst marker, its error).
    frames: Vec<(f64, usize, usize, f64)>,
    /// Per solved frame, in frame order: its fit for [`crate::pipeline::running::unfittable`].
    fits: Vec<FrameFit>,
}

impl MarkerErrors {
    /// For a trial solved for the subject calibrated as `cal` with `ctx`.
    pub fn new(ctx: &Context, cal: &Calibration) -> MarkerErrors {
        let ctx = ctx.pinned_to(cal);
        let nm = ctx.model.markers.len();
        MarkerErrors {
            y: vec![0.0; ctx.model.ny()],
            dphi: vec![0.0; ctx.proxy.terms.len()],
            kin: Workspace::new(&ctx.model),
            acc: vec![(0, 0.0, 0.0, 0); nm],
            frames: Vec::new(),
            fits: Vec::new(),
            ctx,
        }
    }

    /// Frame `f` solved as `proxies` from `observed` (model-marker order, NaN gaps); bridged
    /// frames are not counted.
    pub fn frame(&mut self, f: usize, proxies: &[f64], observed: &[f64], bridged: bool) {
        if bridged {
            return;
        }
        self.ctx.proxy.apply(proxies, &mut self.y, &mut self.dphi);
        crate::kinematics::cpu::forward(&self.ctx.model, &self.y, &mut self.kin);
        let (mut sq, mut n, mut worst) = (0.0, 0, (0, f64::NEG_INFINITY));
        let mut top = [(usize::MAX, f64::NEG_INFINITY); 3];
        for (m, a) in self.acc.iter_mut().enumerate() {
            let o = &observed[3 * m..3 * m + 3];
            if self.ctx.marker_weights[m] <= 0.0 || o.iter().any(|v| !v.is_finite()) {
                continue;
            }
            let d = (0..3).map(|k| (self.kin.markers[3 * m + k] - o[k]).powi(2)).sum::<f64>().sqrt();
            a.0 += 1;
            a.1 += d * d;
            if d > a.2 {
                a.2 = d;
                a.3 = f;
            }
            sq += d * d;
            n += 1;
            if d > worst.1 {
                worst = (m, d);
            }
            if let Some(k) = top.iter().position(|t| d > t.1) {
                top.copy_within(k..2, k + 1);
                top[k] = (m, d);
            }
        }
        if n > 0 {
            let rmse = (sq / n as f64).sqrt();
            self.frames.push((rmse, f, worst.0, worst.1));
            let rigid_move = self.rigid_move(worst.0, observed);
            self.fits.push(FrameFit { frame: f, rmse, top, rigid_move });
        }
    }

    /// How far marker `m` moved against the observed markers on its own body (m): the largest
    /// difference between an observed distance and the model's (rigid) one.
    fn rigid_move(&self, m: usize, observed: &[f64]) -> f64 {
        let markers = &self.ctx.model.markers;
        let (k, o) = (&self.kin.markers, &observed[3 * m..3 * m + 3]);
        let mut out = 0.0f64;
        for q in (0..markers.len()).filter(|&q| q != m && markers[q].body == markers[m].body) {
            let oq = &observed[3 * q..3 * q + 3];
            if self.ctx.marker_weights[q] <= 0.0 || oq.iter().any(|v| !v.is_finite()) {
                continue;
            }
            let dist = |a: &[f64], b: &[f64]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
            out = out.max((dist(o, oq) - dist(&k[3 * m..3 * m + 3], &k[3 * q..3 * q + 3])).abs());
        }
        out
    }

    /// The table.
    pub fn finish(mut self) -> MarkerErrorTable {
        let classes = self.ctx.marker_classes();
        let mut t = MarkerErrorTable::default();
        for (m, &(n, sq, max, at)) in self.acc.iter().enumerate() {
            if n == 0 {
                continue;
            }
            let e = MarkerError {
                marker: self.ctx.model.markers[m].name.clone(),
                frames: n,
                rmse_mm: 1e3 * (sq / n as f64).sqrt(),
                max_mm: 1e3 * max,
                max_frame: at,
            };
            match classes[m] {
                MarkerClass::Anatomical => t.anatomical.push(e),
                MarkerClass::Tracking => t.tracking.push(e),
            }
        }
        let names: Vec<String> = self.ctx.model.markers.iter().map(|m| m.name.clone()).collect();
        t.unfittable = unfittable_runs(&self.fits, &names);
        self.frames.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        t.worst_frames = self
            .frames
            .iter()
            .take(WORST_FRAMES)
            .map(|&(r, f, m, d)| WorstFrame {
                frame: f,
                rmse_mm: 1e3 * r,
                marker: self.ctx.model.markers[m].name.clone(),
                marker_mm: 1e3 * d,
            })
            .collect();
        t
    }
}

impl MarkerErrorTable {
    /// Lines for `smocap solve`'s output: the markers by RMSE, worst first, and the worst frames.
    pub fn lines(&self, trial: &str) -> Vec<String> {
        let mut out = Vec::new();
        for (class, v) in [("anatomical", &self.anatomical), ("tracking", &self.tracking)] {
            if v.is_empty() {
                continue;
            }
            let mut v: Vec<&MarkerError> = v.iter().collect();
            v.sort_by(|a, b| b.rmse_mm.total_cmp(&a.rmse_mm));
            let cells: Vec<String> =
                v.iter().map(|e| format!("{} {:.1}/{:.1} (f{})", e.marker, e.rmse_mm, e.max_mm, e.max_frame)).collect();
            out.push(format!("{trial}: {class} markers, RMSE/max mm: {}", cells.join(", ")));
        }
        let worst: Vec<String> = self
            .worst_frames
            .iter()
            .map(|w| format!("{} ({:.1} mm, {} {:.1} mm)", w.frame, w.rmse_mm, w.marker, w.marker_mm))
            .collect();
        if !worst.is_empty() {
            out.push(format!("{trial}: worst frames: {}", worst.join(", ")));
        }
        out
    }
}
