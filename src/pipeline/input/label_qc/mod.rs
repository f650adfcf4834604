//! Label quality control: swapped labels, jumps and ghosts found in a trial's markers before it
//! is calibrated and solved, repaired or masked, and reported (`docs/LABEL_QC.md`).
//!
//! The screen needs no solve. Markers on one body, or on bodies one or two joints apart, whose
//! distance stays the same over the trial (robust spread ≤ `rigid_sd_mm` on frames sampled over
//! it, [`rigid`]) are *rigid pairs*. A pair's *excess* in a frame is how far its distance is from
//! the trial's beyond `noise_sds` of its spread; a marker's *score* is the median excess over its
//! observed rigid partners. A frame in which no pair's excess passes `threshold_mm` is clean and
//! costs a few hundred distances. Otherwise ([`screen`]):
//! - **swaps**: the markers of the misfitting pairs are tried exchanged with their candidates (the
//!   left/right mirror by name, markers on bodies up to two joints away); an exchange that leaves
//!   both scores within the threshold and removes most of the excess of the pairs it touches is
//!   taken, the one removing the most (less how far it moves the labels from the previous frame's
//!   positions: a mirror-symmetric marker set is told apart by the labels' paths) first;
//! - **jumps and ghosts**: what still scores above the threshold is masked greedily (the marker
//!   with the largest excess first); a *ghost* is a jump that starts as the label reappears after
//!   a gap ("a label that appears far from where its marker was").
//!
//! Detections of the same exchange or marker at most `max_gap_frames` apart form one span; spans
//! detected in fewer than `min_frames` frames, and jumps whose marker already misfitted in the
//! frame before (a misfit that grows, not a label error), are dropped. A swap is *repaired* (the
//! two labels exchanged over the span) when the exchanged fit is within the threshold in every
//! frame of the span where both are observed, otherwise both markers are *masked* over the span;
//! jumps and ghosts are masked over their span. With `mode = flag` the events are reported and
//! nothing is changed. Every decision depends on the trial's frames alone (three passes over its
//! windows), never on threads, lanes or windows.

pub mod report;
pub mod rigid;
pub mod screen;

pub use crate::solve::settings::label_qc::{LabelQcSettings, QcMode};
pub use report::{Action, EventKind, LabelEvent, LabelQc};

use crate::io::MarkerTrial;
use crate::pipeline::context::Context;
use crate::pipeline::input::frames::{for_each_window, TrialFrames};
use screen::Screen;
use std::borrow::Cow;
use std::ops::Range;

