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

/// `Σ_k a_k b_k` as four interleaved partial sums (`k` mod 4) added as `(s0 + s1) + (s2 + s3)`,
/// then the remaining terms in order: a fixed order that the compiler may run in SIMD lanes.
fn dot4(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (mut s0, mut s1, mut s2, mut s3) = (0.0, 0.0, 0.0, 0.0);
    let mut k = 0;
    while k + 4 <= n {
        s0 += a[k] * b[k];
        s1 += a[k + 1] * b[k + 1];
        s2 += a[k + 2] * b[k + 2];
        s3 += a[k + 3] * b[k + 3];
        k += 4;
    }
    let mut s = (s0 + s1) + (s2 + s3);
    while k < n {
        s += a[k] * b[k];
        k += 1;
    }
    s
}

/// Column `j` of `a` as a slice (nalgebra stores columns contiguously).
fn col(a: &DMatrix<f64>, j: usize) -> &[f64] {
    let n = a.nrows();
    &a.as_slice()[j * n..(j + 1) * n]
}

/// `out += α aᵀ b` into the block of `out` at `(i0, j0)` (columns dotted as [`dot4`] does).
pub fn add_t_mul(out: &mut DMatrix<f64>, (i0, j0): (usize, usize), alpha: f64, a: &DMatrix<f64>, b: &DMatrix<f64>) {
    assert_eq!(a.nrows(), b.nrows(), "add_t_mul: ({}×{})ᵀ · {}×{}", a.nrows(), a.ncols(), b.nrows(), b.ncols());
    for j in 0..b.ncols() {
        let bj = col(b, j);
        for i in 0..a.ncols() {
            out[(i0 + i, j0 + j)] += alpha * dot4(col(a, i), bj);
        }
    }
}

/// `out += α aᵀ a` into the square block of `out` at `(o, o)`: the upper triangle computed (as
/// [`dot4`] does), the lower one mirrored from it, so the block stays exactly symmetric.
pub fn add_t_mul_sym(out: &mut DMatrix<f64>, o: usize, alpha: f64, a: &DMatrix<f64>) {
    for j in 0..a.ncols() {
        let aj = col(a, j);
        for i in 0..=j {
            let v = alpha * dot4(col(a, i), aj);
            out[(o + i, o + j)] += v;
            if i != j {
                out[(o + j, o + i)] += v;
            }
        }
    }
}

/// `out += α aᵀ a` over the whole of `out` (square, `a.ncols()` wide), the upper triangle in
/// 4 × 4 tiles of outputs: each output is one sum `Σ_k a_ki a_kj` in increasing `k` (a fixed
/// order, the same on every CPU), sixteen of them at once so that each loaded element serves
/// four, the lower triangle mirrored from the upper. The calibration's reduced system
/// (`solve::calibrate`) spends most of its time here: 3–4× faster than [`add_t_mul_sym`].
pub fn add_t_mul_sym_tiled(out: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>) {
    let n = a.nrows();
    t_mul_sym_tiles(out, alpha, a, |_, _| Some(0..n), |_, _| 0..n);
}

/// The set bits of a mask, lowest first.
#[derive(Clone, Copy)]
struct Bits(u64);

impl Iterator for Bits {
    type Item = usize;
    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        (self.0 != 0).then(|| {
            let k = self.0.trailing_zeros() as usize;
            self.0 &= self.0 - 1;
            k
        })
    }
}

