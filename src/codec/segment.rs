//! Motion segmentation by probabilistic PCA (Barbič et al., *Segmenting Motion Capture Data
//! into Distinct Behaviors*, GI 2004), as Liu & McMillan 2006 use it to cut a take into
//! segments that each suit one PCA model (and as `mdtt`'s paper uses it for its best clips).
//!
//! From a segment's start, the first `K` frames are modelled as a Gaussian: their mean and
//! the principal components covering `τ` of their variance, every discarded direction given
//! the average discarded variance `σ²` (the PPCA covariance `C = U Λ Uᵀ + σ²(I − U Uᵀ)`).
//! `H(K)` is the mean Mahalanobis distance under that model of the next `T` frames. `K` grows
//! by `Δ`; `H` falls while the coming frames resemble the modelled ones and rises when they
//! do not. A cut goes at a peak of `H` that rises more than `R` above the lowest `H` since
//! the segment began; the next segment starts there.
//!
//! `H` is a Mahalanobis distance, so it does not depend on units (scaling every coordinate by
//! `c` scales the covariance by `c²`): `R` is unit-free. It does grow with the dimension
//! (under the model, `E[H]` is about the number of coordinates), so the paper's `R = 500`
//! belongs to its pose vectors; [`Params::at`] keeps it and lets callers say otherwise.
//!
//! Pure math over frames of numbers.

use std::ops::Range;

use nalgebra::{DMatrix, DVector};

use super::linalg::{add_outer_products, dot, leading_eigen};

/// The segmentation's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// `K`: the frames the first model of a segment is fitted to (also its shortest length).
    pub first: usize,
    /// `T`: the frames whose distance to the model is averaged.
    pub window: usize,
    /// `Δ`: the frames added to the model per step.
    pub step: usize,
    /// `τ`: the share of the variance the kept components cover.
    pub variance: f64,
    /// `R`: how far a peak of `H` must rise above the valley before it to cut.
    pub rise: f64,
}

impl Params {
    /// The paper's values (K = 200, T = 150, Δ = 10 at 120 fps; τ = 0.95; R = 500) with the
    /// frame counts scaled to `fps`.
    pub fn at(fps: f64) -> Params {
        let frames = |n: f64| ((n * fps / 120.0).round() as usize).max(1);
        Params {
            first: frames(200.0).max(2),
            window: frames(150.0),
            step: frames(10.0),
            variance: 0.95,
            rise: 500.0,
        }
    }
}

/// Where `data` (`frames × width`, row-major; no gaps) should be cut: each segment's first
/// frame after frame 0, increasing.
pub fn cuts(data: &[f64], width: usize, p: &Params) -> Vec<usize> {
    let frames = data.len().checked_div(width).unwrap_or(0);
    let mut out = Vec::new();
    let mut start = 0;
    while let Some(cut) = next_cut(data, width, frames, start, p) {
        out.push(cut);
        start = cut;
    }
    out
}

/// The segments `cuts` (increasing, inside `0..frames`) make of `frames` frames, each longer
/// than `longest` split evenly into the fewest pieces no longer than it: what codecs that
/// code a segment per chunk (`spca`) or clip (`mdtt`'s adaptive clips) code.
pub fn pieces(cuts: &[usize], frames: usize, longest: usize) -> Vec<Range<usize>> {
    let mut bounds = vec![0];
    bounds.extend_from_slice(cuts);
    bounds.push(frames);
    let mut out = Vec::new();
    for w in bounds.windows(2) {
        let (a, b) = (w[0], w[1]);
        let parts = (b - a).div_ceil(longest.max(1)).max(1);
        for i in 0..parts {
            out.push(a + (b - a) * i / parts..a + (b - a) * (i + 1) / parts);
        }
    }
    out
}

/// `H(K)` for each `K` tried from a segment starting at `start` (for tests and plots).
pub fn distances(data: &[f64], width: usize, start: usize, p: &Params) -> Vec<(usize, f64)> {
    let frames = data.len().checked_div(width).unwrap_or(0);
    let mut out = Vec::new();
    scan(data, width, frames, start, p, |k, h| {
        out.push((k, h));
        false
    });
    out
}

