//! Error measurement inside encoders' parameter searches: the same quantities as
//! `motion::metrics`, without allocating, in the take's own units.

/// Euclidean distance per sample between `a` and `b` (`… × 3`), skipping missing samples.
/// Returns (max, mean) over the present samples.
pub fn max_mean(a: &[f32], b: &[f32], valid: Option<&[bool]>) -> (f64, f64) {
    let (mut max, mut sum, mut n) = (0.0f64, 0.0f64, 0usize);
    for (i, (pa, pb)) in a.chunks_exact(3).zip(b.chunks_exact(3)).enumerate() {
        if valid.is_some_and(|v| !v[i]) {
            continue;
        }
        let d = sample_distance(pa, pb);
        max = max.max(d);
        sum += d;
        n += 1;
    }
    (max, if n == 0 { 0.0 } else { sum / n as f64 })
}

#[inline]
pub fn sample_distance(a: &[f32], b: &[f32]) -> f64 {
    let dx = f64::from(a[0]) - f64::from(b[0]);
    let dy = f64::from(a[1]) - f64::from(b[1]);
    let dz = f64::from(a[2]) - f64::from(b[2]);
    let d = (dx * dx + dy * dy + dz * dz).sqrt();
    if d.is_nan() {
        f64::INFINITY
    } else {
        d
    }
}

/// Round to the nearest integer, halves away from zero, saturating at the i32 range: what
/// every quantiser here uses. `f64::round` is a libm call on baseline x86-64; the cast
/// truncates in one instruction, and quantisers run millions of times per parameter search.
#[inline]
pub fn quantise(x: f64) -> i32 {
    (x + 0.5f64.copysign(x)) as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantise_rounds_half_away_and_saturates() {
        assert_eq!(quantise(2.5), 3);
        assert_eq!(quantise(-2.5), -3);
        assert_eq!(quantise(2.49), 2);
        assert_eq!(quantise(-0.2), 0);
        assert_eq!(quantise(1e20), i32::MAX);
        assert_eq!(quantise(f64::NAN), 0);
    }
}
