//! Reading and writing the files smocap meets: marker trials (TRC), models (MJCF).

pub mod markers;
pub mod mjcf;
pub mod trc;

pub use markers::MarkerTrial;
