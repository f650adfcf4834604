//! Are the joint angles a person's? A low marker RMSE does not say so: registration can buy
//! marker fit with a bent knee. Every trial's report gets, per rotational coordinate, its range
//! of motion against the model's, the frames at a limit and the largest frame-to-frame jump, and
//! the left/right differences of the mean angles ([`PoseCheck`], fed frame by frame so that a
//! streamed trial is checked without being held); the calibration's static frames get their
//! posture ([`static_posture`]). Implausible findings make the trial (or the calibration)
//! `suspect`: a jump of [`FLIP_DEG`] between neighbouring frames (a leg solved 180° round), a
//! standing knee flexed beyond [`STATIC_KNEE_DEG`].

use super::Context;
use crate::model::{CoordinateKind, Model};
use crate::solve::prior::{Asymmetry, StaticPostureReport};
use serde::{Deserialize, Serialize};

/// A change of a joint angle between neighbouring frames beyond this (deg) is a flip, not motion
/// (a knee flexing at 1000 °/s moves 10° per frame at 100 Hz): the trial is `suspect`.
pub const FLIP_DEG: f64 = 90.0;
/// A change between neighbouring frames beyond this (deg) is reported.
pub const JUMP_WARN_DEG: f64 = 30.0;
/// A coordinate at an end of its range in more than this fraction of the frames is reported.
pub const AT_LIMIT_WARN_FRACTION: f64 = 0.2;
/// Within this of an end of its range (deg), a coordinate is at its limit.
pub const AT_LIMIT_DEG: f64 = 0.5;
/// A left/right difference of mean angles beyond this (deg) is reported (in a symmetric task, an
/// offset of one side's calibration).
pub const ASYMMETRY_WARN_DEG: f64 = 10.0;
/// A standing knee flexed (or hyperextended) beyond this (deg) makes the calibration `suspect`.
pub const STATIC_KNEE_DEG: f64 = 10.0;
/// A standing hip or ankle beyond this from neutral (deg), or the two sides of a standing subject
/// further apart, makes the calibration `suspect`.
pub const STATIC_JOINT_DEG: f64 = 20.0;

/// One rotational coordinate over a trial (degrees).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CoordinateRange {
    pub name: String,
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    /// The model's range (infinite ends: none).
    pub model_range: (f64, f64),
    /// Frames within [`AT_LIMIT_DEG`] of an end of the model's range (clamped coordinates).
    pub frames_at_limit: usize,
    /// The largest change between neighbouring solved frames (wrapped to ±180°), and the frame
    /// it arrives at.
    pub largest_jump: f64,
    pub largest_jump_frame: usize,
}

/// What the pose check found in a trial.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PosePlausibility {
    pub frames: usize,
    pub coordinates: Vec<CoordinateRange>,
    pub asymmetry: Vec<Asymmetry>,
    /// Findings worth a look (ranges, limits, jumps, asymmetry).
    pub findings: Vec<String>,
    /// Findings that make the trial `suspect` (flips).
    pub suspect: Vec<String>,
}

#[derive(Clone, Debug)]
struct Acc {
    coord: usize,
    n: usize,
    sum: f64,
    min: f64,
    max: f64,
    at_limit: usize,
    last: Option<f64>,
    jump: f64,
    jump_frame: usize,
}

/// The rotational coordinates a pose check looks at: driven by the proxies, not locked.
fn checked_coordinates(ctx: &Context) -> Vec<usize> {
    ctx.model
        .coordinates
        .iter()
        .enumerate()
        .filter(|(j, c)| c.kind == CoordinateKind::Rotational && !c.locked && !ctx.proxy.y_terms[*j].is_empty())
        .map(|(j, _)| j)
        .collect()
}

/// Left/right pairs among `coords` by name (`_r`/`_l` endings): `(stem, right, left)`.
fn pairs(model: &Model, coords: &[usize]) -> Vec<(String, usize, usize)> {
    let name = |j: usize| model.coordinates[j].name.as_str();
    coords
        .iter()
        .filter_map(|&r| {
            let stem = name(r).strip_suffix("_r")?;
            let l = coords.iter().copied().find(|&l| name(l) == format!("{stem}_l"))?;
            Some((stem.to_string(), r, l))
        })
        .collect()
}

/// Running pose check of one trial, fed solved frames in frame order. Owns what it needs of the
/// subject (so that a sink can carry it) and its buffers: no allocation per frame.
pub struct PoseCheck {
    model: Model,
    proxy: crate::model::proxy::ProxyMap,
    acc: Vec<Acc>,
    y: Vec<f64>,
    dphi: Vec<f64>,
    frames: usize,
}

