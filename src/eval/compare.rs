//! Joint angles against a reference motion, coordinate by coordinate: how a lab checks smocap
//! against its own pipeline (OpenSim or AddBiomechanics IK, Vicon's Plug-in Gait angles).
//!
//! Both sides are [`Motion`]s: named coordinate series on their own time axes (rotations in
//! degrees, translations in millimetres). Frames are matched by time (nearest sample within a
//! tolerance, half the finer frame period by default), angle differences are wrapped to
//! ±180°, and each coordinate gets its RMSE, mean offset, RMSE with the offset removed,
//! correlation and largest difference ([`compare`]). The inputs are read by [`load`].

pub mod crosstalk;
pub mod figure;
pub mod load;

use serde::{Deserialize, Serialize};

/// What a coordinate measures, and so its unit in a [`Motion`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Quantity {
    /// An angle, degrees.
    Angle,
    /// A length, millimetres.
    Length,
}

impl Quantity {
    /// The unit of this quantity in a [`Motion`].
    pub fn unit(self) -> &'static str {
        match self {
            Quantity::Angle => "deg",
            Quantity::Length => "mm",
        }
    }
}

/// One coordinate over time.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub quantity: Quantity,
    /// One value per time of the motion (deg or mm); NaN where not available.
    pub values: Vec<f64>,
}

/// Coordinates sampled at common times (s).
#[derive(Clone, Debug, Default)]
pub struct Motion {
    /// Where it came from (a file name), for reports.
    pub source: String,
    pub times: Vec<f64>,
    pub series: Vec<Series>,
    /// Windows of frames no pose fits (a converted trial's `/smocap/unfittable`; none known for
    /// other files).
    pub unfittable: Vec<Window>,
}

/// A window of unfittable frames of a motion ([`crate::pipeline::running::unfittable`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Window {
    /// First and last frame (0-based, inclusive) and their times on the motion's axis (s).
    pub first: usize,
    pub last: usize,
    pub start_s: f64,
    pub end_s: f64,
    /// Markers with the largest errors, largest first.
    pub markers: Vec<String>,
    /// "data" (the markers moved) or "model" (it cannot reach them).
    pub cause: String,
}

/// A window of `ours` in a comparison: how many matched frames it holds and whether the
/// statistics include them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WindowCompared {
    #[serde(flatten)]
    pub window: Window,
    /// Frames of the window matched to a reference frame.
    pub matched_frames: usize,
    /// Whether the coordinates' statistics (RMSE, offset, …) leave these frames out
    /// ([`CompareOptions::exclude_unfittable`]).
    pub excluded: bool,
}

impl Motion {
    /// The series called `name`.
    pub fn get(&self, name: &str) -> Option<&Series> {
        self.series.iter().find(|s| s.name == name)
    }
}

/// How frames are matched.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CompareOptions {
    /// Largest time difference (s) between matched frames; `None`: half the finer of the two
    /// motions' median frame periods, so that only frames sampled at the same instant are
    /// compared (a 100 Hz trial against a 50 Hz reference: every other frame).
    pub tolerance_s: Option<f64>,
    /// Added to the reference's times before matching (s): a reference that starts its clock
    /// elsewhere.
    pub reference_shift_s: f64,
    /// Compare only these coordinates (all coordinates both motions have when empty).
    pub coordinates: Vec<String>,
    /// Leave the frames of `ours`'s unfittable windows ([`Motion::unfittable`]) out of the statistics.
    #[serde(default)]
    pub exclude_unfittable: bool,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions { tolerance_s: None, reference_shift_s: 0.0, coordinates: Vec::new(), exclude_unfittable: false }
    }
}

/// One coordinate compared over the matched frames where both sides have a value.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CoordinateStats {
    pub name: String,
    pub quantity: Quantity,
    /// Frames compared.
    pub frames: usize,
    /// Root mean square of `ours − reference` (deg or mm; angles wrapped to ±180°).
    pub rmse: f64,
    /// Mean of `ours − reference`: a definition offset shows here.
    pub offset: f64,
    /// RMSE once the mean offset is removed: how well the waveforms agree.
    pub rmse_centred: f64,
    /// Pearson correlation of the two waveforms (NaN when either is constant).
    pub correlation: f64,
    /// Largest |ours − reference|.
    pub max_abs: f64,
    /// Mean of each side over the compared frames.
    pub mean_ours: f64,
    pub mean_reference: f64,
}

