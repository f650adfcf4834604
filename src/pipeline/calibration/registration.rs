//! Marker registration's parts outside the joint solve: the priors that hold each marker's offset
//! about the model's ([`registration_priors`]) and the report of what registration moved
//! ([`registration_report`]). Classes and weights: `docs/CALIBRATION.md`, "Marker roles and
//! registration".

use crate::model::MarkerClass;
use crate::pipeline::context::Context;
use crate::solve::prior::{LandmarkAnchor, OffsetPrior};
use crate::solve::Calibration;
use nalgebra::Vector3;

/// The registration's priors on the markers' offsets about the model's (`generic`), for `frames`
/// calibration frames whose marker RMSE is about `noise_m`:
/// - each landmark (anatomical marker) costs what `prior_fraction · frames` frames with one
///   marker missed by `noise_m` cost at one standard deviation `registration_anatomical_sd_m`, as
///   the scale priors do, so that landmarks stay within millimetres however many frames
///   calibration uses (a prior of one frame's weight washes out: 96 frames moved knee and ASIS
///   markers by 20–40 mm, bending the joints to buy marker fit);
/// - each tracking marker (wand, cluster, computed point) is nearly free (one frame at
///   `registration_tracking_sd_m`);
/// - on a body whose observed markers are all tracking ones, their common rotation is held as
///   landmarks' would be ([`LandmarkAnchor`]): nothing else would fix the body's orientation.
pub fn registration_priors(
    ctx: &Context,
    classes: &[MarkerClass],
    generic: &[Vector3<f64>],
    noise_m: f64,
    frames: usize,
    seen: &[bool],
) -> (OffsetPrior, LandmarkAnchor) {
    let s = &ctx.settings;
    let noise2 = noise_m.powi(2);
    let anatomical = s.prior_fraction * frames as f64 * noise2 / s.registration_anatomical_sd_m.powi(2);
    let tracking = noise2 / s.registration_tracking_sd_m.powi(2);
    let weight = classes
        .iter()
        .map(|c| Vector3::repeat(if *c == MarkerClass::Anatomical { anatomical } else { tracking }))
        .collect();
    let model = &ctx.model;
    let free_body: Vec<bool> = (0..model.bodies.len())
        .map(|b| {
            let on: Vec<usize> = (0..model.markers.len()).filter(|&m| seen[m] && model.markers[m].body == b).collect();
            on.len() >= 2 && on.iter().all(|&m| classes[m] == MarkerClass::Tracking)
        })
        .collect();
    let anchored: Vec<bool> = (0..model.markers.len()).map(|m| seen[m] && free_body[model.markers[m].body]).collect();
    (OffsetPrior { reference: generic.to_vec(), weight }, LandmarkAnchor::new(model, generic, &anchored, anatomical))
}

/// Each registered (or placed) marker's move at the subject's scale, the landmarks beyond
/// `registration_suspect_mm` (suspect) and beyond half of it (warnings).
pub fn registration_report(ctx: &Context, cal: &Calibration) -> crate::solve::prior::RegistrationReport {
    use crate::solve::prior::{MarkerMove, RegistrationReport};
    let Some(offsets) = &cal.marker_offsets else { return RegistrationReport::default() };
    let y = ctx.proxy.state(&cal.proxies);
    let model = &ctx.model;
    let classes = crate::model::marker_classes_with_sources(
        model,
        &ctx.profile.markers.tracking,
        &ctx.profile.markers.anatomical,
    );
    let mut moves: Vec<MarkerMove> = model
        .markers
        .iter()
        .zip(offsets)
        .zip(classes)
        .filter(|((m, o), _)| (*o - m.offset).norm() > 0.0)
        .map(|((m, o), (class, class_from))| {
            let s = Vector3::from_fn(|a, _| y[model.scale_index(m.body, a)]);
            MarkerMove {
                marker: m.name.clone(),
                class,
                class_from,
                moved_mm: (o - m.offset).component_mul(&s).norm() * 1e3,
            }
        })
        .collect();
    moves.sort_by(|a, b| b.moved_mm.total_cmp(&a.moved_mm));
    // Placement moves markers where the setup says (OpenSim's MarkerPlacer): reported, not judged.
    let judged = ctx.settings.registration && !ctx.settings.marker_placement;
    let limit = if judged { ctx.settings.registration_suspect_mm } else { f64::INFINITY };
    let landmarks = moves.iter().filter(|m| m.class == MarkerClass::Anatomical);
    let far = |k: f64| -> Vec<String> {
        landmarks
            .clone()
            .filter(|m| m.moved_mm > k * limit)
            .map(|m| format!("landmark {} moved {:.1} mm from the model's position", m.marker, m.moved_mm))
            .collect()
    };
    let suspect = far(1.0);
    let warnings = far(0.5).into_iter().filter(|w| !suspect.contains(w)).collect();
    RegistrationReport { moves, warnings, suspect }
}