impl PoseCheck {
    pub fn new(ctx: &Context) -> PoseCheck {
        let acc = checked_coordinates(ctx)
            .into_iter()
            .map(|coord| Acc {
                coord,
                n: 0,
                sum: 0.0,
                min: f64::INFINITY,
                max: f64::NEG_INFINITY,
                at_limit: 0,
                last: None,
                jump: 0.0,
                jump_frame: 0,
            })
            .collect();
        PoseCheck {
            model: ctx.model.clone(),
            proxy: ctx.proxy.clone(),
            acc,
            y: vec![0.0; ctx.model.ny()],
            dphi: vec![0.0; ctx.proxy.terms.len()],
            frames: 0,
        }
    }

    /// Records frame `f` with proxies `p`; frames not solved (bridged) are skipped, and the jump
    /// across them is not counted.
    pub fn frame(&mut self, f: usize, p: &[f64], solved: bool) {
        if !solved || p.iter().any(|v| !v.is_finite()) {
            for a in &mut self.acc {
                a.last = None;
            }
            return;
        }
        self.proxy.apply(p, &mut self.y, &mut self.dphi);
        self.frames += 1;
        for a in &mut self.acc {
            let c = &self.model.coordinates[a.coord];
            let v = self.y[a.coord].to_degrees();
            a.n += 1;
            a.sum += v;
            a.min = a.min.min(v);
            a.max = a.max.max(v);
            let (lo, hi) = (c.range.0.to_degrees(), c.range.1.to_degrees());
            if c.clamped && ((v - lo).abs() <= AT_LIMIT_DEG || (hi - v).abs() <= AT_LIMIT_DEG) {
                a.at_limit += 1;
            }
            if let Some(prev) = a.last {
                let d = crate::solve::init::wrap_angle((v - prev).to_radians()).to_degrees().abs();
                if d > a.jump {
                    a.jump = d;
                    a.jump_frame = f;
                }
            }
            a.last = Some(v);
        }
    }

    /// What the frames say.
    pub fn finish(&self) -> PosePlausibility {
        let model = &self.model;
        let mut out = PosePlausibility { frames: self.frames, ..Default::default() };
        if self.frames == 0 {
            return out;
        }
        // Coordinates that never moved (no marker observes them: arms of a lower-body marker set)
        // say nothing about the trial.
        for a in self.acc.iter().filter(|a| a.max > a.min) {
            let c = &model.coordinates[a.coord];
            let r = CoordinateRange {
                name: c.name.clone(),
                min: a.min,
                max: a.max,
                mean: a.sum / a.n.max(1) as f64,
                model_range: (c.range.0.to_degrees(), c.range.1.to_degrees()),
                frames_at_limit: a.at_limit,
                largest_jump: a.jump,
                largest_jump_frame: a.jump_frame,
            };
            if r.largest_jump > FLIP_DEG {
                out.suspect.push(format!(
                    "{} jumps by {:.0}° into frame {}: a flip, not motion",
                    r.name, r.largest_jump, r.largest_jump_frame
                ));
            } else if r.largest_jump > JUMP_WARN_DEG {
                out.findings
                    .push(format!("{} changes by {:.0}° into frame {}", r.name, r.largest_jump, r.largest_jump_frame));
            }
            if r.frames_at_limit as f64 > AT_LIMIT_WARN_FRACTION * self.frames as f64 {
                out.findings.push(format!(
                    "{} is at an end of its range [{:.0}°, {:.0}°] in {} of {} frames",
                    r.name, r.model_range.0, r.model_range.1, r.frames_at_limit, self.frames
                ));
            }
            out.coordinates.push(r);
        }
        let coords: Vec<usize> = self.acc.iter().map(|a| a.coord).collect();
        let mean = |j: usize| out.coordinates.iter().find(|c| c.name == model.coordinates[j].name).map(|c| c.mean);
        for (stem, r, l) in pairs(model, &coords) {
            let (Some(right), Some(left)) = (mean(r), mean(l)) else { continue };
            let difference = left - right;
            if difference.abs() > ASYMMETRY_WARN_DEG {
                out.findings.push(format!(
                    "{stem}: the left side's mean is {difference:+.1}° from the right's ({left:.1}° against {right:.1}°)"
                ));
            }
            out.asymmetry.push(Asymmetry { coordinate: stem, right, left, difference });
        }
        out
    }
}

