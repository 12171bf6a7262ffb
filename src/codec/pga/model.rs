//! Principal geodesic analysis of poses (Fletcher et al. 2004, as used by Tournier et al.
//! 2009): the poses of a take's inner joints are points of SO(3)ⁿ; their intrinsic mean is
//! the Karcher mean joint by joint; the principal geodesics are the principal components of
//! the poses mapped to the tangent space at that mean (the log map, joint by joint), and a
//! point `x` of the `k`-dimensional coordinate space is the pose `μ_j · exp((V x)_j)`.
//!
//! Pure math: rotations in, rotations out.

use nalgebra::{DMatrix, DVector, UnitQuaternion, Vector3};

use crate::codec::linalg::leading_eigen;
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
