//! The multiscale lifting scheme of Tournier et al. 2009 for trajectories (positions and
//! orientations): dyadic subsampling, each odd sample predicted by interpolating its even
//! neighbours — positions with the cubic (4-point Deslauriers–Dubuc) rule, orientations in
//! the tangent space at the nearest neighbour (log, interpolate, exp) — and only the detail
//! (what the prediction missed) kept.
//!
//! Coding is closed loop, coarse to fine: the coarsest samples are sent as differences from
//! the previous one, then every level's details, each predicted from samples *as decoded*.
//! So a sample's error is its own detail's quantisation error (or the whole detail when it
//! is dropped), never the sum of the levels above it. The caller decides what each detail
//! becomes through a `quantise` function: that is where steps and dropping live.

use nalgebra::{UnitQuaternion, Vector3};

use crate::motion::rotation::{exp, log};

/// A space trajectories live in: how to predict a sample from its neighbours and what a
/// detail is.
pub trait Space {
    type Sample: Copy;
    /// The sample at the middle of `at` (`None` where a neighbour is past the chunk's
    /// ends), from the samples at relative positions −3, −1, +1, +3.
    fn predict(at: [Option<Self::Sample>; 4]) -> Self::Sample;
    /// The detail that turns `predicted` into `actual`.
    fn detail(predicted: &Self::Sample, actual: &Self::Sample) -> Vector3<f64>;
    /// `predicted` corrected by `detail`.
    fn apply(predicted: &Self::Sample, detail: &Vector3<f64>) -> Self::Sample;
}

/// Points in 3-D: cubic interpolation, details are differences.
pub struct Positions;

impl Space for Positions {
    type Sample = Vector3<f64>;

    fn predict(at: [Option<Vector3<f64>>; 4]) -> Vector3<f64> {
        match at {
            [Some(a), Some(b), Some(c), Some(d)] => (9.0 * (b + c) - a - d) / 16.0,
            [_, Some(b), Some(c), _] => (b + c) / 2.0,
            [Some(a), Some(b), None, _] => 1.5 * b - 0.5 * a,
            [_, Some(b), None, _] => b,
            [_, None, Some(c), _] => c,
            _ => Vector3::zeros(),
        }
    }

    fn detail(predicted: &Vector3<f64>, actual: &Vector3<f64>) -> Vector3<f64> {
        actual - predicted
    }

    fn apply(predicted: &Vector3<f64>, detail: &Vector3<f64>) -> Vector3<f64> {
        predicted + detail
    }
}

/// Orientations: the neighbours mapped to the tangent space at the nearer left one,
/// interpolated there as points, mapped back; details are rotation vectors.
pub struct Orientations;

impl Space for Orientations {
    type Sample = UnitQuaternion<f64>;

    fn predict(at: [Option<UnitQuaternion<f64>>; 4]) -> UnitQuaternion<f64> {
        let Some(base) = at[1].or(at[2]) else {
            return UnitQuaternion::identity();
        };
        let inv = base.inverse();
        let tangent = at.map(|q| q.map(|q| log(&(inv * q))));
        base * exp(&Positions::predict(tangent))
    }

    fn detail(predicted: &UnitQuaternion<f64>, actual: &UnitQuaternion<f64>) -> Vector3<f64> {
        log(&(predicted.inverse() * actual))
    }

    fn apply(predicted: &UnitQuaternion<f64>, detail: &Vector3<f64>) -> UnitQuaternion<f64> {
        predicted * exp(detail)
    }
}

/// The stride between a chunk's coarsest samples (a power of two, at most `max_stride`, so
/// that `frames` samples have at least two coarse ones when they can).
pub fn coarsest_stride(frames: usize, max_stride: usize) -> usize {
    let mut s = 1;
    while s * 2 <= max_stride && s * 2 < frames {
        s *= 2;
    }
    s
}

/// The order samples are coded in: the coarse ones (every `stride`-th, in time order), then
/// each level's odd samples, coarse to fine.
pub fn coding_order(frames: usize, stride: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..frames).step_by(stride.max(1)).collect();
    let mut h = stride / 2;
    while h >= 1 {
        order.extend((h..frames).step_by(2 * h));
        h /= 2;
    }
    order
}

