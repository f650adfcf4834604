//! Host-side mirrors of the shader's `real` arrays: f32 or f64 words, read and written as f64.

use super::Precision;

/// A host buffer of shader words in the backend's precision.
#[derive(Clone, Debug)]
pub(super) enum Words {
    F32(Vec<f32>),
    F64(Vec<f64>),
}

impl Words {
    pub(super) fn new(precision: Precision) -> Words {
        match precision {
            Precision::F32 => Words::F32(Vec::new()),
            Precision::F64 => Words::F64(Vec::new()),
        }
    }

    /// `values` converted to the precision's words.
    pub(super) fn from_f64(precision: Precision, values: &[f64]) -> Words {
        match precision {
            Precision::F32 => Words::F32(values.iter().map(|&v| v as f32).collect()),
            Precision::F64 => Words::F64(values.to_vec()),
        }
    }

    /// Grows to at least `n` words (never shrinks).
    pub(super) fn ensure(&mut self, n: usize) {
        match self {
            Words::F32(v) if v.len() < n => v.resize(n, 0.0),
            Words::F64(v) if v.len() < n => v.resize(n, 0.0),
            _ => {}
        }
    }

    #[inline]
    pub(super) fn get(&self, i: usize) -> f64 {
        match self {
            Words::F32(v) => v[i] as f64,
            Words::F64(v) => v[i],
        }
    }

    /// The first `n` words as bytes (for upload).
    pub(super) fn bytes(&self, n: usize) -> &[u8] {
        match self {
            Words::F32(v) => bytemuck::cast_slice(&v[..n]),
            Words::F64(v) => bytemuck::cast_slice(&v[..n]),
        }
    }

    /// Sets entry `i` of each of the first `rows` rows of length `stride` to `value(row, i)`,
    /// for `i < n`, rows in parallel (each row's writes are contiguous).
    pub(super) fn fill_rows(
        &mut self,
        rows: usize,
        stride: usize,
        n: usize,
        value: impl Fn(usize, usize) -> f64 + Sync,
    ) {
        use rayon::prelude::*;
        match self {
            Words::F32(v) => v[..rows * stride].par_chunks_mut(stride).enumerate().for_each(|(row, w)| {
                for (i, x) in w[..n].iter_mut().enumerate() {
                    *x = value(row, i) as f32;
                }
            }),
            Words::F64(v) => v[..rows * stride].par_chunks_mut(stride).enumerate().for_each(|(row, w)| {
                for (i, x) in w[..n].iter_mut().enumerate() {
                    *x = value(row, i);
                }
            }),
        }
    }

    /// Bytes per word.
    pub(super) fn word(&self) -> usize {
        match self {
            Words::F32(_) => 4,
            Words::F64(_) => 8,
        }
    }

    /// Overwrites the first words with `bytes` read back from the device (mapped ranges are
    /// aligned to `wgpu::MAP_ALIGNMENT`, 8 bytes, so both word sizes cast in place).
    pub(super) fn copy_from_bytes(&mut self, bytes: &[u8]) {
        let n = bytes.len() / self.word();
        self.ensure(n);
        match self {
            Words::F32(v) => v[..n].copy_from_slice(bytemuck::cast_slice(bytes)),
            Words::F64(v) => v[..n].copy_from_slice(bytemuck::cast_slice(bytes)),
        }
    }
}
