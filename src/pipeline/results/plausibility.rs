//! Are the joint angles a person's? A low marker RMSE does not say so: registration can buy
//! marker fit with a bent knee. Every trial's report gets, per rotational coordinate, its range
//! of motion against the model's, the frames at a limit and the largest frame-to-frame jump, and
//! the left/right differences of the mean angles ([`PoseCheck`], fed frame by frame so that a
//! streamed trial is checked without being held); the calibration's static frames get theirs in
//! [`crate::pipeline::calibration::posture`]. Implausible findings make the trial `suspect`: a
//! jump of [`FLIP_DEG`] between neighbouring frames (a leg solved 180° round).

use crate::model::Model;
use crate::pipeline::calibration::posture::{checked_coordinates, pairs};
use crate::pipeline::context::Context;
use crate::solve::prior::Asymmetry;
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
                let d = crate::model::math::wrap_angle((v - prev).to_radians()).to_degrees().abs();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::calibration::posture::tests::with;

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
}
