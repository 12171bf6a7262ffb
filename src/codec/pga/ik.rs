//! Inverse kinematics in principal-geodesic coordinates (Tournier et al. 2009, §4): the pose
//! whose end points (hands, feet, head: End Sites and leaf joints) land on given positions in
//! the root's frame, searched over the `k` coordinates `x` of [`Geodesics`] by
//! Levenberg–Marquardt on
//!
//! `Σ_e |p_e(x) − target_e|² + Σ_i λ_i (x_i − x_ref,i)²`
//!
//! with the analytic Jacobian: moving `x_i` turns inner joint `j` by the angular velocity
//! `G_j · J_r(w_j) · V_j[:, i]` (its global rotation times the right Jacobian of the exp map
//! at its tangent vector `w_j = V_j x`, times its part of direction `i`), which moves every end
//! point `e` below it by that vector × `(p_e − p_j)`.
//!
//! Pure math; the caller owns the units (targets and translations in one unit, which sets
//! what `λ` weighs against).

use nalgebra::{DMatrix, DVector, Matrix3, UnitQuaternion, Vector3};

use super::model::Geodesics;

/// One joint of the chain as IK sees it.
#[derive(Debug, Clone)]
pub struct Link {
    pub parent: Option<usize>,
    /// Translation from the parent in the parent's frame (the offset, and any constant
    /// position channel).
    pub translation: Vector3<f64>,
    /// Its index among the [`Geodesics`] joints when PGA drives its rotation; `None` for
    /// joints that do not turn (End Sites, the root — IK works in the root's frame).
    pub inner: Option<usize>,
}

/// A skeleton for IK: links in parent-before-child order and the end points to reach.
#[derive(Debug, Clone)]
pub struct Chain {
    links: Vec<Link>,
    ends: Vec<usize>,
    /// For each end, the inner joints above it (link indices), nearest first.
    above: Vec<Vec<usize>>,
}

impl Chain {
    /// `None` when a parent comes after its child or an end is not a link.
    pub fn new(links: Vec<Link>, ends: Vec<usize>) -> Option<Chain> {
        if links
            .iter()
            .enumerate()
            .any(|(i, l)| l.parent.is_some_and(|p| p >= i))
            || ends.iter().any(|&e| e >= links.len())
        {
            return None;
        }
        let above = ends
            .iter()
            .map(|&e| {
                let mut out = Vec::new();
                let mut a = links[e].parent;
                while let Some(p) = a {
                    if links[p].inner.is_some() {
                        out.push(p);
                    }
                    a = links[p].parent;
                }
                out
            })
            .collect();
        Some(Chain { links, ends, above })
    }

    pub fn ends(&self) -> &[usize] {
        &self.ends
    }

    pub fn links(&self) -> &[Link] {
        &self.links
    }
}

/// Reusable state for solving one take frame by frame: poses, the Jacobian and the small
/// system of each step, allocated once.
pub struct Solver {
    rotation: Vec<UnitQuaternion<f64>>,
    position: Vec<Vector3<f64>>,
    /// Per link: its angular velocity per coordinate of its support
    /// ([`Geodesics::support`]), global frame.
    spin: Vec<Vec<Vector3<f64>>>,
    /// `3·ends × k`.
    jac: DMatrix<f64>,
    /// `3·ends × 3·ends`: `I + J D⁻¹ Jᵀ` of a step.
    small: DMatrix<f64>,
}

impl Solver {
    pub fn new(chain: &Chain, k: usize) -> Solver {
        let n = chain.links.len();
        let m = 3 * chain.ends.len();
        Solver {
            rotation: vec![UnitQuaternion::identity(); n],
            position: vec![Vector3::zeros(); n],
            spin: vec![Vec::with_capacity(k); n],
            jac: DMatrix::zeros(m, k),
            small: DMatrix::zeros(m, m),
        }
    }

    /// Global rotations and positions of every link at `x` (root at the origin, unturned).
    pub fn pose(&mut self, chain: &Chain, g: &Geodesics, x: &[f64]) {
        self.pose_with(chain, |j| {
            g.mean[j] * crate::motion::rotation::exp(&g.tangent_of(j, x))
        });
    }