/// The first cut after `start`, if any.
fn next_cut(data: &[f64], width: usize, frames: usize, start: usize, p: &Params) -> Option<usize> {
    let (mut before, mut last) = (f64::NAN, (0, f64::NAN));
    let mut valley = f64::INFINITY;
    let mut cut = None;
    scan(data, width, frames, start, p, |k, h| {
        // `last` is a peak when it rose from `before` and `h` is no higher.
        let peak = last.1 > before && h <= last.1;
        if peak && last.1 - valley > p.rise {
            cut = Some(last.0);
            return true;
        }
        valley = valley.min(h);
        before = last.1;
        last = (k, h);
        false
    });
    cut
}

/// Calls `visit(start + K, H(K))` for `K = first, first + Δ, …` while `K + T` frames remain,
/// until `visit` returns true.
fn scan(
    data: &[f64],
    width: usize,
    frames: usize,
    start: usize,
    p: &Params,
    mut visit: impl FnMut(usize, f64) -> bool,
) {
    let (first, window, step) = (p.first.max(2), p.window.max(1), p.step.max(1));
    if width == 0 || start + first + window > frames {
        return;
    }
    let row = |t: usize| &data[t * width..(t + 1) * width];
    let mut sum = DVector::<f64>::zeros(width);
    let mut outer = DMatrix::<f64>::zeros(width, width);
    let add = |from: usize, to: usize, sum: &mut DVector<f64>, outer: &mut DMatrix<f64>| {
        let block = DMatrix::from_fn(width, to - from, |i, j| row(from + j)[i]);
        add_outer_products(outer, block.as_view());
        for j in from..to {
            for (s, v) in sum.iter_mut().zip(row(j)) {
                *s += v;
            }
        }
    };
    add(start, start + first, &mut sum, &mut outer);
    let mut k = first;
    let mut d = vec![0.0; width];
    while start + k + window <= frames {
        let model = Model::fit(&sum, &outer, k, p.variance);
        let mut h = 0.0;
        for t in start + k..start + k + window {
            for ((di, x), m) in d.iter_mut().zip(row(t)).zip(model.mean.iter()) {
                *di = x - m;
            }
            h += model.distance(&d);
        }
        if visit(start + k, h / window as f64) {
            return;
        }
        let next = (k + step).min(frames - start);
        add(start + k, start + next, &mut sum, &mut outer);
        k = next;
    }
}

/// A PPCA model of some frames.
struct Model {
    mean: DVector<f64>,
    /// Kept components, as columns.
    basis: DMatrix<f64>,
    /// Their variances.
    lambda: Vec<f64>,
    /// The variance of every discarded direction.
    sigma2: f64,
}

impl Model {
    /// The model of `n` frames with coordinate sums `sum` and outer-product sums `outer`.
    fn fit(sum: &DVector<f64>, outer: &DMatrix<f64>, n: usize, variance: f64) -> Model {
        let width = sum.len();
        let mean = sum / n as f64;
        let mut cov = outer / n as f64;
        cov.ger(-1.0, &mean, &mean, 1.0);
        let (vectors, values) = leading_eigen(&cov, width);
        let total: f64 = values.iter().sum();
        // A floor so a coordinate that never moves (or a rank-deficient model) does not make
        // every distance infinite.
        let floor = 1e-9 * (total / width as f64).max(1e-300);
        let mut kept = 0;
        let mut covered = 0.0;
        while kept < width && covered < variance * total {
            covered += values[kept];
            kept += 1;
        }
        let kept = kept.min(width.saturating_sub(1)).max(1.min(width));
        let rest = width - kept;
        let sigma2 = if rest > 0 {
            (values[kept..].iter().sum::<f64>() / rest as f64).max(floor)
        } else {
            floor
        };
        Model {
            mean,
            basis: vectors.columns(0, kept).clone_owned(),
            lambda: values[..kept].iter().map(|v| v.max(floor)).collect(),
            sigma2,
        }
    }

