//! Solving a calibrated subject's trials: frames warm-started from their predecessor in lanes
//! ([`lanes`]), long trials cut into segments, several trials sharing the lanes ([`stream`]),
//! frames handed on in frame order with gaps bridged ([`order`], [`sink`]), flips resolved
//! ([`continuity`]), jumps in unfittable frames continued ([`jumps`]), the marker errors accumulated ([`marker_errors`]) and unfittable frames explained ([`unfittable`]), on the CPU or the wgpu
//! backend ([`device`]); what a solved trial gives ([`trial`]).

pub mod continuity;
pub mod device;
pub mod jumps;
pub mod lanes;
pub mod marker_errors;
pub mod order;
pub mod sink;
pub mod stream;
pub mod trial;
pub mod unfittable;