    /// Global rotations and positions of every link with inner joint `j` turned by
    /// `local(j)` (root at the origin, unturned).
    pub fn pose_with(&mut self, chain: &Chain, local: impl Fn(usize) -> UnitQuaternion<f64>) {
        for (i, l) in chain.links.iter().enumerate() {
            let turn = l.inner.map_or(UnitQuaternion::identity(), &local);
            match l.parent {
                Some(p) => {
                    self.position[i] = self.position[p] + self.rotation[p] * l.translation;
                    self.rotation[i] = self.rotation[p] * turn;
                }
                None => {
                    self.position[i] = Vector3::zeros();
                    self.rotation[i] = turn;
                }
            }
        }
    }

    /// The position of link `i` after [`Solver::pose`].
    pub fn position(&self, i: usize) -> Vector3<f64> {
        self.position[i]
    }

    /// The Jacobian of the end positions (`3·ends × k`) at the pose last computed at `x`.
    pub fn jacobian(&mut self, chain: &Chain, g: &Geodesics, x: &[f64], jac: &mut DMatrix<f64>) {
        let rows = g.directions.nrows();
        let dirs = g.directions.as_slice();
        for (i, l) in chain.links.iter().enumerate() {
            let Some(j) = l.inner else {
                continue;
            };
            let w = g.tangent_of(j, x);
            let m = self.rotation[i].to_rotation_matrix().into_inner() * right_jacobian(&w);
            let spin = &mut self.spin[i];
            spin.clear();
            for c in g.support(j) {
                let at = c * rows + 3 * j;
                spin.push(m * Vector3::new(dirs[at], dirs[at + 1], dirs[at + 2]));
            }
        }
        jac.fill(0.0);
        let m = jac.nrows();
        let js = jac.as_mut_slice();
        for (n, (&e, above)) in chain.ends.iter().zip(&chain.above).enumerate() {
            let pe = self.position[e];
            for &a in above {
                let r = pe - self.position[a];
                let first = chain.links[a].inner.map_or(0, |j| g.support(j).start);
                for (c, s) in (first..).zip(&self.spin[a]) {
                    let d = s.cross(&r);
                    let at = c * m + 3 * n;
                    js[at] += d.x;
                    js[at + 1] += d.y;
                    js[at + 2] += d.z;
                }
            }
        }
    }

