//! One segment's PCA model (Liu & McMillan 2006, §4.1): the mean of its normalised pose
//! vectors and the `k` leading principal components, `k` the fewest that leave every point
//! within the PCA tolerance (foot points within a tighter one). Stored quantised in the
//! header; both sides pose and project with the dequantised values.

use nalgebra::DMatrix;

use crate::codec::entropy::io::Io;
use crate::codec::entropy::IntModel;
use crate::codec::error::{malformed, Result};
use crate::codec::linalg::{add_outer_products, leading_eigen, LeastSquares};
use crate::codec::measure::quantise;
use crate::codec::simd::dispatch;

/// Finest basis precision the format allows, fractional bits.
pub const MAX_BITS: u8 = 20;

/// A segment's model as stored: mean and components, dequantised.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    pub mean: Vec<f64>,
    /// Column `j` holds multiples of `2^-bits[j]`.
    pub bits: Vec<u8>,
    /// Column-major, `k` columns of the pose width.
    pub basis: Vec<f64>,
}

impl Model {
    pub fn width(&self) -> usize {
        self.mean.len()
    }

    pub fn k(&self) -> usize {
        self.bits.len()
    }

    /// The pose of coefficients `c`: `mean + Σ_j c_j · column_j`, into `out`.
    pub fn pose(&self, c: &[f64], out: &mut [f64]) {
        combine(&self.mean, &self.basis, c, out);
    }

    /// The coefficients of poses `rows` (`frames × width`) that come closest to them
    /// (`k × frames`): least squares, since quantised components are not quite orthonormal
    /// and a plain projection would pick up the leading components' share through a coarse
    /// column's rounding.
    pub fn coefficients(&self, rows: &[f64]) -> DMatrix<f64> {
        let w = self.width();
        let frames = rows.len() / w;
        let b = DMatrix::from_column_slice(w, self.k(), &self.basis);
        let y = DMatrix::from_fn(w, frames, |i, f| rows[f * w + i] - self.mean[i]);
        LeastSquares::new(b).solve(y.as_view())
    }

    /// Code the model through `io` (`given` when encoding): `k`, each column's precision,
    /// the mean at `mean_step`, the columns. `width` is the pose width.
    pub fn code<I: Io>(
        io: &mut I,
        m: &mut Models,
        width: usize,
        mean_step: f64,
        given: Option<&Model>,
    ) -> Result<Model> {
        let k = io.raw(given.map_or(0, |g| g.k() as u32), 16) as usize;
        if k > width {
            return Err(malformed(format!(
                "spca model of {k} components for poses of {width} values"
            )));
        }
        let mut bits = Vec::with_capacity(k);
        for j in 0..k {
            let b = io.raw(given.map_or(0, |g| u32::from(g.bits[j])), 5) as u8;
            if b == 0 || b > MAX_BITS {
                return Err(malformed(format!("spca basis precision of {b} bits")));
            }
            bits.push(b);
        }
        let mut mean = Vec::with_capacity(width);
        for i in 0..width {
            // Each point's coordinates as differences from the same coordinate of the
            // previous point: bodies are compact.
            let prev = if i >= 3 {
                previous_of(&mean, i, mean_step)
            } else {
                0
            };
            let v = given.map_or(0, |g| quantise(g.mean[i] / mean_step).wrapping_sub(prev));
            let q = prev.saturating_add(io.int(&mut m.mean, v));
            mean.push(f64::from(q) * mean_step);
        }
        let mut basis = Vec::with_capacity(width * k);
        for (j, &b) in bits.iter().enumerate() {
            let scale = f64::from(1u32 << b);
            for i in 0..width {
                let v = given.map_or(0, |g| quantise(g.basis[j * width + i] * scale));
                let q = io.int(&mut m.basis[usize::from(b)], v);
                basis.push(f64::from(q) / scale);
            }
        }
        Ok(Model { mean, bits, basis })
    }
}

