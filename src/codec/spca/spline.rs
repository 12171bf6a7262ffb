//! Adaptive key frames of one scalar trajectory and the cubic curve through them (Liu &
//! McMillan 2006, §4.2): start with 4 evenly spaced keys, insert the midpoint of every
//! interval where the curve strays more than a threshold from the trajectory, until none
//! does.
//!
//! The curve is a cubic Hermite spline whose tangents are the mean of the neighbouring
//! secants (one-sided at the ends): the paper says only "cubic spline". A Hermite spline is
//! local — a frame depends on the four keys around it — so inserting a key re-fits only its
//! neighbourhood, and a decoder evaluates it in one pass.
//!
//! Because every inserted key is the midpoint of an interval, the key set is a binary tree
//! over the initial intervals and is coded as one split flag per interval long enough to
//! split ([`code`]); the key values follow as differences from the previous key.
//!
//! Pure math and coding; no I/O.

use crate::codec::entropy::io::Io;
use crate::codec::entropy::{Bit, IntModel};
use crate::codec::measure::quantise;

/// The keys a trajectory of `n` frames starts with: 4 evenly spaced, first and last
/// included (fewer for shorter trajectories).
pub fn initial(n: usize) -> Vec<usize> {
    let mut keys: Vec<usize> = (0..4).map(|j| (j * (n.max(1) - 1) + 1) / 3).collect();
    keys.dedup();
    keys
}

/// Values at every frame `0..n` of the spline through `(at[j], v[j])` (`at` increasing,
/// from 0 to `n − 1`), into `out`.
pub fn evaluate(at: &[usize], v: &[f64], out: &mut [f64]) {
    if at.len() == 1 {
        out.fill(v[0]);
        return;
    }
    for j in 0..at.len() - 1 {
        interval(at, v, j, |f, x| out[f] = x);
    }
    out[at[at.len() - 1]] = v[v.len() - 1];
}

/// The secant of interval `j`.
#[inline]
fn secant(at: &[usize], v: &[f64], j: usize) -> f64 {
    (v[j + 1] - v[j]) / (at[j + 1] - at[j]) as f64
}

/// The tangent at key `j`: the mean of the secants either side, the one secant at the ends.
#[inline]
fn tangent(at: &[usize], v: &[f64], j: usize) -> f64 {
    let last = at.len() - 1;
    if j == 0 {
        secant(at, v, 0)
    } else if j == last {
        secant(at, v, last - 1)
    } else {
        0.5 * (secant(at, v, j - 1) + secant(at, v, j))
    }
}

/// Calls `put(frame, value)` for the frames `at[j]..at[j + 1]` (the first key included, the
/// next one not).
#[inline]
fn interval(at: &[usize], v: &[f64], j: usize, mut put: impl FnMut(usize, f64)) {
    let (a, b) = (at[j], at[j + 1]);
    let h = (b - a) as f64;
    let (p0, p1) = (v[j], v[j + 1]);
    let (m0, m1) = (tangent(at, v, j) * h, tangent(at, v, j + 1) * h);
    put(a, p0);
    for f in a + 1..b {
        let u = (f - a) as f64 / h;
        let (u2, u3) = (u * u, u * u * u);
        let x = (2.0 * u3 - 3.0 * u2 + 1.0) * p0
            + (u3 - 2.0 * u2 + u) * m0
            + (3.0 * u2 - 2.0 * u3) * p1
            + (u3 - u2) * m1;
        put(f, x);
    }
}

/// A trajectory's keys as coded: which frames are keys, and their quantised values.
#[derive(Debug, Clone, PartialEq)]
pub struct Keys {
    pub at: Vec<usize>,
    pub q: Vec<i32>,
}

impl Keys {
    /// The dequantised key values.
    pub fn values(&self, step: f64) -> Vec<f64> {
        self.q.iter().map(|&q| f64::from(q) * step).collect()
    }
}

/// Keys for `x` (one value per frame) such that the spline through their values quantised
/// at `step` is within `threshold` of `x` at every frame between keys (at a key, within
/// `step / 2`).
pub fn fit(x: &[f64], threshold: f64, step: f64) -> Keys {
    let n = x.len();
    let mut is_key = vec![false; n];
    for k in initial(n) {
        is_key[k] = true;
    }
    loop {
        let at: Vec<usize> = (0..n).filter(|&f| is_key[f]).collect();
        let v: Vec<f64> = at
            .iter()
            .map(|&f| f64::from(quantise(x[f] / step)) * step)
            .collect();
        let mut split = false;
        for j in 0..at.len().saturating_sub(1) {
            let (a, b) = (at[j], at[j + 1]);
            if b - a < 2 {
                continue;
            }
            let mut far = false;
            interval(&at, &v, j, |f, y| far |= (y - x[f]).abs() > threshold);
            if far {
                is_key[(a + b) / 2] = true;
                split = true;
            }
        }
        if !split {
            let q = at.iter().map(|&f| quantise(x[f] / step)).collect();
            return Keys { at, q };
        }
    }
}

/// Split-flag contexts by depth below the initial intervals.
const DEPTHS: usize = 8;

