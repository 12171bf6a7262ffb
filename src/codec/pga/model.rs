//! Principal geodesic analysis of poses (Fletcher et al. 2004, as used by Tournier et al.
//! 2009): the poses of a take's inner joints are points of SO(3)ⁿ; their intrinsic mean is
//! the Karcher mean joint by joint; the principal geodesics are the principal components of
//! the poses mapped to the tangent space at that mean (the log map, joint by joint), and a
//! point `x` of the `k`-dimensional coordinate space is the pose `μ_j · exp((V x)_j)`.
//!
//! Pure math: rotations in, rotations out.

use nalgebra::{DMatrix, DVector, UnitQuaternion, Vector3};

use crate::codec::entropy::ints::IntModel;
use crate::codec::entropy::io::{code_residual, Io};
use crate::codec::entropy::rangecoder::{Decoder, Encoder};
use crate::codec::error::{malformed, Result};
use crate::codec::linalg::leading_eigen;
use crate::codec::wire::{Reader, Writer};
use crate::motion::rotation::{exp, karcher_mean, log};

/// Fixed-point iterations of the Karcher mean (it converges in a handful for poses).
const MEAN_ITERATIONS: usize = 30;

/// The mean pose and principal geodesic directions of a set of poses.
#[derive(Debug, Clone)]
pub struct Geodesics {
    /// The intrinsic mean rotation of each joint.
    pub mean: Vec<UnitQuaternion<f64>>,
    /// `3n × k`: orthonormal directions in the tangent space at the mean, largest variance
    /// first; rows `3j..3j+3` are joint `j`'s rotation-vector part.
    pub directions: DMatrix<f64>,
    /// The variance of the poses along each direction.
    pub variances: Vec<f64>,
    /// `3n × k`, the transpose of what maps a tangent vector to coordinates — the
    /// least-squares projection `(VᵀV)⁻¹Vᵀ`, which is `Vᵀ` for the fitted (orthonormal)
    /// directions and stays exact for the stored ones, rounded. Transposed so that each
    /// coordinate is one contiguous dot product.
    projector: DMatrix<f64>,
    /// Whether the directions are the canonical basis (each joint's own rotation-vector
    /// components at its mean), which is stored as a flag instead of a matrix.
    canonical: bool,
}

/// The least-squares projection onto the columns of `v`; `None` when they are dependent.
/// The Gram matrix goes through [`linalg::tn`](crate::codec::linalg::tn), not nalgebra's
/// product: the projection decides coordinates and so bitstream bytes, which must not
/// depend on the SIMD kernels of the machine that encodes.
fn projector_of(v: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let gram = crate::codec::linalg::tn(v, v.as_view());
    Some(gram.cholesky()?.solve(&v.transpose()).transpose())
}

/// Direction steps run from 2⁻¹ to 2⁻³⁰: no component needs coarser than half its range,
/// none finer than f32 gave.
const MIN_EXPONENT: f64 = 1.0;
const MAX_EXPONENT: f64 = 30.0;

/// The directions' components as multiples of `2^−exponents[i]`, column by column, through
/// `io`; from `given` when encoding. Malformed when a decoded component is past ±1.
fn code_directions<I: Io>(
    io: &mut I,
    exponents: &[u8],
    given: Option<&DMatrix<f64>>,
    rows: usize,
) -> Result<DMatrix<f64>> {
    let mut out = DMatrix::zeros(rows, exponents.len());
    for (i, &e) in exponents.iter().enumerate() {
        let step = 2f64.powi(-i32::from(e));
        let mut model = IntModel::default();
        let mut previous = 0;
        for r in 0..rows {
            let q = given.map_or(0, |g| (g[(r, i)] / step).round() as i64);
            // Components of one joint come in threes and neighbours alike: code the
            // difference from the one before.
            let v = previous + code_residual(io, &mut model, q - previous)?;
            previous = v;
            let x = v as f64 * step;
            if x.abs() > 1.0 + step {
                return Err(malformed("a pga direction is not part of a unit vector"));
            }
            out[(r, i)] = x;
        }
    }
    Ok(out)
}