/// `out += α aᵀ a`, the upper triangle in 4 × 4 tiles of outputs mirrored to the lower: each
/// output one sum over the rows `k` in increasing order, those that `tile_rows(i0, j0)` gives
/// for a whole tile (`None`: the tile adds nothing) and `pair_rows(i, j)` for one output of a
/// tile at the matrix's edge.
#[inline(always)]
fn t_mul_sym_tiles<R: Iterator<Item = usize>>(
    out: &mut DMatrix<f64>,
    alpha: f64,
    a: &DMatrix<f64>,
    tile_rows: impl Fn(usize, usize) -> Option<R>,
    pair_rows: impl Fn(usize, usize) -> R,
) {
    let (n, m) = (a.nrows(), a.ncols());
    assert_eq!((out.nrows(), out.ncols()), (m, m), "add_t_mul_sym: out is not {m}×{m}");
    let data = a.as_slice();
    let c = |j: usize| &data[j * n..(j + 1) * n];
    let mut tile = [[0.0f64; 4]; 4];
    let mut j0 = 0;
    while j0 < m {
        let jw = (m - j0).min(4);
        let mut i0 = 0;
        while i0 <= j0 {
            let iw = (m - i0).min(4);
            let Some(rows) = tile_rows(i0, j0) else {
                i0 += 4;
                continue;
            };
            if iw == 4 && jw == 4 {
                let (a0, a1, a2, a3) = (c(i0), c(i0 + 1), c(i0 + 2), c(i0 + 3));
                let (b0, b1, b2, b3) = (c(j0), c(j0 + 1), c(j0 + 2), c(j0 + 3));
                let mut s = [[0.0f64; 4]; 4];
                for k in rows {
                    let (x0, x1, x2, x3) = (a0[k], a1[k], a2[k], a3[k]);
                    let (y0, y1, y2, y3) = (b0[k], b1[k], b2[k], b3[k]);
                    s[0][0] += x0 * y0;
                    s[0][1] += x0 * y1;
                    s[0][2] += x0 * y2;
                    s[0][3] += x0 * y3;
                    s[1][0] += x1 * y0;
                    s[1][1] += x1 * y1;
                    s[1][2] += x1 * y2;
                    s[1][3] += x1 * y3;
                    s[2][0] += x2 * y0;
                    s[2][1] += x2 * y1;
                    s[2][2] += x2 * y2;
                    s[2][3] += x2 * y3;
                    s[3][0] += x3 * y0;
                    s[3][1] += x3 * y1;
                    s[3][2] += x3 * y2;
                    s[3][3] += x3 * y3;
                }
                tile = s;
            } else {
                for (di, row) in tile.iter_mut().enumerate().take(iw) {
                    for (dj, v) in row.iter_mut().enumerate().take(jw) {
                        let (x, y) = (c(i0 + di), c(j0 + dj));
                        let mut s = 0.0;
                        for k in pair_rows(i0 + di, j0 + dj) {
                            s += x[k] * y[k];
                        }
                        *v = s;
                    }
                }
            }
            for (di, row) in tile.iter().enumerate().take(iw) {
                for (dj, v) in row.iter().enumerate().take(jw) {
                    let (i, j) = (i0 + di, j0 + dj);
                    if i < j {
                        out[(i, j)] += alpha * v;
                        out[(j, i)] += alpha * v;
                    } else if i == j {
                        out[(i, j)] += alpha * v;
                    }
                }
            }
            i0 += 4;
        }
        j0 += 4;
    }
}