/// Adaptive models of one kind of trajectory's keys.
#[derive(Debug, Clone)]
pub struct Models {
    split: [Bit; DEPTHS],
    first: IntModel,
    delta: IntModel,
}

impl Default for Models {
    fn default() -> Self {
        Models {
            split: [Bit::default(); DEPTHS],
            first: IntModel::default(),
            delta: IntModel::default(),
        }
    }
}

/// Code the keys of a trajectory of `n` frames through `io`: `given` when encoding, ignored
/// when decoding; returns the keys (as given, or as decoded).
pub fn code<I: Io>(io: &mut I, m: &mut Models, n: usize, given: Option<&Keys>) -> Keys {
    let mut is_key = vec![false; n];
    if let Some(g) = given {
        for &f in &g.at {
            is_key[f] = true;
        }
    }
    let start = initial(n);
    let mut at = Vec::with_capacity(start.len());
    for w in start.windows(2) {
        at.push(w[0]);
        tree(io, m, &mut is_key, w[0], w[1], 0, &mut at);
    }
    at.push(start[start.len() - 1]);
    let mut q = Vec::with_capacity(at.len());
    let mut previous = 0i32;
    for j in 0..at.len() {
        let v = given.map_or(0, |g| g.q[j]);
        let got = if j == 0 {
            io.int(&mut m.first, v)
        } else {
            previous.saturating_add(io.int(&mut m.delta, v.wrapping_sub(previous)))
        };
        q.push(got);
        previous = got;
    }
    Keys { at, q }
}

/// The split flags of interval `a..b` and below it, in depth-first order; pushes the keys
/// strictly inside it onto `at` in increasing order.
fn tree<I: Io>(
    io: &mut I,
    m: &mut Models,
    is_key: &mut [bool],
    a: usize,
    b: usize,
    depth: usize,
    at: &mut Vec<usize>,
) {
    if b - a < 2 {
        return;
    }
    let mid = (a + b) / 2;
    let split = io.bit(&mut m.split[depth.min(DEPTHS - 1)], is_key[mid]);
    if split {
        is_key[mid] = true;
        tree(io, m, is_key, a, mid, depth + 1, at);
        at.push(mid);
        tree(io, m, is_key, mid, b, depth + 1, at);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::entropy::{Decoder, Encoder};

    #[test]
    fn starts_with_four_evenly_spaced_keys() {
        assert_eq!(initial(10), vec![0, 3, 6, 9]);
        assert_eq!(initial(100), vec![0, 33, 66, 99]);
        assert_eq!(initial(3), vec![0, 1, 2]);
        assert_eq!(initial(1), vec![0]);
    }

    #[test]
    fn interpolates_keys_and_lines_exactly() {
        let at = [0, 4, 9];
        let v = [1.0, 3.0, 5.5];
        let mut out = vec![0.0; 10];
        evaluate(&at, &v, &mut out);
        assert_eq!((out[0], out[4], out[9]), (1.0, 3.0, 5.5));
        // Equal secants make the spline the line through them.
        let mut line = vec![0.0; 9];
        evaluate(&[0, 3, 8], &[0.0, 3.0, 8.0], &mut line);
        for (f, y) in line.iter().enumerate() {
            assert!((y - f as f64).abs() < 1e-12, "{f}: {y}");
        }
    }

    #[test]
    fn fits_within_the_threshold_with_few_keys_where_smooth() {
        // Smooth for 300 frames, then a fast wiggle for 100.
        let x: Vec<f64> = (0..400)
            .map(|f| {
                let t = f as f64 / 120.0;
                if f < 300 {
                    50.0 * t.sin()
                } else {
                    50.0 * t.sin() + 20.0 * (t * 40.0).sin()
                }
            })
            .collect();
        let (threshold, step) = (0.5, 0.25);
        let keys = fit(&x, threshold, step);
        let mut y = vec![0.0; x.len()];
        evaluate(&keys.at, &keys.values(step), &mut y);
        for f in 0..x.len() {
            let tol = if keys.at.contains(&f) {
                step / 2.0
            } else {
                threshold
            };
            assert!((y[f] - x[f]).abs() <= tol + 1e-9, "frame {f}");
        }
        let smooth = keys.at.iter().filter(|&&f| f < 290).count();
        let wiggly = keys.at.iter().filter(|&&f| f >= 300).count();
        assert!(smooth < 15 && wiggly > 3 * smooth, "{smooth} vs {wiggly}");
    }

    #[test]
    fn the_coded_keys_decode_to_the_same() {
        let mut m = Models::default();
        let mut enc = Encoder::new();
        let trajectories: Vec<Vec<f64>> = (1..5)
            .map(|k| {
                (0..157)
                    .map(|f| (f as f64 * 0.05 * k as f64).cos() * 30.0)
                    .collect()
            })
            .collect();
        let fitted: Vec<Keys> = trajectories.iter().map(|x| fit(x, 0.3, 0.2)).collect();
        for k in &fitted {
            assert_eq!(&code(&mut enc, &mut m, 157, Some(k)), k);
        }
        let bytes = enc.finish();
        let (mut dec, mut m) = (Decoder::new(&bytes), Models::default());
        for k in &fitted {
            assert_eq!(&code(&mut dec, &mut m, 157, None), k);
        }
    }
}
