//! A trial's markers on their way in: units and up axis brought to the model's
//! ([`convention`]), labels matched to the model's markers ([`matching`], [`trial`]), label
//! errors screened ([`label_qc`]), and frames read a window at a time ([`frames`],
//! [`file_frames`]) so that a long trial is never held whole.

pub mod convention;
pub mod file_frames;
pub mod frames;
pub mod label_qc;
pub mod matching;
pub mod trial;
