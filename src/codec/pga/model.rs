//! Principal geodesic analysis of poses (Fletcher et al. 2004, as used by Tournier et al.
//! 2009): the poses of a take's inner joints are points of SO(3)ⁿ; their intrinsic mean is
//! the Karcher mean joint by joint; the principal geodesics are the principal components of
//! the poses mapped to the tangent space at that mean (the log map, joint by joint), and a
//! point `x` of the `k`-dimensional coordinate space is the pose `μ_j · exp((V x)_j)`.
//!
//! Pure math: rotations in, rotations out.

use nalgebra::{DMatrix, DVector, UnitQuaternion, Vector3};

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
            directions,
            variances,
        })
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
        Geodesics {
            mean: self.mean.clone(),
            directions: self.directions.columns(0, k).clone_owned(),
            variances: self.variances[..k].to_vec(),
        }
    }

    /// The model as stored: `n` and `k` (u32 each), then per joint its mean as a unit
    /// quaternion (w, x, y, z; f32), then the `3n × k` directions column by column (f32).
    /// Variances are not stored (a decoder does not need them).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.u32(self.joints() as u32).u32(self.dims() as u32);
        for q in &self.mean {
            let c = q.quaternion().coords;
            w.f32(c.w as f32)
                .f32(c.x as f32)
                .f32(c.y as f32)
                .f32(c.z as f32);
        }
        for v in self.directions.iter() {
            w.f32(*v as f32);
        }
        w.0
    }

    /// The model of [`Geodesics::to_bytes`] for `joints` inner joints and at most
    /// `max_dims` directions; malformed unless it has exactly that many joints, finite
    /// numbers and quaternions of unit norm (to f32 precision). The encoder codes with the
    /// parsed model, so both sides use the same numbers.
    pub fn parse(bytes: &[u8], joints: usize, max_dims: usize) -> Result<Geodesics> {
        let mut r = Reader::named(bytes, "pga model");
        let n = r.u32()? as usize;
        let k = r.u32()? as usize;
        if n != joints || k == 0 || k > max_dims.min(3 * n) {
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
        let mut directions = DMatrix::zeros(3 * n, k);
        for v in directions.iter_mut() {
            let x = f64::from(r.f32()?);
            if !x.is_finite() || x.abs() > 1.0 + 1e-5 {
                return Err(malformed("a pga direction is not part of a unit vector"));
            }
            *v = x;
        }
        r.finish()?;
        Ok(Geodesics {
            mean,
            directions,
            variances: vec![0.0; k],
        })
    }

    /// A pose's coordinates along the directions: the projection of its tangent vector.
    pub fn coordinates(&self, pose: &[UnitQuaternion<f64>]) -> Vec<f64> {
        let mut u = DVector::zeros(3 * self.joints());
        tangent_into(&self.mean, pose, &mut u);
        (self.directions.transpose() * u).iter().copied().collect()
    }

    /// Joint `j`'s rotation vector at the mean for coordinates `x`: `(V x)_j`.
    pub fn tangent_of(&self, j: usize, x: &[f64]) -> Vector3<f64> {
        let rows = self.directions.rows(3 * j, 3);
        let mut w = Vector3::zeros();
        for (i, xi) in x.iter().enumerate() {
            w += rows.column(i) * *xi;
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
    fn the_stored_model_parses_back_and_bad_ones_are_refused() {
        let (poses, n) = dancer_poses(60);
        let g = Geodesics::fit(&poses, n, 12).unwrap();
        let bytes = g.to_bytes();
        assert_eq!(bytes.len(), 8 + 16 * n + 4 * 3 * n * 12);
        let back = Geodesics::parse(&bytes, n, 64).unwrap();
        assert_eq!(back.dims(), 12);
        assert!((back.directions.clone() - &g.directions).amax() < 1e-6);
        assert!(back
            .mean
            .iter()
            .zip(&g.mean)
            .all(|(a, b)| a.angle_to(b) < 1e-6));
        // Stored once, parsed twice: the same numbers.
        assert_eq!(
            Geodesics::parse(&back.to_bytes(), n, 64)
                .unwrap()
                .to_bytes(),
            back.to_bytes()
        );
        assert!(Geodesics::parse(&bytes, n + 1, 64).is_err());
        assert!(Geodesics::parse(&bytes, n, 11).is_err());
        assert!(Geodesics::parse(&bytes[..bytes.len() - 1], n, 64).is_err());
        let mut bad = bytes.clone();
        bad[8..12].copy_from_slice(&7f32.to_le_bytes());
        assert!(Geodesics::parse(&bad, n, 64).is_err());
        let mut bad = bytes;
        let at = 8 + 16 * n;
        bad[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(Geodesics::parse(&bad, n, 64).is_err());
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