    /// The coordinates whose end points best reach `targets` (one per end, root frame),
    /// held near `reference` with weights `lambda` (one per coordinate), starting from
    /// `start`: damped Gauss–Newton (Levenberg–Marquardt) for at most `iterations` steps.
    /// Each step computes the pose once, for its cost and its Jacobian.
    ///
    /// A step solves `(JᵀJ + D) δ = −g` with `D` diagonal (the weights plus the damping), by
    /// the Woodbury identity in the space of the end points: `3·ends` rows against `k` up to
    /// `3n` coordinates, so the system to factor is small.
    #[allow(clippy::too_many_arguments)]
    pub fn solve(
        &mut self,
        chain: &Chain,
        g: &Geodesics,
        targets: &[Vector3<f64>],
        start: &[f64],
        reference: &[f64],
        lambda: &[f64],
        iterations: usize,
    ) -> Vec<f64> {
        let k = g.dims();
        let m = 3 * chain.ends.len();
        let mut x = start.to_vec();
        let mut r = vec![0.0; m];
        let (mut grad, mut diag, mut y, mut step, mut trial) = (
            vec![0.0; k],
            vec![0.0; k],
            vec![0.0; k],
            vec![0.0; k],
            vec![0.0; k],
        );
        let mut z = DVector::zeros(m);
        let mut jac = std::mem::take(&mut self.jac);
        let mut small = std::mem::take(&mut self.small);
        let mut damping = 1e-6;
        self.pose(chain, g, &x);
        let mut posed = true;
        let mut cost = self.cost(chain, targets, &x, reference, lambda);
        for _ in 0..iterations {
            // The pose at `x` is current here.
            self.jacobian(chain, g, &x, &mut jac);
            for (n, &e) in chain.ends.iter().enumerate() {
                let d = self.position[e] - targets[n];
                r[3 * n..3 * n + 3].copy_from_slice(d.as_slice());
            }
            // g = Jᵀr + Λ(x − x_ref); diag(JᵀJ) for the damping.
            for c in 0..k {
                let col = jac.column(c);
                let mut dot = 0.0;
                let mut sq = 0.0;
                for (a, b) in col.iter().zip(&r) {
                    dot += a * b;
                    sq += a * a;
                }
                grad[c] = dot + lambda[c] * (x[c] - reference[c]);
                diag[c] = sq + lambda[c];
            }
            let mut accepted = false;
            while damping < 1e12 {
                // D = Λ + μ diag(H); y = D⁻¹ g; z = J y; small = I + J D⁻¹ Jᵀ.
                let d: Vec<f64> = (0..k)
                    .map(|c| lambda[c] + damping * diag[c].max(1e-12))
                    .collect();
                if d.iter().any(|v| *v <= 0.0) {
                    damping *= 10.0;
                    continue;
                }
                for c in 0..k {
                    y[c] = grad[c] / d[c];
                }
                z.fill(0.0);
                small.fill_with_identity();
                {
                    // Column-major storage: column `c` of J is `js[c·m..(c+1)·m]`; the lower
                    // triangle of `small` is accumulated column by column.
                    let js = jac.as_slice();
                    let ss = small.as_mut_slice();
                    for c in 0..k {
                        let col = &js[c * m..(c + 1) * m];
                        let inv = 1.0 / d[c];
                        for (j, &b) in col.iter().enumerate() {
                            if b == 0.0 {
                                continue;
                            }
                            z[j] += b * y[c];
                            let s = b * inv;
                            for (out, &a) in ss[j * m + j..(j + 1) * m].iter_mut().zip(&col[j..]) {
                                *out += s * a;
                            }
                        }
                    }
                }
                for j in 0..m {
                    for i in j + 1..m {
                        small[(j, i)] = small[(i, j)];
                    }
                }
                let Some(chol) = small.clone().cholesky() else {
                    damping *= 10.0;
                    continue;
                };
                let w = chol.solve(&z);
                // δ = −y + D⁻¹ Jᵀ w.
                for c in 0..k {
                    let col = jac.column(c);
                    let jw: f64 = col.iter().zip(w.iter()).map(|(a, b)| a * b).sum();
                    step[c] = -y[c] + jw / d[c];
                    trial[c] = x[c] + step[c];
                }
                self.pose(chain, g, &trial);
                posed = false;
                let c = self.cost(chain, targets, &trial, reference, lambda);
                if c < cost {
                    posed = true;
                    let size = step.iter().map(|v| v * v).sum::<f64>().sqrt();
                    std::mem::swap(&mut x, &mut trial);
                    cost = c;
                    damping = (damping / 10.0).max(1e-12);
                    accepted = size > 1e-9 * (1.0 + x.iter().map(|v| v * v).sum::<f64>().sqrt());
                    break;
                }
                damping *= 10.0;
            }
            if !accepted {
                break;
            }
        }
        self.jac = jac;
        self.small = small;
        // Leave the pose of the answer behind for the caller.
        if !posed {
            self.pose(chain, g, &x);
        }
        x
    }

    /// The objective at the pose last computed (at `x`).
    fn cost(
        &self,
        chain: &Chain,
        targets: &[Vector3<f64>],
        x: &[f64],
        reference: &[f64],
        lambda: &[f64],
    ) -> f64 {
        let reach: f64 = chain
            .ends
            .iter()
            .zip(targets)
            .map(|(&e, t)| (self.position[e] - t).norm_squared())
            .sum();
        let hold: f64 = x
            .iter()
            .zip(reference)
            .zip(lambda)
            .map(|((a, b), l)| l * (a - b) * (a - b))
            .sum();
        reach + hold
    }
}

