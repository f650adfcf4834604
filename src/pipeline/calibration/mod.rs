//! One subject, one morphology: the scale factors, a pose per calibration frame and the markers'
//! positions on their bodies, estimated together from the static trial and frames of the motion
//! trials ([`calibrate`], with its anthropometric prior in [`priors`]; `docs/CALIBRATION.md`).
//! Beside it: choosing the calibration frames ([`frames`]), marker registration's priors and
//! report ([`registration`]), the static posture ([`posture`]) and feet flat ([`feet_flat`]),
//! functional joint centres ([`joint_centres`], [`functional_hips`]), a subject's files and
//! setups ([`subject`], [`ik_tasks`]) and whether its trials are one subject ([`subject_check`]).

pub mod calibrate;
pub mod feet_flat;
pub mod frames;
pub mod functional_hips;
pub mod ik_tasks;
pub mod joint_centres;
pub mod posture;
pub mod priors;
pub mod registration;
pub mod subject;
pub mod subject_check;

pub use calibrate::{calibrate_subject, calibrate_subject_with};
