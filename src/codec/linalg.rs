//! The few dense products the encoders need, written out so their summation order is fixed.
//!
//! nalgebra hands large products to `matrixmultiply`, which picks SIMD kernels at run time:
//! a machine with AVX-512 and one without would then round differently, choose different
//! parameters and write different bitstreams for the same take. Golden tests (and users who
//! re-encode to compare) need the same bytes everywhere, so encoder arithmetic that feeds a
//! decision goes through these loops instead.

use nalgebra::{Cholesky, DMatrix, DMatrixView};

/// Dot product with four accumulators combined in a fixed order: as deterministic as a
/// plain loop, but not bound by the latency of one chain of additions.
pub fn dot(x: &[f64], y: &[f64]) -> f64 {
    let mut acc = [0f64; 4];
    let (xc, yc) = (x.chunks_exact(4), y.chunks_exact(4));
    let (xr, yr) = (xc.remainder(), yc.remainder());
    for (a, b) in xc.zip(yc) {
        for k in 0..4 {
            acc[k] += a[k] * b[k];
        }
    }
    let tail: f64 = xr.iter().zip(yr).map(|(a, b)| a * b).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// `Aᵀ·B` as column dot products (both operands column-major, so both are contiguous).
pub fn tn(a: &DMatrix<f64>, b: DMatrixView<'_, f64>) -> DMatrix<f64> {
    assert_eq!(a.nrows(), b.nrows(), "inner dimensions");
    let n = a.nrows();
    let mut out = DMatrix::zeros(a.ncols(), b.ncols());
    let (av, bv) = (a.as_slice(), b.clone_owned());
    let bs = bv.as_slice();
    for j in 0..b.ncols() {
        for i in 0..a.ncols() {
            out[(i, j)] = dot(&av[i * n..(i + 1) * n], &bs[j * n..(j + 1) * n]);
        }
    }
    out
}

/// Add `Σ_j v_j v_jᵀ` over the columns of `v` to the symmetric matrix `c`.
pub fn add_outer_products(c: &mut DMatrix<f64>, v: DMatrixView<'_, f64>) {
    let n = c.nrows();
    for col in v.column_iter() {
        for a in 0..n {
            let va = col[a];
            if va == 0.0 {
                continue;
            }
            let mut dst = c.column_mut(a);
            for (d, vb) in dst.iter_mut().zip(col.iter()) {
                *d += vb * va;
            }
        }
    }
}

/// Least-squares coefficients of `y` (columns) on the columns of `b`: `(BᵀB)⁻¹ Bᵀ y`. A
/// ridge of 1e-12 of the mean diagonal keeps the Gram matrix positive definite when a
/// column is (nearly) zero.
pub struct LeastSquares {
    b: DMatrix<f64>,
    chol: Cholesky<f64, nalgebra::Dyn>,
}

impl LeastSquares {
    pub fn new(b: DMatrix<f64>) -> Self {
        let mut g = tn(&b, b.as_view());
        let k = g.nrows().max(1);
        let ridge = 1e-12 * (g.trace() / k as f64).max(1e-300);
        for i in 0..g.nrows() {
            g[(i, i)] += ridge;
        }
        let chol = Cholesky::new(g).expect("a ridged Gram matrix is positive definite");
        LeastSquares { b, chol }
    }

    pub fn solve(&self, y: DMatrixView<'_, f64>) -> DMatrix<f64> {
        self.chol.solve(&tn(&self.b, y))
    }
}

/// The `k` leading eigenvectors of a symmetric matrix, as columns, largest first; signs
/// fixed (largest entry positive) so that the result does not depend on the solver.
pub fn leading_eigenvectors(c: &DMatrix<f64>, k: usize) -> DMatrix<f64> {
    leading_eigen(c, k).0
}

/// The `k` leading eigenvectors (as columns, largest first, signs fixed as above) and their
/// eigenvalues (clamped at 0).
pub fn leading_eigen(c: &DMatrix<f64>, k: usize) -> (DMatrix<f64>, Vec<f64>) {
    let eig = nalgebra::SymmetricEigen::new(c.clone());
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let values = order
        .iter()
        .take(k)
        .map(|&i| eig.eigenvalues[i].max(0.0))
        .collect();
    let mut b = DMatrix::<f64>::zeros(c.nrows(), k);
    for (dst, &src) in order.iter().take(k).enumerate() {
        let mut v = eig.eigenvectors.column(src).clone_owned();
        let imax = v.iamax();
        if v[imax] < 0.0 {
            v = -v;
        }
        b.set_column(dst, &v);
    }
    (b, values)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agrees_with_nalgebra() {
        let a = DMatrix::from_fn(7, 3, |i, j| {
            ((i * 7 + j * 13 + i * j * 5) % 11) as f64 - 5.0
        });
        let b = DMatrix::from_fn(7, 4, |i, j| ((i + 2 * j) as f64).sin());
        assert!((tn(&a, b.as_view()) - a.transpose() * &b).norm() < 1e-12);
        let mut c = DMatrix::zeros(7, 7);
        add_outer_products(&mut c, b.as_view());
        assert!((c - &b * b.transpose()).norm() < 1e-12);
        // Exact fit: y in the span of a.
        let x = DMatrix::from_fn(3, 2, |i, j| (i + j) as f64);
        let y = &a * &x;
        let ls = LeastSquares::new(a);
        assert!((ls.solve(y.as_view()) - x).norm() < 1e-8);
    }
}