/// The right Jacobian of SO(3)'s exp map at `w`: `exp(w + δ) ≈ exp(w) · exp(J_r(w) δ)`.
pub fn right_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = w.norm_squared();
    let k = w.cross_matrix();
    if t2 < 1e-12 {
        return Matrix3::identity() - 0.5 * k + k * k / 6.0;
    }
    let t = t2.sqrt();
    Matrix3::identity() - (1.0 - t.cos()) / t2 * k + (t - t.sin()) / (t2 * t) * k * k
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::rotation::{exp, from_euler};

    /// A small humanoid-ish tree: a spine with two arms, inner joints 1..=6, ends 7..=9.
    fn chain() -> Chain {
        let l = |parent: usize, t: [f64; 3], inner: Option<usize>| Link {
            parent: Some(parent),
            translation: Vector3::from(t),
            inner,
        };
        let links = vec![
            Link {
                parent: None,
                translation: Vector3::zeros(),
                inner: None,
            },
            l(0, [0.0, 10.0, 0.0], Some(0)),
            l(1, [0.0, 12.0, 1.0], Some(1)),
            l(2, [8.0, 2.0, 0.0], Some(2)),
            l(3, [15.0, 0.0, 0.0], Some(3)),
            l(2, [-8.0, 2.0, 0.0], Some(4)),
            l(5, [-15.0, 0.0, 1.0], Some(5)),
            l(4, [14.0, 0.0, 0.0], None),
            l(6, [-14.0, 0.5, 0.0], None),
            l(2, [0.0, 9.0, 0.0], None),
        ];
        Chain::new(links, vec![7, 8, 9]).unwrap()
    }

    fn geodesics(k: usize) -> Geodesics {
        let mut poses = Vec::new();
        for f in 0..80 {
            let s = f as f64 * 0.1;
            for j in 0..6 {
                let a = (s + j as f64).sin() * 40.0;
                let b = (0.7 * s - j as f64).cos() * 25.0;
                poses.push(from_euler([2, 0, 1], [a, b, 0.3 * a - b]));
            }
        }
        Geodesics::fit(&poses, 6, k).unwrap()
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        let c = chain();
        // A fitted model and the canonical one (whose Jacobian skips the zeros).
        for g in [geodesics(8), Geodesics::canonical(geodesics(1).mean)] {
            check_jacobian(&c, &g);
        }
    }

    fn check_jacobian(c: &Chain, g: &Geodesics) {
        let mut s = Solver::new(c, g.dims());
        let x: Vec<f64> = (0..g.dims())
            .map(|i| 0.3 * (i as f64 + 1.0).sin())
            .collect();
        s.pose(c, g, &x);
        let mut jac = DMatrix::zeros(9, g.dims());
        s.jacobian(c, g, &x, &mut jac);
        let ends = |s: &mut Solver, x: &[f64]| -> Vec<f64> {
            s.pose(c, g, x);
            c.ends()
                .iter()
                .flat_map(|&e| s.position(e).iter().copied().collect::<Vec<_>>())
                .collect()
        };
        let h = 1e-6;
        for i in 0..g.dims() {
            let (mut a, mut b) = (x.clone(), x.clone());
            a[i] += h;
            b[i] -= h;
            let (pa, pb) = (ends(&mut s, &a), ends(&mut s, &b));
            for r in 0..9 {
                let fd = (pa[r] - pb[r]) / (2.0 * h);
                assert!(
                    (fd - jac[(r, i)]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "({r}, {i}): {fd} vs {}",
                    jac[(r, i)]
                );
            }
        }
    }

    #[test]
    fn the_right_jacobian_linearises_exp() {
        for w in [Vector3::new(0.3, -1.2, 0.5), Vector3::new(1e-8, 0.0, 2e-8)] {
            let d = Vector3::new(1e-6, -2e-6, 1.5e-6);
            let lhs = exp(&(w + d));
            let rhs = exp(&w) * exp(&(right_jacobian(&w) * d));
            assert!(lhs.angle_to(&rhs) < 1e-11);
        }
    }

    #[test]
    fn ik_finds_coordinates_that_reach_reachable_targets() {
        let c = chain();
        let g = geodesics(6);
        let mut s = Solver::new(&c, g.dims());
        let truth: Vec<f64> = (0..g.dims())
            .map(|i| 0.4 * (2.0 * i as f64).cos())
            .collect();
        s.pose(&c, &g, &truth);
        let targets: Vec<_> = c.ends().iter().map(|&e| s.position(e)).collect();
        // From nearby, as from the previous frame, with a light hold.
        let start: Vec<f64> = truth.iter().map(|v| v + 0.05).collect();
        let x = s.solve(&c, &g, &targets, &start, &start, &[1e-6; 6], 50);
        s.pose(&c, &g, &x);
        for (n, &e) in c.ends().iter().enumerate() {
            assert!((s.position(e) - targets[n]).norm() < 1e-4, "end {n}");
        }
    }
}
