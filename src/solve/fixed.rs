//! Dense matrix products in a fixed order of our own, for computations that reach an output.
//!
//! nalgebra multiplies dynamic matrices larger than 5×5 through `matrixmultiply`, which picks
//! its f64 kernel at run time (AVX-512, FMA+AVX2, AVX, generic): fused multiply-adds and another
//! summation order change the last bits, so the same inputs would give other bytes on another
//! CPU. These products sum `Σ_k a_ik b_kj` in increasing `k` with separate multiplies and adds
//! (Rust never contracts them into fused ones), the same on every CPU. `scripts/cpu_check.sh`
//! checks the outputs against a build with `matrixmultiply` forced to its generic kernel.

use nalgebra::{DMatrix, DVector};

/// `a · b`.
pub fn mul(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    assert_eq!(a.ncols(), b.nrows(), "mul: {}×{} · {}×{}", a.nrows(), a.ncols(), b.nrows(), b.ncols());
    DMatrix::from_fn(a.nrows(), b.ncols(), |i, j| {
        let mut s = 0.0;
        for k in 0..a.ncols() {
            s += a[(i, k)] * b[(k, j)];
        }
        s
    })
}

/// `a · bᵀ`.
pub fn mul_t(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    assert_eq!(a.ncols(), b.ncols(), "mul_t: {}×{} · ({}×{})ᵀ", a.nrows(), a.ncols(), b.nrows(), b.ncols());
    DMatrix::from_fn(a.nrows(), b.nrows(), |i, j| {
        let mut s = 0.0;
        for k in 0..a.ncols() {
            s += a[(i, k)] * b[(j, k)];
        }
        s
    })
}

/// `aᵀ · b`.
pub fn t_mul(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    assert_eq!(a.nrows(), b.nrows(), "t_mul: ({}×{})ᵀ · {}×{}", a.nrows(), a.ncols(), b.nrows(), b.ncols());
    DMatrix::from_fn(a.ncols(), b.ncols(), |i, j| {
        let mut s = 0.0;
        for k in 0..a.nrows() {
            s += a[(k, i)] * b[(k, j)];
        }
        s
    })
}

/// `a · v`.
pub fn mul_v(a: &DMatrix<f64>, v: &DVector<f64>) -> DVector<f64> {
    assert_eq!(a.ncols(), v.len(), "mul_v: {}×{} · {}", a.nrows(), a.ncols(), v.len());
    DVector::from_fn(a.nrows(), |i, _| {
        let mut s = 0.0;
        for k in 0..a.ncols() {
            s += a[(i, k)] * v[k];
        }
        s
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_order_products_match_nalgebras_on_exact_integers() {
        let a = DMatrix::from_fn(7, 9, |i, j| (i * 3 + j) as f64 - 5.0);
        let b = DMatrix::from_fn(9, 8, |i, j| (i as f64) - 2.0 * j as f64);
        let v = DVector::from_fn(9, |i, _| i as f64 - 4.0);
        assert_eq!(mul(&a, &b), &a * &b);
        assert_eq!(mul_t(&a, &b.transpose()), &a * &b);
        assert_eq!(t_mul(&a.transpose(), &b), &a * &b);
        assert_eq!(mul_v(&a, &v), &a * &v);
    }
}