/// Screens `trial` (in the model's conventions; its columns matched to the model's markers by
/// `columns`) as `ctx.settings.label_qc` says.
pub fn screen_trial(ctx: &Context, trial: &dyn TrialFrames, columns: &[Option<usize>]) -> Result<LabelQc, String> {
    let settings = &ctx.settings.label_qc;
    if settings.mode == QcMode::Off {
        return Ok(LabelQc::off());
    }
    let model = &ctx.model;
    let nm = model.markers.len();
    let n = trial.header().n_frames();
    let used: Vec<bool> = (0..nm).map(|m| columns[m].is_some() && ctx.marker_weights[m] > 0.0).collect();
    let mut x = vec![[f64::NAN; 3]; nm];
    // Pass 1: the rigid pairs.
    let mut sampler = rigid::PairSampler::new(rigid::candidate_pairs(model, &used), n, settings);
    for_each_window(trial, |w0, w| {
        for f in 0..w.n_frames() {
            fill(w, f, columns, &mut x);
            sampler.frame(w0 + f, &x);
        }
    })?;
    let pairs = sampler.rigid(settings);
    let mut scr = Screen::new(model, &used, pairs, settings.threshold_mm * 1e-3, settings.step_mm * 1e-3);
    // Pass 2: the per-frame screen, detections grouped into spans.
    let threshold = settings.threshold_mm * 1e-3;
    let mut spans = Spans::new(settings.max_gap_frames);
    let mut seen = vec![false; nm];
    for_each_window(trial, |w0, w| {
        for f in 0..w.n_frames() {
            fill(w, f, columns, &mut x);
            scr.frame(&x);
            spans.add(w0 + f, &scr.findings, &seen, &scr.previous, threshold);
            for (s, p) in seen.iter_mut().zip(&x) {
                *s = p[0].is_finite();
            }
        }
    })?;
    let mut raw = spans.finish();
    raw.retain(|s| s.detected >= settings.min_frames.max(1) && s.abrupt);
    // Pass 3: a swap is repaired only where the exchange fits over its whole span.
    if raw.iter().any(|s| s.b.is_some()) {
        for_each_window(trial, |w0, w| {
            for f in 0..w.n_frames() {
                let g = w0 + f;
                if !raw.iter().any(|s| s.b.is_some() && s.fits && s.range.contains(&g)) {
                    continue;
                }
                fill(w, f, columns, &mut x);
                for s in raw.iter_mut().filter(|s| s.b.is_some() && s.fits && s.range.contains(&g)) {
                    s.fits = scr.exchange_fits(s.a, s.b.expect("swap"), &x);
                }
            }
        })?;
    }
    raw.sort_by_key(|s| (s.range.start, s.kind, s.a, s.b));
    let flag = settings.mode == QcMode::Flag;
    let mut masked: Vec<Range<usize>> = Vec::new();
    let mut events = Vec::new();
    let mut ops = Vec::new();
    for s in &raw {
        let action = match (flag, s.b.is_some() && s.fits) {
            (true, _) => Action::Flagged,
            (false, true) => Action::Repaired,
            (false, false) => Action::Masked,
        };
        if action == Action::Masked {
            masked.push(s.range.clone());
        }
        let name = |m: usize| model.markers[m].name.clone();
        events.push(LabelEvent {
            kind: s.kind,
            markers: std::iter::once(s.a).chain(s.b).map(name).collect(),
            first_frame: s.range.start,
            last_frame: s.range.end - 1,
            detected_frames: s.detected,
            action,
            residual_before_mm: 1e3 * s.before / s.detected as f64,
            residual_after_mm: (s.b.is_some() && action != Action::Masked).then(|| 1e3 * s.after / s.detected as f64),
        });
        ops.push((s.a, s.b));
    }
    let masked_frames = union_len(&mut masked);
    let masked_share = masked_frames as f64 / n.max(1) as f64;
    let suspect = if flag && !events.is_empty() {
        Some(format!("label QC found {} labelling errors, left as they are (--label-qc flag)", events.len()))
    } else if masked_share > settings.suspect_masked_share {
        Some(format!(
            "label QC masked markers in {:.1} % of the frames (more than {:.1} %)",
            100.0 * masked_share,
            100.0 * settings.suspect_masked_share
        ))
    } else {
        None
    };
    Ok(LabelQc {
        mode: settings.mode,
        rigid_pairs: scr.pair_count(),
        events,
        masked_frames,
        masked_share,
        suspect,
        ops,
    })
}

/// Screens a trial held whole and applies what it decided, in place.
pub fn screen_in_place(ctx: &Context, trial: &mut MarkerTrial, columns: &[Option<usize>]) -> Result<LabelQc, String> {
    let qc = screen_trial(ctx, &*trial, columns)?;
    if qc.changes() {
        qc.apply(trial, 0, columns);
    }
    Ok(qc)
}

/// Frame `f` of `w` in model-marker order.
fn fill(w: &MarkerTrial, f: usize, columns: &[Option<usize>], x: &mut [[f64; 3]]) {
    for (m, c) in columns.iter().enumerate() {
        x[m] = c.and_then(|c| w.position(f, c)).unwrap_or([f64::NAN; 3]);
    }
}

/// Frames covered by `ranges` (sorted here).
fn union_len(ranges: &mut [Range<usize>]) -> usize {
    ranges.sort_by_key(|r| r.start);
    let mut total = 0;
    let mut end = 0;
    for r in ranges.iter() {
        let start = r.start.max(end);
        if r.end > start {
            total += r.end - start;
        }
        end = end.max(r.end);
    }
    total
}