/// The quantised mean coordinate three before `i` (the same axis of the previous point).
fn previous_of(mean: &[f64], i: usize, step: f64) -> i32 {
    quantise(mean[i - 3] / step)
}

/// The adaptive models of the header's model block.
pub struct Models {
    mean: IntModel,
    basis: Vec<IntModel>,
}

impl Default for Models {
    fn default() -> Self {
        Models {
            mean: IntModel::default(),
            basis: vec![IntModel::default(); usize::from(MAX_BITS) + 1],
        }
    }
}

/// A segment's principal components before quantisation: what the encoder chooses `k` and
/// the precisions from.
pub struct Analysis {
    pub mean: Vec<f64>,
    /// All components, column-major, largest variance first.
    pub vectors: DMatrix<f64>,
    /// Their variances (per frame).
    pub variances: Vec<f64>,
}

impl Analysis {
    /// PCA of `rows` (`frames × width`, row-major).
    pub fn of(rows: &[f64], width: usize) -> Analysis {
        let frames = rows.len() / width;
        let mut mean = vec![0.0; width];
        for r in rows.chunks_exact(width) {
            for (m, v) in mean.iter_mut().zip(r) {
                *m += v;
            }
        }
        mean.iter_mut().for_each(|m| *m /= frames.max(1) as f64);
        let centred = DMatrix::from_fn(width, frames, |i, f| rows[f * width + i] - mean[i]);
        let mut c = DMatrix::zeros(width, width);
        add_outer_products(&mut c, centred.as_view());
        let (vectors, values) = leading_eigen(&c, width);
        let variances = values.iter().map(|v| v / frames.max(1) as f64).collect();
        Analysis {
            mean,
            vectors,
            variances,
        }
    }

    /// The model of the first `k` components, quantised: the mean at `mean_step`, column `j`
    /// at the precision that moves a pose by about `basis_error` at its coefficients'
    /// typical size (an error δ in column j moves a pose by δ·|c_j|, and |c_j| is about the
    /// component's standard deviation).
    pub fn model(&self, k: usize, mean_step: f64, basis_error: f64) -> Model {
        let width = self.mean.len();
        let bits: Vec<u8> = self.variances[..k]
            .iter()
            .map(|&v| {
                let step = basis_error / v.sqrt().max(1e-300);
                (-step.log2()).ceil().clamp(1.0, f64::from(MAX_BITS)) as u8
            })
            .collect();
        let mean = self
            .mean
            .iter()
            .map(|m| f64::from(quantise(m / mean_step)) * mean_step)
            .collect();
        let mut basis = Vec::with_capacity(width * k);
        for (j, &b) in bits.iter().enumerate() {
            let scale = f64::from(1u32 << b);
            basis.extend(
                self.vectors
                    .column(j)
                    .iter()
                    .map(|v| f64::from(quantise(v * scale)) / scale),
            );
        }
        Model { mean, bits, basis }
    }
}

/// How far a segment's poses stray from their projection on the first `k` components, for
/// growing `k`, computed as far as asked and kept: every trial of rate control asks for the
/// fewest components within its tolerance, and each `k` costs a pass over the segment.
pub struct Truncation {
    width: usize,
    /// Poses less the mean less their projection on the components so far.
    residual: Vec<f64>,
    /// `errors[k]`: the largest `distance / share` of any point with `k` components.
    errors: Vec<f64>,
    share: Vec<f64>,
}

impl Truncation {
    /// For poses `rows` (`frames × width`) under `a`, point `p`'s distance counted as
    /// `distance / share[p]` (feet have a smaller share of the tolerance).
    pub fn new(a: &Analysis, rows: &[f64], share: &[f64]) -> Truncation {
        let width = a.mean.len();
        let residual = rows
            .chunks_exact(width)
            .flat_map(|x| x.iter().zip(&a.mean).map(|(x, m)| x - m))
            .collect();
        let mut t = Truncation {
            width,
            residual,
            errors: Vec::new(),
            share: share.to_vec(),
        };
        t.errors.push(t.error());
        t
    }