/// [`add_t_mul_sym_tiled`] skipping the rows where a tile's columns are exactly zero: each
/// column's non-zero rows are a bit mask (`a` at most 64 rows; taller matrices go to the dense
/// product), and each 4 × 4 tile of outputs sums only over the rows where some column of its
/// left four and some of its right four are non-zero, in increasing order. A skipped row only
/// adds `±0` products to a sum that starts at `+0` (never `−0`), so the result is bit for bit
/// [`add_t_mul_sym_tiled`]'s (a matrix holding a non-finite value goes to it whole). The
/// calibration's reduced system uses it: with the poses ordered leaves first, `U = L⁻¹B`'s column
/// of a marker is non-zero only on the pose proxies that move it (its chain to the root), and two
/// markers on different limbs share only the root's and trunk's.
pub fn add_t_mul_sym_sparse(out: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>) {
    let (n, m) = (a.nrows(), a.ncols());
    if n > 64 {
        return add_t_mul_sym_tiled(out, alpha, a);
    }
    let data = a.as_slice();
    // Each column's non-zero rows, and whether every value is finite (in the same pass).
    let mut finite = true;
    let mut mask = |j: usize| -> u64 {
        let mut bits = 0u64;
        for (k, v) in data[j * n..(j + 1) * n].iter().enumerate() {
            finite &= v.is_finite();
            if *v != 0.0 {
                bits |= 1 << k;
            }
        }
        bits
    };
    let masks: Vec<u64> = (0..m).map(&mut mask).collect();
    if !finite {
        return add_t_mul_sym_tiled(out, alpha, a);
    }
    let tiles: Vec<u64> = masks.chunks(4).map(|t| t.iter().fold(0, |a, b| a | b)).collect();
    t_mul_sym_tiles(
        out,
        alpha,
        a,
        |i0, j0| Some(Bits(tiles[i0 / 4] & tiles[j0 / 4])).filter(|b| b.0 != 0),
        |i, j| Bits(masks[i] & masks[j]),
    );
}

/// `b ← L⁻¹ b` for lower-triangular `l` (square, `b.nrows()` rows), column by column as
/// nalgebra's `solve_lower_triangular_unchecked_mut` does it (`x_k /= L_kk`, then
/// `x_i −= L_ik x_k` for `i > k`, in increasing `k`), skipping the exact zeros: an `x_k` that is
/// zero, and the rows where `L`'s column `k` is. The result is nalgebra's but for the sign of
/// zeros (with a non-finite value anywhere, nalgebra's solve runs instead); with the poses ordered leaves first (`solve::calibrate`), a marker's column has
/// non-zeros only on its chain to the root and `L` no fill, so most of the work is skipped.
pub fn solve_lower_sparse(l: &DMatrix<f64>, b: &mut DMatrix<f64>) {
    solve_lower_sparse_in(l, b, &mut SparseScratch::default());
}

/// The index lists [`solve_lower_sparse_in`] builds, kept by a caller that solves many systems.
#[derive(Default)]
pub struct SparseScratch {
    /// Each column's below-diagonal non-zeros of `l`, as (row, value), columns one after another.
    below: Vec<(usize, f64)>,
    start: Vec<usize>,
}

/// [`solve_lower_sparse`] with its index lists in `scratch` (no allocation once they have grown).
pub fn solve_lower_sparse_in(l: &DMatrix<f64>, b: &mut DMatrix<f64>, scratch: &mut SparseScratch) {
    let n = l.nrows();
    assert!(l.ncols() == n && b.nrows() == n, "solve_lower_sparse: shapes");
    if l.iter().chain(b.iter()).any(|v| !v.is_finite()) {
        l.solve_lower_triangular_unchecked_mut(b);
        return;
    }
    let ld = l.as_slice();
    // Below-diagonal non-zero rows of each column of `l`.
    let SparseScratch { below, start } = scratch;
    below.clear();
    start.clear();
    for k in 0..n {
        start.push(below.len());
        below.extend((k + 1..n).map(|i| (i, ld[k * n + i])).filter(|&(_, v)| v != 0.0));
    }
    start.push(below.len());
    for x in b.as_mut_slice().chunks_exact_mut(n.max(1)) {
        for k in 0..n {
            if x[k] == 0.0 {
                continue;
            }
            let v = x[k] / ld[k * n + k];
            x[k] = v;
            for &(i, lik) in &below[start[k]..start[k + 1]] {
                x[i] -= lik * v;
            }
        }
    }
}

