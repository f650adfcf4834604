//! The posture of a static trial: a subject standing in the calibration's static frames should
//! stand straight, the sides alike. A standing knee flexed beyond [`STATIC_KNEE_DEG`], a hip or
//! ankle beyond [`STATIC_JOINT_DEG`], or the sides that far apart make the calibration `suspect`.
//! Also the coordinates a pose check looks at and their left/right pairs, which the trials' pose
//! check ([`crate::pipeline::results::plausibility`]) shares.

use crate::model::{CoordinateKind, Model};
use crate::pipeline::context::Context;
use crate::solve::prior::{Asymmetry, StaticPostureReport};

/// A standing knee flexed (or hyperextended) beyond this (deg) makes the calibration `suspect`.
pub const STATIC_KNEE_DEG: f64 = 10.0;
/// A standing hip or ankle beyond this from neutral (deg), or the two sides of a standing subject
/// further apart, makes the calibration `suspect`.
pub const STATIC_JOINT_DEG: f64 = 20.0;

/// The rotational coordinates a pose check looks at: driven by the proxies, not locked.
pub(crate) fn checked_coordinates(ctx: &Context) -> Vec<usize> {
    ctx.model
        .coordinates
        .iter()
        .enumerate()
        .filter(|(j, c)| c.kind == CoordinateKind::Rotational && !c.locked && !ctx.proxy.y_terms[*j].is_empty())
        .map(|(j, _)| j)
        .collect()
}

/// Left/right pairs among `coords` by name (`_r`/`_l` endings): `(stem, right, left)`.
pub(crate) fn pairs(model: &Model, coords: &[usize]) -> Vec<(String, usize, usize)> {
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
pub(crate) mod tests {
    use super::*;

    pub(crate) fn with(ctx: &Context, name: &str, deg: f64) -> Vec<f64> {
        let mut p = ctx.proxy.default_proxies();
        let k = ctx.proxy.proxies.iter().position(|x| x.name == name).expect("proxy");
        p[k] = deg.to_radians();
        p
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
