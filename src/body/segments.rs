//! Which model body carries each of the body asset's segments: a name table with the common
//! spellings, and folding into the nearest ancestor segment a model has.
//!
//! The asset's 19 segments (`pelvis`, `torso`, `head`, `femur_r` … `hand_l`) are smocap's body
//! names, which the shipped model (`models/fullbody.xml`), gait2354, Rajagopal 2016 and OpenCap's
//! `unscaled_generic.osim` share. Other models are matched by [`CANDIDATES`] (case, `_`, `-`,
//! `.` and spaces ignored; sides as `_r`, `r_`, `R`, `right_` …). A segment whose body the
//! model lacks goes to its parent segment's body ([`FOLD`]): `head` → `torso` (Rajagopal's torso
//! carries the head), `radius` → `ulna`, `hand` → `radius`, `toes` → `calcn` → (`talus`) →
//! `tibia`. `pelvis`, `femur_*` and `tibia_*` are required ([`BindError::Missing`]).
//!
//! The trunk: where the model has lumbar bodies between `pelvis` and `torso`, the `torso`
//! segment's skin is split between the torso and the lowest lumbar body ([`SegmentMap::spine`]),
//! blended by height along the spine in the bind pose.

use super::asset::BodyAsset;
use crate::model::Model;

/// Per asset segment (without side): names a model may give its body, best first.
pub const CANDIDATES: &[(&str, &[&str])] = &[
    ("pelvis", &["pelvis", "hips", "hip", "sacrum", "root"]),
    ("torso", &["torso", "thorax", "trunk", "chest", "upperbody", "back"]),
    ("head", &["head", "skull", "headneck", "neck"]),
    ("femur", &["femur", "thigh", "upperleg", "upleg"]),
    ("tibia", &["tibia", "shank", "lowerleg", "calf", "shin", "leg"]),
    ("calcn", &["calcn", "calcaneus", "foot", "heel", "talus", "ankle"]),
    ("toes", &["toes", "toe", "forefoot"]),
    ("humerus", &["humerus", "upperarm", "arm"]),
    ("ulna", &["ulna", "forearm", "lowerarm"]),
    ("radius", &["radius"]),
    ("hand", &["hand", "wrist"]),
];

/// A segment's parent segment, where its skin goes when the model has no body for it.
pub const FOLD: &[(&str, &str)] = &[
    ("torso", "pelvis"),
    ("head", "torso"),
    ("calcn", "tibia"),
    ("toes", "calcn"),
    ("humerus", "torso"),
    ("ulna", "humerus"),
    ("radius", "ulna"),
    ("hand", "radius"),
];

/// Segments a model must have a body for.
pub const REQUIRED: &[&str] = &["pelvis", "femur_r", "femur_l", "tibia_r", "tibia_l"];

/// Errors binding the body mesh to a model.
#[derive(Debug, thiserror::Error)]
pub enum BindError {
    #[error("the model has no body for the body segment(s) {0:?} (looked for e.g. {1:?}); the body needs at least a pelvis, both femurs and both tibias")]
    Missing(Vec<String>, Vec<String>),
    #[error("the body asset has no joint cube '{0}'")]
    MissingJoint(String),
    #[error("the body asset has no segment '{0}'")]
    MissingSegment(String),
    #[error(transparent)]
    Body(#[from] super::asset::BodyError),
}

/// The asset's segments on a model's bodies.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentMap {
    /// Per asset segment: the model body that carries its skin.
    pub host: Vec<usize>,
    /// Per asset segment: whether the model has a body of its own for it (not folded).
    pub own: Vec<bool>,
    /// `(lowest lumbar body, torso body)` where the model has bodies between pelvis and torso.
    pub spine: Option<(usize, usize)>,
}

fn norm(s: &str) -> String {
    s.chars().filter(|c| !matches!(c, '_' | '-' | '.' | ' ')).flat_map(char::to_lowercase).collect()
}

/// `(base, side)` of a segment name: `femur_r` → (`femur`, Some('r')).
fn split(seg: &str) -> (&str, Option<char>) {
    match seg.rsplit_once('_') {
        Some((b, "r")) => (b, Some('r')),
        Some((b, "l")) => (b, Some('l')),
        _ => (seg, None),
    }
}

/// The normalised names a segment's body may have, best first.
fn spellings(seg: &str) -> Vec<String> {
    let (base, side) = split(seg);
    let names = CANDIDATES.iter().find(|(b, _)| *b == base).map_or(&[][..], |c| c.1);
    let mut out = Vec::new();
    for n in names.iter().chain(std::iter::once(&base)) {
        match side {
            None => out.push(n.to_string()),
            Some(s) => {
                let word = if s == 'r' { "right" } else { "left" };
                for pre in [s.to_string(), word.to_string()] {
                    out.push(format!("{n}{pre}"));
                    out.push(format!("{pre}{n}"));
                }
            }
        }
    }
    out
}

/// The model body whose normalised name is one of `seg`'s spellings.
pub fn find_body(model: &Model, seg: &str) -> Option<usize> {
    let names: Vec<String> = model.bodies.iter().map(|b| norm(&b.name)).collect();
    spellings(seg).iter().find_map(|s| names.iter().position(|n| n == s))
}

/// The segment a segment folds into (with its side), if any.
fn parent_segment(seg: &str) -> Option<String> {
    let (base, side) = split(seg);
    let p = FOLD.iter().find(|(b, _)| *b == base)?.1;
    Some(match (side, p) {
        (Some(s), "tibia" | "calcn" | "humerus" | "ulna" | "radius") => format!("{p}_{s}"),
        _ => p.to_string(),
    })
}

/// Maps `asset`'s segments onto `model`'s bodies.
pub fn map_segments(model: &Model, asset: &BodyAsset) -> Result<SegmentMap, BindError> {
    let missing: Vec<String> =
        REQUIRED.iter().filter(|s| find_body(model, s).is_none()).map(|s| s.to_string()).collect();
    if !missing.is_empty() {
        let hints = missing.iter().flat_map(|m| spellings(m).into_iter().take(2)).collect();
        return Err(BindError::Missing(missing, hints));
    }
    let mut host = Vec::with_capacity(asset.segments.len());
    let mut own = Vec::with_capacity(asset.segments.len());
    for seg in &asset.segments {
        let mut s = seg.clone();
        let mut first = true;
        let b = loop {
            if let Some(b) = find_body(model, &s) {
                break b;
            }
            first = false;
            // REQUIRED are found, and every chain of FOLD ends in one of them
            s = parent_segment(&s).ok_or_else(|| BindError::MissingSegment(s.clone()))?;
        };
        host.push(b);
        own.push(first);
    }
    let spine = asset.segment_index("torso").and_then(|t| {
        let torso = host[t];
        let pelvis = find_body(model, "pelvis")?;
        let chain = model.chain(torso);
        let at = chain.iter().position(|&b| b == pelvis)?;
        (chain.len() > at + 2).then(|| (chain[at + 1], torso))
    });
    Ok(SegmentMap { host, own, spine })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spellings_cover_sides_and_synonyms() {
        let s = spellings("femur_r");
        for n in ["femurr", "rfemur", "femurright", "rightthigh", "thighr"] {
            assert!(s.contains(&n.to_string()), "{n}");
        }
        assert_eq!(norm("Right_Upper-Leg"), "rightupperleg");
        assert_eq!(parent_segment("hand_l").as_deref(), Some("radius_l"));
        assert_eq!(parent_segment("head").as_deref(), Some("torso"));
        assert_eq!(parent_segment("humerus_r").as_deref(), Some("torso"));
    }
}
