//! Gaps in, full matrices out: transforms need every sample, so missing samples are filled
//! before coding (and masked again after decoding).

/// Per-sample validity of `frames × points × 3` data (NaN = missing).
pub fn mask(data: &[f32]) -> Vec<bool> {
    data.chunks_exact(3).map(|p| !p[0].is_nan()).collect()
}

/// [`mask`], or `None` if every sample is present.
pub fn validity(data: &[f32]) -> Option<Vec<bool>> {
    let v = mask(data);
    v.iter().any(|x| !x).then_some(v)
}

/// Fill missing samples by linear interpolation along each point's trajectory, holding the
/// nearest valid sample before the first and after the last; a point never seen is zero.
/// Smooth fills cost transform codecs almost nothing, and decoded values there are masked.
pub fn fill(data: &[f32], points: usize) -> Vec<f32> {
    let mut out = data.to_vec();
    if points == 0 {
        return out;
    }
    let w = points * 3;
    let frames = data.len() / w;
    for p in 0..points {
        let at = |f: usize| f * w + p * 3;
        let mut last_valid: Option<usize> = None;
        let mut f = 0;
        while f < frames {
            if !out[at(f)].is_nan() {
                last_valid = Some(f);
                f += 1;
                continue;
            }
            let gap_start = f;
            while f < frames && out[at(f)].is_nan() {
                f += 1;
            }
            let next_valid = (f < frames).then_some(f);
            for g in gap_start..f {
                for k in 0..3 {
                    out[at(g) + k] = match (last_valid, next_valid) {
                        (Some(a), Some(b)) => {
                            let t = (g - a) as f32 / (b - a) as f32;
                            let (va, vb) = (out[at(a) + k], out[at(b) + k]);
                            va + (vb - va) * t
                        }
                        (Some(a), None) => out[at(a) + k],
                        (None, Some(b)) => out[at(b) + k],
                        (None, None) => 0.0,
                    };
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_holds_and_zeroes() {
        let n = f32::NAN;
        // Two points, four frames: point 0 has a middle gap and a trailing gap, point 1 none.
        let d = [
            0.0, 0.0, 0.0, n, n, n, //
            n, n, n, n, n, n, //
            2.0, 4.0, 6.0, n, n, n, //
            n, n, n, n, n, n,
        ];
        let f = fill(&d, 2);
        assert_eq!(&f[6..9], &[1.0, 2.0, 3.0]);
        assert_eq!(&f[18..21], &[2.0, 4.0, 6.0]);
        assert_eq!(&f[3..6], &[0.0, 0.0, 0.0]);
        assert_eq!(
            validity(&d).unwrap(),
            vec![true, false, false, false, true, false, false, false]
        );
        assert!(validity(&[1.0, 2.0, 3.0]).is_none());
    }
}