/// Code a trajectory closed loop: `details[i]` is the detail of sample `coding_order[i]`
/// (the coarse samples' relative to the previous coarse one, or to `S::predict` of nothing
/// for the first), given to `quantise`, whose answer is what the decoder will add. Returns
/// the decoded samples. With `samples = None` (decoding), details come from `quantise`'s
/// answer to a zero detail.
pub fn code<S: Space>(
    frames: usize,
    stride: usize,
    samples: Option<&[S::Sample]>,
    mut quantise: impl FnMut(usize, Vector3<f64>) -> Vector3<f64>,
) -> Vec<S::Sample> {
    let mut out: Vec<Option<S::Sample>> = vec![None; frames];
    let detail =
        |pred: &S::Sample, t: usize| samples.map_or(Vector3::zeros(), |s| S::detail(pred, &s[t]));
    let mut previous: Option<S::Sample> = None;
    let stride = stride.max(1);
    for t in (0..frames).step_by(stride) {
        let pred = match previous {
            Some(p) => p,
            None => S::predict([None; 4]),
        };
        let d = quantise(t, detail(&pred, t));
        let v = S::apply(&pred, &d);
        out[t] = Some(v);
        previous = Some(v);
    }
    let mut h = stride / 2;
    while h >= 1 {
        for t in (h..frames).step_by(2 * h) {
            let at = |k: isize| -> Option<S::Sample> {
                let i = t as isize + k * h as isize;
                (0..frames as isize)
                    .contains(&i)
                    .then(|| out[i as usize])
                    .flatten()
            };
            let pred = S::predict([at(-3), at(-1), at(1), at(3)]);
            let d = quantise(t, detail(&pred, t));
            out[t] = Some(S::apply(&pred, &d));
        }
        h /= 2;
    }
    out.into_iter()
        .map(|v| v.expect("every sample is coded at some level"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_sample_is_coded_once() {
        for frames in [1, 2, 3, 7, 16, 17, 60, 129] {
            for max in [1, 8, 32] {
                let s = coarsest_stride(frames, max);
                let mut o = coding_order(frames, s);
                assert_eq!(o.len(), frames);
                o.sort_unstable();
                assert!(o.iter().enumerate().all(|(i, &t)| i == t));
            }
        }
    }

    #[test]
    fn smooth_trajectories_leave_small_details_and_exact_details_give_them_back() {
        let frames = 61;
        let pos: Vec<Vector3<f64>> = (0..frames)
            .map(|t| {
                let x = t as f64 / 10.0;
                Vector3::new(x.sin(), x * x * 0.1, (0.7 * x).cos())
            })
            .collect();
        let rot: Vec<UnitQuaternion<f64>> = pos
            .iter()
            .map(|p| UnitQuaternion::from_scaled_axis(*p * 0.8))
            .collect();
        let s = coarsest_stride(frames, 16);
        // Lossless: decoded equals input.
        let mut fine = Vec::new();
        let back = code::<Positions>(frames, s, Some(&pos), |t, d| {
            if t % 2 == 1 {
                fine.push(d.norm());
            }
            d
        });
        assert!(back.iter().zip(&pos).all(|(a, b)| (a - b).norm() < 1e-12));
        // The finest details of a smooth curve are tiny against its motion per frame (about
        // 0.1 here): at the ends, where the rule falls back to fewer neighbours, and far
        // smaller inside, where the cubic rule applies.
        let largest = fine.iter().cloned().fold(0.0, f64::max);
        assert!(largest < 1e-2, "{largest}");
        let inside = fine[2..fine.len() - 2].iter().cloned().fold(0.0, f64::max);
        assert!(inside < 1e-4, "{inside}");
        let mut fine = Vec::new();
        let back = code::<Orientations>(frames, s, Some(&rot), |t, d| {
            if t % 2 == 1 {
                fine.push(d.norm());
            }
            d
        });
        assert!(back.iter().zip(&rot).all(|(a, b)| a.angle_to(b) < 1e-12));
        assert!(fine.iter().cloned().fold(0.0, f64::max) < 1e-2);
        assert!(fine[2..fine.len() - 2].iter().cloned().fold(0.0, f64::max) < 1e-4);
    }

    #[test]
    fn closed_loop_errors_do_not_add_up_across_levels() {
        let frames = 64;
        let pos: Vec<Vector3<f64>> = (0..frames)
            .map(|t| Vector3::new((t as f64 * 0.37).sin() * 50.0, t as f64, 0.0))
            .collect();
        let step = 0.5;
        let q = |_: usize, d: Vector3<f64>| d.map(|c| (c / step).round() * step);
        let back = code::<Positions>(frames, 32, Some(&pos), q);
        for (a, b) in back.iter().zip(&pos) {
            assert!((a - b).amax() <= step / 2.0 + 1e-9);
        }
        // The decoder, given the same quantised details, decodes the same samples.
        let mut sent = Vec::new();
        code::<Positions>(frames, 32, Some(&pos), |t, d| {
            let v = q(t, d);
            sent.push(v);
            v
        });
        let mut it = sent.into_iter();
        let again = code::<Positions>(frames, 32, None, |_, _| it.next().unwrap());
        assert_eq!(again, back);
    }
}