impl Geodesics {
    /// The mean and the `k` leading directions of `poses` (`frames × joints`, row-major);
    /// `None` when there are no poses or no joints.
    pub fn fit(poses: &[UnitQuaternion<f64>], joints: usize, k: usize) -> Option<Geodesics> {
        if joints == 0 || poses.is_empty() || !poses.len().is_multiple_of(joints) {
            return None;
        }
        let frames = poses.len() / joints;
        let mean: Vec<UnitQuaternion<f64>> = (0..joints)
            .map(|j| {
                let samples: Vec<_> = (0..frames).map(|f| poses[f * joints + j]).collect();
                karcher_mean(&samples, MEAN_ITERATIONS)
            })
            .collect::<Option<_>>()?;
        let dim = 3 * joints;
        let mut cov = DMatrix::<f64>::zeros(dim, dim);
        let mut u = DVector::<f64>::zeros(dim);
        for f in 0..frames {
            tangent_into(&mean, &poses[f * joints..(f + 1) * joints], &mut u);
            cov.ger(1.0, &u, &u, 1.0);
        }
        cov /= frames as f64;
        let (directions, variances) = leading_eigen(&cov, k.min(dim));
        Some(Geodesics {
            mean,
            projector: projector_of(&directions)?,
            directions,
            variances,
            canonical: false,
        })
    }

    /// A model of given means and (independent) directions, variances unknown; `None` when
    /// the directions are dependent or not `3 × joints` long.
    pub fn new(mean: Vec<UnitQuaternion<f64>>, directions: DMatrix<f64>) -> Option<Geodesics> {
        if directions.nrows() != 3 * mean.len() || directions.ncols() == 0 {
            return None;
        }
        Some(Geodesics {
            variances: vec![0.0; directions.ncols()],
            projector: projector_of(&directions)?,
            directions,
            mean,
            canonical: false,
        })
    }

    /// The canonical model at `mean`: every direction a joint's own rotation-vector axis, so
    /// coordinates are the joints' rotations at their mean. It costs the means alone to
    /// store, which wins where a take is too short for its principal directions to pay for
    /// themselves.
    pub fn canonical(mean: Vec<UnitQuaternion<f64>>) -> Geodesics {
        let d = 3 * mean.len();
        Geodesics {
            variances: vec![0.0; d],
            projector: DMatrix::identity(d, d),
            directions: DMatrix::identity(d, d),
            mean,
            canonical: true,
        }
    }

    pub fn joints(&self) -> usize {
        self.mean.len()
    }

    /// The number of directions `k`.
    pub fn dims(&self) -> usize {
        self.directions.ncols()
    }

    /// The first `k` directions only.
    pub fn truncated(&self, k: usize) -> Geodesics {
        let k = k.min(self.dims());
        let directions = self.directions.columns(0, k).clone_owned();
        Geodesics {
            mean: self.mean.clone(),
            projector: projector_of(&directions).expect("leading columns of independent ones"),
            directions,
            variances: self.variances[..k].to_vec(),
            canonical: self.canonical && k == self.dims(),
        }
    }

    /// The model as stored, each direction `i`'s components to within `precision[i]` (what
    /// the encoder allows: a coordinate that never exceeds `x` turns a joint by at most
    /// `x · precision` more): `n` and `k` (u32 each), its kind (u8, since parameters
    /// version 2: 1 for the
    /// [canonical](Geodesics::canonical) model, whose `k` is `3n` and nothing follows the
    /// means; 0 otherwise), per joint its mean as a unit quaternion (w, x, y, z; f32), per
    /// direction its step exponent `e` (u8, step `2^−e`),
    /// then the `3n × k` components column by column as multiples of their
    /// direction's step, through the adaptive range coder (a context per direction), after
    /// their length in bytes (u32).
    /// Variances are not stored (a decoder does not need them).
    pub fn to_bytes(&self, precision: &[f64]) -> Vec<u8> {
        let mut w = Writer::new();
        w.u32(self.joints() as u32)
            .u32(self.dims() as u32)
            .bytes(&[u8::from(self.canonical)]);
        for q in &self.mean {
            let c = q.quaternion().coords;
            w.f32(c.w as f32)
                .f32(c.x as f32)
                .f32(c.y as f32)
                .f32(c.z as f32);
        }
        if self.canonical {
            return w.0;
        }
        let exponents: Vec<u8> = (0..self.dims())
            .map(|i| {
                // The coarsest step whose rounding error (half a step) is within precision.
                let p = precision.get(i).copied().unwrap_or(0.0);
                let e = if p > 0.0 {
                    (-(2.0 * p).log2()).ceil()
                } else {
                    30.0
                };
                e.clamp(MIN_EXPONENT, MAX_EXPONENT) as u8
            })
            .collect();
        w.bytes(&exponents);
        let mut enc = Encoder::new();
        code_directions(
            &mut enc,
            &exponents,
            Some(&self.directions),
            self.directions.nrows(),
        )
        .expect("encoding cannot fail");
        let coded = enc.finish();
        w.u32(coded.len() as u32).bytes(&coded);
        w.0
    }