/// The posture of `frames` (proxy vectors of static calibration frames) of `ctx`'s subject, over
/// the coordinates the static posture prior holds ([`crate::solve::prior::StaticPosture`]).
pub fn static_posture(ctx: &Context, frames: &[Vec<f64>]) -> StaticPostureReport {
    let mut out = StaticPostureReport { frames: frames.len(), ..Default::default() };
    if frames.is_empty() {
        return out;
    }
    let held = crate::solve::prior::StaticPosture::held_coordinates(&ctx.model);
    let coords: Vec<usize> = checked_coordinates(ctx).into_iter().filter(|&j| held[j]).collect();
    let mut sums = vec![0.0; coords.len()];
    for p in frames {
        let y = ctx.proxy.state(p);
        for (s, &j) in sums.iter_mut().zip(&coords) {
            *s += y[j].to_degrees();
        }
    }
    let mean: Vec<f64> = sums.iter().map(|s| s / frames.len() as f64).collect();
    let model = &ctx.model;
    for (&j, &m) in coords.iter().zip(&mean) {
        let name = &model.coordinates[j].name;
        let lower = name.to_ascii_lowercase();
        if lower.contains("knee") && m.abs() > STATIC_KNEE_DEG {
            out.suspect.push(format!("standing, {name} is {m:.1}° (more than {STATIC_KNEE_DEG}° from straight)"));
        } else if (lower.contains("hip") || lower.contains("ankle")) && m.abs() > STATIC_JOINT_DEG {
            out.suspect.push(format!("standing, {name} is {m:.1}° (more than {STATIC_JOINT_DEG}° from neutral)"));
        }
        out.angles.push((name.clone(), m));
    }
    for (stem, r, l) in pairs(model, &coords) {
        let at = |k: usize| coords.iter().position(|&j| j == k).map(|i| mean[i]);
        let (Some(right), Some(left)) = (at(r), at(l)) else { continue };
        let difference = left - right;
        let lower = stem.to_ascii_lowercase();
        let limit = if lower.contains("knee") { STATIC_KNEE_DEG } else { STATIC_JOINT_DEG };
        if (lower.contains("knee") || lower.contains("hip") || lower.contains("ankle")) && difference.abs() > limit {
            out.suspect.push(format!(
                "standing, {stem} differs by {difference:+.1}° between the sides (left {left:.1}°, right {right:.1}°)"
            ));
        }
        out.asymmetry.push(Asymmetry { coordinate: stem, right, left, difference });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(ctx: &Context, name: &str, deg: f64) -> Vec<f64> {
        let mut p = ctx.proxy.default_proxies();
        let k = ctx.proxy.proxies.iter().position(|x| x.name == name).expect("proxy");
        p[k] = deg.to_radians();
        p
    }

    #[test]
    fn a_half_turn_between_neighbouring_frames_is_a_flip_and_a_wrap_is_not() {
        let ctx = Context::shipped().expect("shipped");
        let mut check = PoseCheck::new(&ctx);
        for (f, deg) in [0.0, 10.0, 20.0, 150.0, 160.0].iter().enumerate() {
            check.frame(f, &with(&ctx, "hip_rotation_r", *deg), true);
        }
        let p = check.finish();
        assert_eq!(p.suspect.len(), 1, "{p:?}");
        assert!(p.suspect[0].contains("hip_rotation_r") && p.suspect[0].contains("frame 3"), "{:?}", p.suspect);
        // The heading crossing ±180° is no jump.
        let mut check = PoseCheck::new(&ctx);
        for (f, deg) in [170.0, 179.0, -179.0, -170.0].iter().enumerate() {
            check.frame(f, &with(&ctx, "pelvis_rotation", *deg), true);
        }
        let p = check.finish();
        assert!(p.suspect.is_empty() && p.findings.is_empty(), "{p:?}");
        let r = p.coordinates.iter().find(|c| c.name == "pelvis_rotation").expect("moved");
        assert!((r.largest_jump - 9.0).abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn a_standing_knee_bent_beyond_ten_degrees_is_suspect_and_asymmetry_is_reported() {
        let ctx = Context::shipped().expect("shipped");
        let straight = with(&ctx, "knee_angle_r", 3.0);
        assert!(static_posture(&ctx, &[straight]).suspect.is_empty());
        let bent = with(&ctx, "knee_angle_r", 18.0);
        let s = static_posture(&ctx, &[bent.clone(), bent]);
        assert_eq!(s.frames, 2);
        assert!(s.suspect.iter().any(|w| w.contains("knee_angle_r is 18.0°")), "{:?}", s.suspect);
        assert!(s.suspect.iter().any(|w| w.contains("knee_angle differs by -18.0°")), "{:?}", s.suspect);
        let knee = s.asymmetry.iter().find(|a| a.coordinate == "knee_angle").expect("pair");
        assert!((knee.difference + 18.0).abs() < 1e-9);
    }
}