/// A whole comparison.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Comparison {
    pub ours: String,
    pub reference: String,
    /// Frames of `ours` matched to a reference frame within the tolerance.
    pub matched_frames: usize,
    pub ours_frames: usize,
    pub reference_frames: usize,
    pub tolerance_s: f64,
    pub reference_shift_s: f64,
    /// Per coordinate, in `ours`'s order.
    pub coordinates: Vec<CoordinateStats>,
    /// Requested or reference coordinates that `ours` lacks, and the other way round.
    pub missing_in_ours: Vec<String>,
    pub missing_in_reference: Vec<String>,
    /// Mean RMSE over the angles compared (deg).
    pub mean_angle_rmse: f64,
    /// `ours`'s unfittable windows, with their matched frames, included in the statistics or not.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unfittable: Vec<WindowCompared>,
}

impl Comparison {
    /// The statistics of coordinate `name`.
    pub fn get(&self, name: &str) -> Option<&CoordinateStats> {
        self.coordinates.iter().find(|c| c.name == name)
    }
}

/// Errors comparing.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    #[error("no frame of {ours} lies within {tolerance_s} s of a frame of {reference} (times {ours_span} against {reference_span}); shift the reference's clock with --shift")]
    NoOverlap { ours: String, reference: String, tolerance_s: f64, ours_span: String, reference_span: String },
    #[error("{ours} and {reference} share no coordinate (ours: {ours_names}; reference: {reference_names})")]
    NothingShared { ours: String, reference: String, ours_names: String, reference_names: String },
}

/// `a − b` for angles, wrapped to [−180°, 180°).
pub fn wrapped_difference(a: f64, b: f64) -> f64 {
    (a - b + 180.0).rem_euclid(360.0) - 180.0
}

/// Median spacing of `times` (s); `None` with fewer than two.
fn median_period(times: &[f64]) -> Option<f64> {
    let mut d: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    Some(d[d.len() / 2])
}

/// For each time of `a` (sorted), the index of the nearest time of `b` (sorted) within `tol`.
pub fn match_times(a: &[f64], b: &[f64], tol: f64) -> Vec<Option<usize>> {
    let mut j = 0;
    a.iter()
        .map(|&t| {
            while j + 1 < b.len() && (b[j + 1] - t).abs() <= (b[j] - t).abs() {
                j += 1;
            }
            (!b.is_empty() && (b[j] - t).abs() <= tol).then_some(j)
        })
        .collect()
}

/// Compares `ours` with `reference` coordinate by coordinate.
pub fn compare(ours: &Motion, reference: &Motion, opt: &CompareOptions) -> Result<Comparison, CompareError> {
    let ref_times: Vec<f64> = reference.times.iter().map(|t| t + opt.reference_shift_s).collect();
    let tol = opt.tolerance_s.unwrap_or_else(|| {
        let p = median_period(&ours.times).into_iter().chain(median_period(&ref_times)).fold(f64::INFINITY, f64::min);
        if p.is_finite() && p > 0.0 {
            0.5 * p
        } else {
            1e-6
        }
    });
    let mut matches = match_times(&ours.times, &ref_times, tol);
    let matched_frames = matches.iter().filter(|m| m.is_some()).count();
    let unfittable = windows_compared(ours, &mut matches, opt.exclude_unfittable);
    let span = |t: &[f64]| match (t.first(), t.last()) {
        (Some(a), Some(b)) => format!("{a:.3}–{b:.3} s"),
        _ => "none".to_string(),
    };
    if matched_frames == 0 {
        return Err(CompareError::NoOverlap {
            ours: ours.source.clone(),
            reference: reference.source.clone(),
            tolerance_s: tol,
            ours_span: span(&ours.times),
            reference_span: span(&ref_times),
        });
    }
    let wanted = |n: &str| opt.coordinates.is_empty() || opt.coordinates.iter().any(|c| c == n);
    let mut coordinates = Vec::new();
    let mut missing_in_reference = Vec::new();
    for s in ours.series.iter().filter(|s| wanted(&s.name)) {
        let Some(r) = reference.get(&s.name) else {
            missing_in_reference.push(s.name.clone());
            continue;
        };
        let pairs: Vec<(f64, f64)> = matches
            .iter()
            .enumerate()
            .filter_map(|(i, m)| m.map(|j| (s.values[i], r.values[j])))
            .filter(|(a, b)| a.is_finite() && b.is_finite())
            .collect();
        if let Some(st) = stats(&s.name, s.quantity, &pairs) {
            coordinates.push(st);
        }
    }
    let mut missing_in_ours: Vec<String> = reference
        .series
        .iter()
        .filter(|r| wanted(&r.name) && ours.get(&r.name).is_none())
        .map(|r| r.name.clone())
        .collect();
    missing_in_ours
        .extend(opt.coordinates.iter().filter(|c| ours.get(c).is_none() && reference.get(c).is_none()).cloned());
    if coordinates.is_empty() {
        let names = |m: &Motion| m.series.iter().map(|s| s.name.as_str()).collect::<Vec<_>>().join(", ");
        return Err(CompareError::NothingShared {
            ours: ours.source.clone(),
            reference: reference.source.clone(),
            ours_names: names(ours),
            reference_names: names(reference),
        });
    }
    let angles: Vec<f64> = coordinates.iter().filter(|c| c.quantity == Quantity::Angle).map(|c| c.rmse).collect();
    let mean_angle_rmse = if angles.is_empty() { f64::NAN } else { angles.iter().sum::<f64>() / angles.len() as f64 };
    Ok(Comparison {
        ours: ours.source.clone(),
        reference: reference.source.clone(),
        matched_frames,
        ours_frames: ours.times.len(),
        reference_frames: reference.times.len(),
        tolerance_s: tol,
        reference_shift_s: opt.reference_shift_s,
        coordinates,
        missing_in_ours,
        missing_in_reference,
        mean_angle_rmse,
        unfittable,
    })
}