    /// The model of [`Geodesics::to_bytes`] for `joints` inner joints and at most
    /// `max_dims` directions; malformed unless it has exactly that many joints, finite
    /// numbers, quaternions of unit norm (to f32 precision), steps in range and independent
    /// directions of components within ±1. The encoder codes with the parsed model, so both
    /// sides use the same numbers.
    pub fn parse(bytes: &[u8], joints: usize, max_dims: usize) -> Result<Geodesics> {
        Geodesics::parse_layout(bytes, joints, max_dims, true)
    }

    /// The model as parameters version 1 stored it: no kind byte (every model fitted), the
    /// rest as [`Geodesics::parse`].
    pub fn parse_v1(bytes: &[u8], joints: usize, max_dims: usize) -> Result<Geodesics> {
        Geodesics::parse_layout(bytes, joints, max_dims, false)
    }

    fn parse_layout(
        bytes: &[u8],
        joints: usize,
        max_dims: usize,
        kind_byte: bool,
    ) -> Result<Geodesics> {
        let mut r = Reader::named(bytes, "pga model");
        let n = r.u32()? as usize;
        let k = r.u32()? as usize;
        let canonical = match kind_byte.then(|| r.u8()).transpose()? {
            None | Some(0) => false,
            Some(1) => true,
            Some(other) => return Err(malformed(format!("pga model kind {other}"))),
        };
        if n != joints || k == 0 || k > max_dims.min(3 * n) || (canonical && k != 3 * n) {
            return Err(malformed(format!(
                "pga model of {n} joints and {k} directions (the skeleton has {joints} inner joints)"
            )));
        }
        let mut mean = Vec::with_capacity(n);
        for _ in 0..n {
            let (w, x, y, z) = (r.f32()?, r.f32()?, r.f32()?, r.f32()?);
            let q =
                nalgebra::Quaternion::new(f64::from(w), f64::from(x), f64::from(y), f64::from(z));
            if !q.coords.iter().all(|v| v.is_finite()) || (q.norm() - 1.0).abs() > 1e-5 {
                return Err(malformed("a pga mean rotation is not a unit quaternion"));
            }
            mean.push(UnitQuaternion::new_normalize(q));
        }
        if canonical {
            r.finish()?;
            return Ok(Geodesics::canonical(mean));
        }
        let exponents = r.take(k)?.to_vec();
        if exponents
            .iter()
            .any(|&e| !(MIN_EXPONENT..=MAX_EXPONENT).contains(&f64::from(e)))
        {
            return Err(malformed("a pga direction step is out of range"));
        }
        let length = r.u32()? as usize;
        let coded = r.take(length)?;
        r.finish()?;
        let mut dec = Decoder::new(coded);
        let directions = code_directions(&mut dec, &exponents, None, 3 * n)?;
        if dec.overran() {
            return Err(malformed("pga model is truncated"));
        }
        Geodesics::new(mean, directions)
            .ok_or_else(|| malformed("the pga directions are not independent"))
    }

    /// A pose's coordinates along the directions: the projection of its tangent vector.
    pub fn coordinates(&self, pose: &[UnitQuaternion<f64>]) -> Vec<f64> {
        let mut u = DVector::zeros(3 * self.joints());
        tangent_into(&self.mean, pose, &mut u);
        let rows = self.projector.nrows();
        let p = self.projector.as_slice();
        (0..self.projector.ncols())
            .map(|i| crate::codec::linalg::dot(&p[i * rows..(i + 1) * rows], u.as_slice()))
            .collect()
    }

    /// The directions that can turn joint `j`: all of them, or for the canonical model its
    /// own three (what lets IK skip the zeros of a sparse model).
    pub fn support(&self, j: usize) -> std::ops::Range<usize> {
        if self.canonical {
            3 * j..3 * j + 3
        } else {
            0..self.dims()
        }
    }

