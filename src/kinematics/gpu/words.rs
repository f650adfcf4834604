//! Host-side shader words: the model's `real` array at upload, and [`Word`] for the per-frame
//! blocks packed and read in place.

use super::Precision;

/// A host buffer of shader words in the backend's precision.
#[derive(Clone, Debug)]
pub(super) enum Words {
    F32(Vec<f32>),
    F64(Vec<f64>),
}

impl Words {
    /// `values` converted to the precision's words.
    pub(super) fn from_f64(precision: Precision, values: &[f64]) -> Words {
        match precision {
            Precision::F32 => Words::F32(values.iter().map(|&v| v as f32).collect()),
            Precision::F64 => Words::F64(values.to_vec()),
        }
    }

    /// The first `n` words as bytes (for upload).
    pub(super) fn bytes(&self, n: usize) -> &[u8] {
        match self {
            Words::F32(v) => bytemuck::cast_slice(&v[..n]),
            Words::F64(v) => bytemuck::cast_slice(&v[..n]),
        }
    }
}

/// A shader word on the host: f32 or f64, as plain bytes.
pub(super) trait Word: bytemuck::Pod + Send + Sync {
    fn of(v: f64) -> Self;
    fn to_f64(self) -> f64;
    fn reals(s: &[Self]) -> crate::kinematics::backend::Reals<'_>;
}

impl Word for f32 {
    #[inline]
    fn of(v: f64) -> f32 {
        v as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn reals(s: &[f32]) -> crate::kinematics::backend::Reals<'_> {
        crate::kinematics::backend::Reals::F32(s)
    }
}

impl Word for f64 {
    #[inline]
    fn of(v: f64) -> f64 {
        v
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    fn reals(s: &[f64]) -> crate::kinematics::backend::Reals<'_> {
        crate::kinematics::backend::Reals::F64(s)
    }
}