/// A span of detections of one exchange (`b` set) or one marker's jump.
#[derive(Clone, Debug)]
struct Span {
    kind: EventKind,
    a: usize,
    b: Option<usize>,
    range: Range<usize>,
    detected: usize,
    before: f64,
    after: f64,
    /// Swaps: whether the exchange fits in every frame of the span (pass 3).
    fits: bool,
    /// Jumps: whether the marker fitted in the frame before the span (or was not seen).
    abrupt: bool,
}

/// Detections grouped into spans as frames go by.
struct Spans {
    gap: usize,
    open: Vec<Span>,
    done: Vec<Span>,
}

impl Spans {
    fn new(gap: usize) -> Spans {
        Spans { gap, open: Vec::new(), done: Vec::new() }
    }

    /// Frame `f`'s findings; `seen[m]`: marker `m` was observed in frame `f − 1`, where its score
    /// was `previous[m]`.
    fn add(&mut self, f: usize, found: &screen::Findings, seen: &[bool], previous: &[f64], threshold: f64) {
        let gap = self.gap;
        let (open, done) = (&mut self.open, &mut self.done);
        let mut i = 0;
        while i < open.len() {
            if open[i].range.end + gap < f {
                done.push(open.remove(i));
            } else {
                i += 1;
            }
        }
        let swaps = found.swaps.iter().map(|&(a, b, before, after)| (EventKind::Swap, a, Some(b), before, after));
        let masks = found.masks.iter().map(|&(m, s)| (EventKind::Jump, m, None, s, 0.0));
        for (kind, a, b, before, after) in swaps.chain(masks) {
            let same = |s: &&mut Span| (s.kind == EventKind::Swap) == (kind == EventKind::Swap) && s.a == a && s.b == b;
            match open.iter_mut().find(same) {
                Some(s) => {
                    s.range.end = f + 1;
                    s.detected += 1;
                    s.before += before;
                    s.after += after;
                }
                None => {
                    let ghost = kind == EventKind::Jump && f > 0 && !seen[a];
                    // A jump starts from a frame where the marker fitted: a misfit that grows
                    // (soft tissue at an impact) is not one.
                    let abrupt = b.is_some() || ghost || f == 0 || previous[a] < before - 0.5 * threshold;
                    let kind = if ghost { EventKind::Ghost } else { kind };
                    open.push(Span { kind, a, b, range: f..f + 1, detected: 1, before, after, fits: true, abrupt });
                }
            }
        }
    }

    fn finish(mut self) -> Vec<Span> {
        self.done.append(&mut self.open);
        self.done
    }
}

/// A trial's frames with its label QC applied as they are read.
pub struct Screened<'a> {
    pub inner: Box<dyn TrialFrames + 'a>,
    pub qc: LabelQc,
    pub columns: Vec<Option<usize>>,
}

impl TrialFrames for Screened<'_> {
    fn header(&self) -> &MarkerTrial {
        self.inner.header()
    }

    fn window(&self, range: Range<usize>) -> Result<Cow<'_, MarkerTrial>, String> {
        let first = range.start;
        let w = self.inner.window(range)?;
        if !self.qc.changes() {
            return Ok(w);
        }
        let mut w = w.into_owned();
        self.qc.apply(&mut w, first, &self.columns);
        Ok(Cow::Owned(w))
    }

    fn window_frames(&self) -> usize {
        self.inner.window_frames()
    }

    fn label_qc(&self) -> Option<&LabelQc> {
        Some(&self.qc)
    }
}

/// `trial` screened as `ctx.settings.label_qc` says, its repairs applied as its windows are
/// read; `trial` itself when screening is off or its markers do not match the model's.
pub fn screened<'a>(
    ctx: &Context,
    name: &str,
    trial: Box<dyn TrialFrames + 'a>,
) -> Result<Box<dyn TrialFrames + 'a>, String> {
    if ctx.settings.label_qc.mode == QcMode::Off {
        return Ok(trial);
    }
    let Ok(matched) = crate::pipeline::input::trial::match_markers(ctx, name, trial.header()) else { return Ok(trial) };
    let qc = screen_trial(ctx, trial.as_ref(), &matched.columns)?;
    Ok(Box::new(Screened { inner: trial, qc, columns: matched.columns }))
}
