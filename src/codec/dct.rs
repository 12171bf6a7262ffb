//! The orthonormal DCT-II along time, as a basis matrix: clips are short (tens to hundreds
//! of frames) and only the first `l` coefficients are kept, so a `L × l` matrix product
//! beats a fast transform and is exact to reason about.

/// `L × l` row-major: entry (t, j) = s_j cos(π (t + ½) j / L), s_0 = √(1/L), s_j = √(2/L).
/// Columns are orthonormal, so truncating them is an orthogonal projection.
pub fn basis(len: usize, keep: usize) -> Vec<f64> {
    let keep = keep.min(len);
    let mut d = vec![0.0; len * keep];
    let n = len as f64;
    for t in 0..len {
        for j in 0..keep {
            let s = if j == 0 {
                (1.0 / n).sqrt()
            } else {
                (2.0 / n).sqrt()
            };
            d[t * keep + j] = s * (std::f64::consts::PI * (t as f64 + 0.5) * j as f64 / n).cos();
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_orthonormal_and_match_the_definition() {
        for len in [1, 2, 7, 64] {
            let d = basis(len, len);
            for a in 0..len {
                for b in 0..len {
                    let dot: f64 = (0..len).map(|t| d[t * len + a] * d[t * len + b]).sum();
                    let want = if a == b { 1.0 } else { 0.0 };
                    assert!((dot - want).abs() < 1e-12, "len {len} ({a},{b}) {dot}");
                }
            }
        }
        // A constant signal has only a DC coefficient, √L times its value.
        let d = basis(8, 3);
        let c: Vec<f64> = (0..3)
            .map(|j| (0..8).map(|t| 2.0 * d[t * 3 + j]).sum())
            .collect();
        assert!((c[0] - 2.0 * 8f64.sqrt()).abs() < 1e-12);
        assert!(c[1].abs() < 1e-12 && c[2].abs() < 1e-12);
    }
}