    /// `dᵀ C⁻¹ d` for the PPCA covariance: the kept components weighed by their own
    /// variance, the rest by `σ²`.
    fn distance(&self, d: &[f64]) -> f64 {
        let width = d.len();
        let basis = self.basis.as_slice();
        let all = dot(d, d);
        let mut along = 0.0;
        let mut inside = 0.0;
        for (i, l) in self.lambda.iter().enumerate() {
            let c = dot(&basis[i * width..(i + 1) * width], d);
            along += c * c / l;
            inside += c * c;
        }
        along + (all - inside).max(0.0) / self.sigma2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_segments_are_split_evenly() {
        assert_eq!(pieces(&[], 10, 100), vec![0..10]);
        assert_eq!(pieces(&[4], 10, 100), vec![0..4, 4..10]);
        let s = pieces(&[], 2 * 4096 + 1, 4096);
        assert_eq!(s.len(), 3);
        assert!(s.iter().all(|r| r.len() <= 4096));
        assert_eq!(s.last().unwrap().end, 2 * 4096 + 1);
    }
    use crate::rng::Rng;

    /// `frames` frames of `width` coordinates moving in a few directions of their own.
    fn behaviour(frames: usize, width: usize, seed: u64, speed: f64) -> Vec<f64> {
        let mut rng = Rng::new(seed);
        let dirs: Vec<Vec<f64>> = (0..3)
            .map(|_| (0..width).map(|_| 2.0 * rng.unit() - 1.0).collect())
            .collect();
        let offset: Vec<f64> = (0..width).map(|_| 3.0 * (2.0 * rng.unit() - 1.0)).collect();
        let mut out = Vec::with_capacity(frames * width);
        for t in 0..frames {
            let s = t as f64 * speed;
            let w = [s.sin(), (1.7 * s).cos(), (0.6 * s + 1.0).sin()];
            for i in 0..width {
                let v: f64 = (0..3).map(|d| w[d] * dirs[d][i]).sum();
                out.push(offset[i] + v + 0.01 * (2.0 * rng.unit() - 1.0));
            }
        }
        out
    }

    #[test]
    fn a_change_of_behaviour_is_cut_near_where_it_happens() {
        let width = 12;
        let p = Params::at(120.0);
        let mut data = behaviour(700, width, 1, 0.05);
        data.extend(behaviour(600, width, 2, 0.11));
        let cuts = cuts(&data, width, &p);
        assert!(!cuts.is_empty(), "no cut");
        assert!(
            cuts.iter().any(|&c| c.abs_diff(700) <= 60),
            "cuts {cuts:?}, the change is at 700"
        );
        // One behaviour throughout: no cut.
        let same = behaviour(1300, width, 1, 0.05);
        assert!(super::cuts(&same, width, &p).is_empty());
    }

    #[test]
    fn distances_do_not_depend_on_units() {
        let width = 6;
        let p = Params::at(60.0);
        let data = behaviour(400, width, 3, 0.1);
        let scaled: Vec<f64> = data.iter().map(|v| v * 1000.0).collect();
        let (a, b) = (
            distances(&data, width, 0, &p),
            distances(&scaled, width, 0, &p),
        );
        assert_eq!(a.len(), b.len());
        assert!(!a.is_empty());
        for ((ka, ha), (kb, hb)) in a.iter().zip(&b) {
            assert_eq!(ka, kb);
            assert!((ha - hb).abs() <= 1e-6 * ha.abs().max(1.0), "{ha} vs {hb}");
        }
    }

    #[test]
    fn frame_counts_follow_the_frame_rate() {
        assert_eq!(Params::at(120.0).first, 200);
        assert_eq!(Params::at(30.0).first, 50);
        assert_eq!(Params::at(30.0).window, 38);
        assert!(Params::at(1.0).step >= 1);
        // Too short to model: no cut, no panic.
        assert!(cuts(&[0.0; 30], 3, &Params::at(120.0)).is_empty());
        assert!(cuts(&[], 0, &Params::at(120.0)).is_empty());
    }
}