    fn error(&self) -> f64 {
        self.residual
            .chunks_exact(3)
            .zip(self.share.iter().cycle())
            .map(|(d, s)| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() / s)
            .fold(0.0, f64::max)
    }

    /// The fewest components of `a` (the analysis this was made for) that leave every point
    /// within `tolerance` (times its share).
    pub fn components_for(&mut self, a: &Analysis, tolerance: f64) -> usize {
        if let Some(k) = self.errors.iter().position(|&e| e <= tolerance) {
            return k;
        }
        while self.errors.len() <= self.width {
            let k = self.errors.len() - 1;
            let u = a.vectors.column(k);
            for x in self.residual.chunks_exact_mut(self.width) {
                let c: f64 = x.iter().zip(u.iter()).map(|(a, b)| a * b).sum();
                for (xi, ui) in x.iter_mut().zip(u.iter()) {
                    *xi -= c * ui;
                }
            }
            self.errors.push(self.error());
            if self.errors[k + 1] <= tolerance {
                return k + 1;
            }
        }
        self.width
    }
}

dispatch! {
    /// `mean + Σ_j c_j · column_j` into `out` (columns of `mean.len()` values, contiguous): the
    /// spca decoder's inner loop. Compiled for AVX2 too and chosen at run time ([`dispatch!`]);
    /// element-wise, so the same bits either way (see `mdtt::transform::reconstruct`).
    fn combine(mean: &[f64], basis: &[f64], c: &[f64], out: &mut [f64]) {
        out.copy_from_slice(mean);
        for (column, &cj) in basis.chunks_exact(mean.len().max(1)).zip(c) {
            for (o, &b) in out.iter_mut().zip(column) {
                *o += b * cj;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::entropy::{Decoder, Encoder};

    /// Poses of 4 points moving along two directions.
    fn rows(frames: usize) -> Vec<f64> {
        (0..frames)
            .flat_map(|f| {
                let (a, b) = (
                    (f as f64 * 0.1).sin() * 100.0,
                    (f as f64 * 0.37).cos() * 10.0,
                );
                (0..12)
                    .map(move |i| 500.0 + i as f64 * 40.0 + a * (i % 3) as f64 + b * (i % 2) as f64)
            })
            .collect()
    }

    #[test]
    fn two_directions_need_two_components_and_round_trip() {
        let x = rows(200);
        let a = Analysis::of(&x, 12);
        let mut t = Truncation::new(&a, &x, &[1.0; 4]);
        assert_eq!(t.components_for(&a, 1e6), 0);
        assert_eq!(t.components_for(&a, 1e-6), 2);
        assert_eq!(t.components_for(&a, 1e6), 0);
        // A point with a third of the share needs the tolerance three times tighter.
        let mut feet = Truncation::new(&a, &x, &[1.0, 1.0, 1.0, 1.0 / 3.0]);
        assert_eq!(feet.components_for(&a, 1e-6), 2);
        let m = a.model(2, 0.01, 0.001);
        let c = m.coefficients(&x);
        let mut pose = vec![0.0; 12];
        for (f, r) in x.chunks_exact(12).enumerate() {
            m.pose(c.column(f).as_slice(), &mut pose);
            for (p, v) in pose.iter().zip(r) {
                assert!((p - v).abs() < 0.5, "{p} vs {v}");
            }
        }
        let mut enc = Encoder::new();
        assert_eq!(
            Model::code(&mut enc, &mut Models::default(), 12, 0.01, Some(&m)).unwrap(),
            m
        );
        let bytes = enc.finish();
        let got = Model::code(
            &mut Decoder::new(&bytes),
            &mut Models::default(),
            12,
            0.01,
            None,
        );
        assert_eq!(got.unwrap(), m);
    }
}