/// `ours`'s unfittable windows with their matched frames (times within a window's span); with
/// `exclude`, those frames' matches are dropped from `matches`.
fn windows_compared(ours: &Motion, matches: &mut [Option<usize>], exclude: bool) -> Vec<WindowCompared> {
    ours.unfittable
        .iter()
        .map(|w| {
            let inside = |i: usize| ours.times[i] >= w.start_s && ours.times[i] <= w.end_s;
            let mut matched_frames = 0;
            for (i, m) in matches.iter_mut().enumerate() {
                if m.is_some() && inside(i) {
                    matched_frames += 1;
                    if exclude {
                        *m = None;
                    }
                }
            }
            WindowCompared { window: w.clone(), matched_frames, excluded: exclude }
        })
        .collect()
}

/// Statistics of `(ours, reference)` pairs; `None` when there are none.
fn stats(name: &str, quantity: Quantity, pairs: &[(f64, f64)]) -> Option<CoordinateStats> {
    if pairs.is_empty() {
        return None;
    }
    let n = pairs.len() as f64;
    let diff = |(a, b): &(f64, f64)| match quantity {
        Quantity::Angle => wrapped_difference(*a, *b),
        Quantity::Length => a - b,
    };
    let d: Vec<f64> = pairs.iter().map(diff).collect();
    let offset = d.iter().sum::<f64>() / n;
    let rmse = (d.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    let rmse_centred = (d.iter().map(|v| (v - offset).powi(2)).sum::<f64>() / n).sqrt();
    let max_abs = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // The reference unwrapped onto ours (ours − wrapped difference), so a waveform that
    // crosses ±180° on one side only correlates as it should.
    let r: Vec<f64> = pairs.iter().zip(&d).map(|((a, _), dv)| a - dv).collect();
    let a: Vec<f64> = pairs.iter().map(|p| p.0).collect();
    let (ma, mr) = (a.iter().sum::<f64>() / n, r.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(&r) {
        sab += (x - ma) * (y - mr);
        saa += (x - ma).powi(2);
        sbb += (y - mr).powi(2);
    }
    let correlation = if saa > 0.0 && sbb > 0.0 { sab / (saa * sbb).sqrt() } else { f64::NAN };
    Some(CoordinateStats {
        name: name.to_string(),
        quantity,
        frames: pairs.len(),
        rmse,
        offset,
        rmse_centred,
        correlation,
        max_abs,
        mean_ours: ma,
        mean_reference: mr,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motion(name: &str, times: Vec<f64>, series: Vec<(&str, Vec<f64>)>) -> Motion {
        Motion {
            source: name.into(),
            times,
            series: series
                .into_iter()
                .map(|(n, v)| Series { name: n.into(), quantity: Quantity::Angle, values: v })
                .collect(),
            unfittable: Vec::new(),
        }
    }

    #[test]
    fn a_constant_offset_shows_as_offset_with_a_perfect_waveform() {
        let t: Vec<f64> = (0..100).map(|i| i as f64 * 0.01).collect();
        let r: Vec<f64> = t.iter().map(|t| 30.0 * (6.0 * t).sin()).collect();
        let o: Vec<f64> = r.iter().map(|v| v + 5.0).collect();
        let c = compare(
            &motion("ours", t.clone(), vec![("knee", o)]),
            &motion("ref", t, vec![("knee", r)]),
            &Default::default(),
        )
        .unwrap();
        let k = c.get("knee").unwrap();
        assert!((k.offset - 5.0).abs() < 1e-9 && (k.rmse - 5.0).abs() < 1e-9, "{k:?}");
        assert!(k.rmse_centred < 1e-9 && (k.correlation - 1.0).abs() < 1e-12, "{k:?}");
        assert_eq!(c.matched_frames, 100);
    }

    #[test]
    fn angles_are_compared_across_the_wrap() {
        let t = vec![0.0, 0.01, 0.02];
        let c = compare(
            &motion("ours", t.clone(), vec![("rot", vec![179.0, -179.0, 178.0])]),
            &motion("ref", t, vec![("rot", vec![-179.0, 179.0, -180.0])]),
            &Default::default(),
        )
        .unwrap();
        let s = c.get("rot").unwrap();
        assert!((s.max_abs - 2.0).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn frames_are_matched_by_time_not_by_index() {
        // The reference runs at half the rate and starts 0.1 s later.
        let t: Vec<f64> = (0..200).map(|i| i as f64 * 0.01).collect();
        let tr: Vec<f64> = (0..90).map(|i| 0.1 + i as f64 * 0.02).collect();
        let f = |t: &f64| 10.0 * t;
        let c = compare(
            &motion("ours", t.clone(), vec![("hip", t.iter().map(f).collect())]),
            &motion("ref", tr.clone(), vec![("hip", tr.iter().map(f).collect())]),
            &Default::default(),
        )
        .unwrap();
        let s = c.get("hip").unwrap();
        assert!(s.rmse < 1e-9, "{s:?}");
        // The frames of 0.1 s ..= 1.88 s that the 50 Hz reference also sampled.
        assert_eq!(c.matched_frames, 90);
    }

    #[test]
    fn unfittable_windows_are_listed_and_left_out_on_request() {
        let t: Vec<f64> = (0..100).map(|i| i as f64 * 0.01).collect();
        let r = vec![0.0; 100];
        // Ours is off by 30° in frames 40–49 only.
        let o: Vec<f64> = (0..100).map(|i| if (40..50).contains(&i) { 30.0 } else { 0.0 }).collect();
        let mut ours = motion("ours", t.clone(), vec![("knee", o)]);
        ours.unfittable = vec![Window {
            first: 40,
            last: 49,
            start_s: 0.40,
            end_s: 0.49,
            markers: vec!["RKNE".into()],
            cause: "data".into(),
        }];
        let reference = motion("ref", t, vec![("knee", r)]);
        let with = compare(&ours, &reference, &Default::default()).unwrap();
        assert_eq!((with.unfittable[0].matched_frames, with.unfittable[0].excluded), (10, false));
        assert!((with.get("knee").unwrap().offset - 3.0).abs() < 1e-9);
        let opt = CompareOptions { exclude_unfittable: true, ..Default::default() };
        let without = compare(&ours, &reference, &opt).unwrap();
        assert_eq!((without.unfittable[0].matched_frames, without.unfittable[0].excluded), (10, true));
        let k = without.get("knee").unwrap();
        assert_eq!(k.frames, 90);
        assert!(k.offset.abs() < 1e-12 && k.max_abs < 1e-12, "{k:?}");
    }

    #[test]
    fn no_overlap_in_time_is_an_error_naming_both_spans() {
        let e = compare(
            &motion("ours", vec![0.0, 0.01], vec![("a", vec![0.0, 0.0])]),
            &motion("ref", vec![5.0, 5.01], vec![("a", vec![0.0, 0.0])]),
            &Default::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("5.000–5.010 s"), "{e}");
    }
}
