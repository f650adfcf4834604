//! Dense kernels of [`super::BoxQp`] on plain slices: symmetric matrix–vector product from the
//! upper triangle, dot product, and an in-place Cholesky factorisation and solve. Matrices are
//! column-major; the kernels are written so that their inner loops vectorise.

/// In-place left-looking Cholesky of the lower triangle of the column-major `nf × nf` matrix
/// `a` (column `j` holds rows `j..nf` at `a[j·nf + j..(j + 1)·nf]`), storing `L` there and
/// `1/L_jj` in `inv_diag`. Columns are produced in pairs, each pass subtracting four earlier
/// columns: the inner loop is a vectorisable multi-axpy with no reduction chain.
/// `Err((j, pivot))` if pivot `j` is `≤ thr` (or NaN).
pub(super) fn cholesky(a: &mut [f64], inv_diag: &mut [f64], nf: usize, thr: f64) -> Result<(), (usize, f64)> {
    let mut j = 0;
    while j < nf {
        let (done, rest) = a.split_at_mut(j * nf);
        if j + 1 == nf {
            let col = &mut rest[j..nf];
            for k in 0..j {
                let s = done[k * nf + j];
                col[0] -= s * s;
            }
            inv_diag[j] = finish_column(col, j, thr)?;
            break;
        }
        let (cj, cj1) = rest.split_at_mut(nf);
        let (cj, cj1) = (&mut cj[j..nf], &mut cj1[j + 1..nf]);
        let mut k = 0;
        while k + 4 <= j {
            let c0 = &done[k * nf + j..(k + 1) * nf];
            let c1 = &done[(k + 1) * nf + j..(k + 2) * nf];
            let c2 = &done[(k + 2) * nf + j..(k + 3) * nf];
            let c3 = &done[(k + 3) * nf + j..(k + 4) * nf];
            let (s0, s1, s2, s3) = (c0[0], c1[0], c2[0], c3[0]);
            let (t0, t1, t2, t3) = (c0[1], c1[1], c2[1], c3[1]);
            cj[0] -= (s0 * s0 + s1 * s1) + (s2 * s2 + s3 * s3);
            let rows = cj[1..].iter_mut().zip(cj1.iter_mut());
            for (((((o, p), &a0), &a1), &a2), &a3) in rows.zip(&c0[1..]).zip(&c1[1..]).zip(&c2[1..]).zip(&c3[1..]) {
                *o -= (a0 * s0 + a1 * s1) + (a2 * s2 + a3 * s3);
                *p -= (a0 * t0 + a1 * t1) + (a2 * t2 + a3 * t3);
            }
            k += 4;
        }
        for k in k..j {
            let c0 = &done[k * nf + j..(k + 1) * nf];
            let (s0, t0) = (c0[0], c0[1]);
            cj[0] -= s0 * s0;
            for ((o, p), &a0) in cj[1..].iter_mut().zip(cj1.iter_mut()).zip(&c0[1..]) {
                *o -= a0 * s0;
                *p -= a0 * t0;
            }
        }
        inv_diag[j] = finish_column(cj, j, thr)?;
        let t0 = cj[1];
        for (p, &a0) in cj1.iter_mut().zip(&cj[1..]) {
            *p -= a0 * t0;
        }
        inv_diag[j + 1] = finish_column(cj1, j + 1, thr)?;
        j += 2;
    }
    Ok(())
}

/// Solves `L Lᵀ z = y` in place for the factor left by [`cholesky`] (`inv_diag[j] = 1/L_jj`).
pub(super) fn cholesky_solve(l: &[f64], inv_diag: &[f64], y: &mut [f64]) {
    let nf = y.len();
    // L w = y: column-oriented forward substitution.
    for j in 0..nf {
        let wj = y[j] * inv_diag[j];
        y[j] = wj;
        for (yi, lij) in y[j + 1..].iter_mut().zip(&l[j * nf + j + 1..(j + 1) * nf]) {
            *yi -= lij * wj;
        }
    }
    // Lᵀ z = w: row i of Lᵀ is column i of L.
    for i in (0..nf).rev() {
        let s = dot(&l[i * nf + i + 1..(i + 1) * nf], &y[i + 1..]);
        y[i] = (y[i] - s) * inv_diag[i];
    }
}

/// Pivot test, square root and scaling of one Cholesky column (`col[0]` is the pivot);
/// returns `1/L_jj`.
fn finish_column(col: &mut [f64], j: usize, thr: f64) -> Result<f64, (usize, f64)> {
    let pivot = col[0];
    if pivot.is_nan() || pivot <= thr {
        return Err((j, pivot));
    }
    let d = pivot.sqrt();
    let inv = 1.0 / d;
    col[0] = d;
    col[1..].iter_mut().for_each(|v| *v *= inv);
    Ok(inv)
}

/// Dot product with four independent accumulators (vectorises without reassociation).
#[inline]
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let mut tail = 0.0;
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        tail += x * y;
    }
    let mut acc = [0.0; 4];
    for (x, y) in ca.zip(cb) {
        acc[0] += x[0] * y[0];
        acc[1] += x[1] * y[1];
        acc[2] += x[2] * y[2];
        acc[3] += x[3] * y[3];
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// `out = H v` for symmetric `H` (column-major `n × n`), reading only the upper triangle.
pub(super) fn symv_upper(h: &[f64], n: usize, v: &[f64], out: &mut [f64]) {
    out.iter_mut().for_each(|o| *o = 0.0);
    for j in 0..n {
        let col = &h[j * n..j * n + j];
        let vj = v[j];
        if vj != 0.0 {
            for (o, c) in out[..j].iter_mut().zip(col) {
                *o += c * vj;
            }
        }
        out[j] += dot(col, &v[..j]) + h[j * n + j] * vj;
    }
}