    /// Joint `j`'s rotation vector at the mean for coordinates `x`: `(V x)_j`.
    pub fn tangent_of(&self, j: usize, x: &[f64]) -> Vector3<f64> {
        // Column-major: direction `i`'s rows `3j..3j+3` sit together. Indexing the storage
        // directly keeps this allocation-free (it runs once per joint per IK trial).
        let rows = self.directions.nrows();
        let data = self.directions.as_slice();
        let mut w = Vector3::zeros();
        let support = self.support(j);
        let end = support.end.min(x.len());
        for (i, xi) in x.iter().enumerate().take(end).skip(support.start) {
            let at = i * rows + 3 * j;
            w += Vector3::new(data[at], data[at + 1], data[at + 2]) * *xi;
        }
        w
    }

    /// The pose at coordinates `x` into `out` (one rotation per joint).
    pub fn pose(&self, x: &[f64], out: &mut [UnitQuaternion<f64>]) {
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.mean[j] * exp(&self.tangent_of(j, x));
        }
    }
}

/// `u_j = log(μ_j⁻¹ q_j)`, stacked.
fn tangent_into(mean: &[UnitQuaternion<f64>], pose: &[UnitQuaternion<f64>], u: &mut DVector<f64>) {
    for (j, (m, q)) in mean.iter().zip(pose).enumerate() {
        let v = log(&(m.inverse() * q));
        u.fixed_rows_mut::<3>(3 * j).copy_from(&v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::rotation::from_euler;
    use crate::motion::synthetic::dancer;

    /// The dancer's poses (every joint with three rotation channels but the root).
    pub(crate) fn dancer_poses(frames: usize) -> (Vec<UnitQuaternion<f64>>, usize) {
        let m = dancer(frames, 60.0, 5);
        let sk = m.skeleton.unwrap();
        let mut out = Vec::new();
        let mut joints = 0;
        for f in 0..frames {
            let v = sk.frame_values(f);
            let mut k = 0;
            joints = 0;
            for (j, joint) in sk.joints.iter().enumerate() {
                let n = joint.channels.len();
                if j > 0 {
                    if let Some(order) = crate::motion::rotation::euler_order(&joint.channels) {
                        let r = &v[k + n - 3..k + n];
                        out.push(from_euler(order, [r[0], r[1], r[2]]));
                        joints += 1;
                    }
                }
                k += n;
            }
        }
        (out, joints)
    }

    #[test]
    fn all_directions_give_every_pose_back() {
        let (poses, n) = dancer_poses(120);
        let g = Geodesics::fit(&poses, n, 3 * n).unwrap();
        assert_eq!(g.dims(), 3 * n);
        let mut back = vec![UnitQuaternion::identity(); n];
        for pose in poses.chunks_exact(n) {
            g.pose(&g.coordinates(pose), &mut back);
            for (a, b) in pose.iter().zip(&back) {
                assert!(a.angle_to(b) < 1e-9);
            }
        }
        // Directions are orthonormal and sorted by variance.
        let gram = g.directions.transpose() * &g.directions;
        assert!((gram - DMatrix::identity(3 * n, 3 * n)).amax() < 1e-9);
        assert!(g.variances.windows(2).all(|w| w[0] >= w[1]));
    }

    #[test]
    fn the_stored_model_parses_back_within_its_precision_and_bad_ones_are_refused() {
        let (poses, n) = dancer_poses(60);
        let g = Geodesics::fit(&poses, n, 12).unwrap();
        let precision: Vec<f64> = (0..12).map(|i| 1e-6 * (1 << i) as f64).collect();
        let bytes = g.to_bytes(&precision);
        let back = Geodesics::parse(&bytes, n, 64).unwrap();
        assert_eq!(back.dims(), 12);
        for (i, p) in precision.iter().enumerate() {
            let error = (back.directions.column(i) - g.directions.column(i)).amax();
            assert!(error <= *p, "direction {i}: {error} > {p}");
        }
        // Coarser precision, fewer bytes: far under the 4 bytes of an f32 per component.
        let coarse = g.to_bytes(&[1e-3; 12]);
        assert!(coarse.len() < bytes.len());
        assert!(
            coarse.len() < 9 + 16 * n + 3 * n * 12 * 2,
            "{}",
            coarse.len()
        );
        assert!(back
            .mean
            .iter()
            .zip(&g.mean)
            .all(|(a, b)| a.angle_to(b) < 1e-6));
        // Stored once, parsed twice: the same numbers.
        assert_eq!(
            Geodesics::parse(&back.to_bytes(&precision), n, 64)
                .unwrap()
                .directions,
            back.directions
        );
        assert!(Geodesics::parse(&bytes, n + 1, 64).is_err());
        assert!(Geodesics::parse(&bytes, n, 11).is_err());
        assert!(Geodesics::parse(&bytes[..9 + 16 * n + 5], n, 64).is_err());
        let mut bad = bytes.clone();
        bad[9..13].copy_from_slice(&7f32.to_le_bytes());
        assert!(Geodesics::parse(&bad, n, 64).is_err());
        let mut bad = bytes.clone();
        bad[9 + 16 * n] = 0;
        assert!(Geodesics::parse(&bad, n, 64).is_err());
        for i in 9 + 16 * n + 12..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x5a;
            let _ = Geodesics::parse(&b, n, 64);
        }
        // Two equal directions: no projection onto them.
        let mut twice = g.directions.columns(0, 2).clone_owned();
        let first = twice.column(0).clone_owned();
        twice.set_column(1, &first);
        assert!(Geodesics::new(g.mean.clone(), twice).is_none());
    }

    #[test]
    fn the_canonical_model_stores_only_its_means_and_gives_poses_back() {
        let (poses, n) = dancer_poses(60);
        let fitted = Geodesics::fit(&poses, n, 3).unwrap();
        let g = Geodesics::canonical(fitted.mean.clone());
        let bytes = g.to_bytes(&[]);
        assert_eq!(bytes.len(), 9 + 16 * n);
        let back = Geodesics::parse(&bytes, n, 3 * n).unwrap();
        assert_eq!(back.to_bytes(&[]), bytes);
        let mut out = vec![UnitQuaternion::identity(); n];
        for pose in poses.chunks_exact(n) {
            back.pose(&back.coordinates(pose), &mut out);
            for (a, b) in pose.iter().zip(&out) {
                assert!(a.angle_to(b) < 1e-6);
            }
        }
        // Its `k` is every axis, and nothing may follow the means.
        let mut bad = bytes.clone();
        bad[4..8].copy_from_slice(&3u32.to_le_bytes());
        assert!(Geodesics::parse(&bad, n, 3 * n).is_err());
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(Geodesics::parse(&longer, n, 3 * n).is_err());
        let mut kind = bytes;
        kind[8] = 2;
        assert!(Geodesics::parse(&kind, n, 3 * n).is_err());
    }

    #[test]
    fn the_stored_model_with_all_directions_still_gives_poses_back() {
        let (poses, n) = dancer_poses(60);
        let g = Geodesics::fit(&poses, n, 3 * n).unwrap();
        let stored = Geodesics::parse(&g.to_bytes(&vec![1e-3; 3 * n]), n, 3 * n).unwrap();
        let mut back = vec![UnitQuaternion::identity(); n];
        for pose in poses.chunks_exact(n) {
            stored.pose(&stored.coordinates(pose), &mut back);
            for (a, b) in pose.iter().zip(&back) {
                // Coarse directions, but every one of them: the projection is still exact;
                // only the f32 mean's rounding is left.
                assert!(a.angle_to(b) < 1e-6, "{}", a.angle_to(b));
            }
        }
    }

    #[test]
    fn a_motion_along_one_geodesic_needs_one_direction() {
        // Poses on one geodesic through a mean: p(s) = μ · exp(s v).
        let n = 4;
        let mean: Vec<_> = (0..n)
            .map(|j| from_euler([0, 1, 2], [10.0 * j as f64, -20.0, 5.0]))
            .collect();
        let v: Vec<Vector3<f64>> = (0..n)
            .map(|j| Vector3::new(0.3, -0.1 * j as f64, 0.2))
            .collect();
        let mut poses = Vec::new();
        for f in 0..50 {
            let s = (f as f64 / 49.0 - 0.5) * 1.5;
            for j in 0..n {
                poses.push(mean[j] * exp(&(v[j] * s)));
            }
        }
        let g = Geodesics::fit(&poses, n, 1).unwrap();
        let mut back = vec![UnitQuaternion::identity(); n];
        for pose in poses.chunks_exact(n) {
            g.pose(&g.coordinates(pose), &mut back);
            for (a, b) in pose.iter().zip(&back) {
                assert!(a.angle_to(b) < 1e-9, "{}", a.angle_to(b));
            }
        }
    }
}