/// `aᵀ v` (each entry one sum in increasing row order).
pub fn t_mul_v(a: &DMatrix<f64>, v: &DVector<f64>) -> DVector<f64> {
    assert_eq!(a.nrows(), v.len(), "t_mul_v: ({}×{})ᵀ · {}", a.nrows(), a.ncols(), v.len());
    let n = a.nrows();
    let vs = v.as_slice();
    DVector::from_fn(a.ncols(), |j, _| {
        let cj = &a.as_slice()[j * n..(j + 1) * n];
        let mut s = 0.0;
        for k in 0..n {
            s += cj[k] * vs[k];
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
        let mut out = DMatrix::zeros(11, 11);
        add_t_mul(&mut out, (1, 2), 2.0, &a, &a);
        assert_eq!(out.view((1, 2), (9, 9)), a.transpose() * &a * 2.0);
        let mut sym = DMatrix::zeros(10, 10);
        add_t_mul_sym(&mut sym, 1, -1.0, &a);
        assert_eq!(sym.view((1, 1), (9, 9)), -(a.transpose() * &a));
        // Tiles of 4 with ragged edges (9 columns), and a narrow matrix.
        let mut tiled = DMatrix::zeros(9, 9);
        add_t_mul_sym_tiled(&mut tiled, -1.0, &a);
        assert_eq!(tiled, -(a.transpose() * &a));
        let narrow = a.columns(0, 3).into_owned();
        let mut t3 = DMatrix::zeros(3, 3);
        add_t_mul_sym_tiled(&mut t3, 2.0, &narrow);
        assert_eq!(t3, narrow.transpose() * &narrow * 2.0);
        assert_eq!(t_mul_v(&a, &v.rows(0, 7).into_owned()), a.transpose() * v.rows(0, 7));
    }

    #[test]
    fn the_sparse_symmetric_product_is_the_dense_one_bit_for_bit() {
        // Irrational-ish values with exact zeros in blocks (as `L⁻¹B` has them), ragged tiles,
        // and a matrix holding a NaN (the dense product's, which propagates it).
        let zero = |i: usize, j: usize| (i * 7 + j * 3) % 5 < 2 || (j > 9 && i < 20);
        let a = DMatrix::from_fn(37, 23, |i, j| if zero(i, j) { 0.0 } else { ((i * 13 + j) as f64).sin() * 1e3 });
        for alpha in [1.0, -1.0, 0.3] {
            let mut dense = DMatrix::from_fn(23, 23, |i, j| ((i + j) as f64).cos());
            let mut sparse = dense.clone();
            add_t_mul_sym_tiled(&mut dense, alpha, &a);
            add_t_mul_sym_sparse(&mut sparse, alpha, &a);
            assert!(dense.iter().zip(sparse.iter()).all(|(d, s)| d.to_bits() == s.to_bits()));
        }
        let mut b = a.clone();
        b[(5, 4)] = f64::NAN;
        let (mut dense, mut sparse) = (DMatrix::zeros(23, 23), DMatrix::zeros(23, 23));
        add_t_mul_sym_tiled(&mut dense, -1.0, &b);
        add_t_mul_sym_sparse(&mut sparse, -1.0, &b);
        assert!(dense.iter().zip(sparse.iter()).all(|(d, s)| d.to_bits() == s.to_bits() || (d.is_nan() && s.is_nan())));
    }

    #[test]
    fn the_sparse_triangular_solve_is_nalgebras() {
        // A lower factor with structural zeros (no fill), and right-hand sides with zero runs.
        let l = DMatrix::from_fn(9, 9, |i, j| match (i, j) {
            (i, j) if i == j => 1.5 + i as f64 * 0.1,
            (i, j) if i > j && (i + j) % 3 == 0 => ((i * 9 + j) as f64).sin(),
            _ => 0.0,
        });
        let b = DMatrix::from_fn(9, 6, |i, j| if (i + 2 * j) % 4 == 1 { 0.0 } else { ((i + 11 * j) as f64).cos() });
        let mut ours = b.clone();
        solve_lower_sparse(&l, &mut ours);
        let mut theirs = b.clone();
        l.solve_lower_triangular_unchecked_mut(&mut theirs);
        assert!(ours.iter().zip(theirs.iter()).all(|(a, b)| a == b));
    }
}
