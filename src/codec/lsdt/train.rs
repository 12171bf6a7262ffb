//! Algorithm 1 of the LSDT paper: for one coordinate (x, y or z), the orthogonal `J × J`
//! matrix `B` minimising `Σ‖B mᵢ − eᵢ‖²` subject to `‖eᵢ‖₀ ≤ P`, where `mᵢ` are the `J`-point
//! samples. It alternates the two exact sub-problems, so the objective never increases:
//! - given `B`, the best `eᵢ` keeps the `P` largest-magnitude entries of `B mᵢ`;
//! - given `E`, the best orthogonal `B` is `Ṽ Ũᵀ` from the SVD `M Eᵀ = Ũ Σ Ṽᵀ` (orthogonal
//!   Procrustes).

use nalgebra::DMatrix;

use crate::codec::dct;
use crate::rng::Rng;

/// Where the iteration starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Init {
    /// The orthonormal DCT-II (the paper's choice).
    Dct,
    /// A random orthogonal matrix (QR of Gaussian-ish noise), for the paper's Fig. 3 check.
    Random(u64),
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainOptions {
    /// Non-zeros kept per sample (the paper's P = 8).
    pub sparsity: usize,
    pub max_iterations: usize,
    /// Stop when the objective improves by less than this fraction.
    pub tolerance: f64,
    pub init: Init,
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            sparsity: 8,
            max_iterations: 50,
            tolerance: 1e-6,
            init: Init::Dct,
        }
    }
}

/// A trained transform and the objective after each iteration (index 0: the initial `B`).
#[derive(Debug, Clone)]
pub struct Trained {
    /// `J × J`, orthogonal; apply as `B m`.
    pub basis: DMatrix<f64>,
    pub objective: Vec<f64>,
}

/// Train on `samples` (`J × N`: one column per sample of the `J` points' coordinate).
pub fn train(samples: &DMatrix<f64>, opts: &TrainOptions) -> Trained {
    let j = samples.nrows();
    let mut b = match opts.init {
        Init::Dct => {
            // dct::basis is L × l with columns as basis vectors; B applies them as rows.
            let d = dct::basis(j, j);
            DMatrix::from_fn(j, j, |r, c| d[c * j + r])
        }
        Init::Random(seed) => random_orthogonal(j, seed),
    };
    let p = opts.sparsity.min(j);
    let (mut e, mut obj) = sparse_codes(&b, samples, p);
    let mut objective = vec![obj];
    for _ in 0..opts.max_iterations {
        b = procrustes(samples, &e);
        let (e2, o2) = sparse_codes(&b, samples, p);
        let improved = obj - o2;
        e = e2;
        obj = o2;
        objective.push(obj);
        if improved <= opts.tolerance * obj.abs().max(f64::MIN_POSITIVE) {
            break;
        }
    }
    Trained {
        basis: b,
        objective,
    }
}

/// A trained LSDT basis and each coordinate's run.
pub struct TrainedBasis {
    pub basis: crate::codec::Basis,
    /// x, y, z.
    pub runs: [Trained; 3],
    /// Frames the samples were drawn from.
    pub samples: usize,
}

/// Train the three per-coordinate transforms of a layout on the frames of `takes` (each
/// `frames × points × 3`, NaN for gaps; frames with a gap are left out), using at most
/// `max_samples` frames spread evenly over all of them.
pub fn train_basis(
    takes: &[&[f32]],
    points: usize,
    opts: &TrainOptions,
    max_samples: usize,
) -> crate::codec::Result<TrainedBasis> {
    train_basis_reporting(takes, points, opts, max_samples, &mut |_| {})
}

/// As [`train_basis`], calling `done(d)` as each coordinate's transform is trained.
pub fn train_basis_reporting(
    takes: &[&[f32]],
    points: usize,
    opts: &TrainOptions,
    max_samples: usize,
    done: &mut dyn FnMut(usize),
) -> crate::codec::Result<TrainedBasis> {
    let w = points * 3;
    if points == 0 {
        return Err(crate::codec::Error::Invalid("no points to train on".into()));
    }
    let complete: Vec<&[f32]> = takes
        .iter()
        .flat_map(|t| t.chunks_exact(w))
        .filter(|f| f.iter().all(|v| v.is_finite()))
        .collect();
    if complete.is_empty() {
        return Err(crate::codec::Error::Invalid(
            "no complete frame to train on".into(),
        ));
    }
    let n = complete.len().min(max_samples.max(1));
    let stride = complete.len() as f64 / n as f64;
    let picked: Vec<&[f32]> = (0..n)
        .map(|i| complete[((i as f64 * stride) as usize).min(complete.len() - 1)])
        .collect();
    let runs = [0, 1, 2].map(|d| {
        let m = DMatrix::from_fn(points, n, |p, c| f64::from(picked[c][p * 3 + d]));
        let mut t = train(&m, opts);
        t.basis = by_energy(&t.basis, &m);
        done(d);
        t
    });
    let basis = super::spatial::basis_from([&runs[0].basis, &runs[1].basis, &runs[2].basis])?;
    Ok(TrainedBasis {
        basis,
        runs,
        samples: n,
    })
}

/// `B` with its rows in order of decreasing energy over the samples (`Σ (B M)²` per row).
/// Any row order is as orthogonal and as sparse; this one lets the codecs code where a
/// coordinate's last non-zero coefficient is and skip the zeros after it.
fn by_energy(b: &DMatrix<f64>, m: &DMatrix<f64>) -> DMatrix<f64> {
    let e = b * m;
    let energy: Vec<f64> = e.row_iter().map(|r| r.norm_squared()).collect();
    let mut order: Vec<usize> = (0..b.nrows()).collect();
    order.sort_by(|&x, &y| energy[y].total_cmp(&energy[x]));
    DMatrix::from_fn(b.nrows(), b.ncols(), |r, c| b[(order[r], c)])
}

/// The best `P`-sparse codes for `B`, and the objective `‖B M − E‖²`.
fn sparse_codes(b: &DMatrix<f64>, m: &DMatrix<f64>, p: usize) -> (DMatrix<f64>, f64) {
    let mut e = b * m;
    let mut residual = 0.0;
    let mut mags: Vec<f64> = Vec::with_capacity(e.nrows());
    for mut col in e.column_iter_mut() {
        mags.clear();
        mags.extend(col.iter().map(|v| v.abs()));
        if p < mags.len() {
            // The P-th largest magnitude; entries below it are dropped (ties keep the first).
            let k = mags.len() - p;
            let threshold = *mags.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
            let mut kept = 0;
            for v in col.iter_mut() {
                if v.abs() >= threshold && kept < p {
                    kept += 1;
                } else {
                    residual += *v * *v;
                    *v = 0.0;
                }
            }
        }
    }
    (e, residual)
}

/// The orthogonal `B` maximising `tr(B M Eᵀ)`: `Ṽ Ũᵀ` from the SVD of `M Eᵀ`.
fn procrustes(m: &DMatrix<f64>, e: &DMatrix<f64>) -> DMatrix<f64> {
    let svd = (m * e.transpose()).svd(true, true);
    let u = svd.u.expect("SVD computed U");
    let v_t = svd.v_t.expect("SVD computed Vᵀ");
    v_t.transpose() * u.transpose()
}

fn random_orthogonal(j: usize, seed: u64) -> DMatrix<f64> {
    let mut rng = Rng::new(seed);
    // Sum of uniforms: close enough to Gaussian for a random rotation's starting point.
    let g = DMatrix::from_fn(j, j, |_, _| (0..4).map(|_| rng.unit()).sum::<f64>() - 2.0);
    g.qr().q()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples that really are sparse in a hidden orthogonal basis, plus a little noise.
    fn sparse_data(j: usize, n: usize, p: usize) -> (DMatrix<f64>, DMatrix<f64>) {
        let hidden = random_orthogonal(j, 99);
        let mut rng = Rng::new(5);
        let mut codes = DMatrix::zeros(j, n);
        for c in 0..n {
            for _ in 0..p {
                codes[(rng.below(j), c)] = rng.unit() * 10.0 - 5.0;
            }
        }
        let noise = DMatrix::from_fn(j, n, |_, _| (rng.unit() - 0.5) * 0.01);
        (hidden.transpose() * codes + noise, hidden)
    }

    #[test]
    fn learned_basis_is_orthogonal_and_the_objective_never_rises() {
        let (m, _) = sparse_data(16, 400, 3);
        let t = train(
            &m,
            &TrainOptions {
                sparsity: 3,
                ..TrainOptions::default()
            },
        );
        let eye = DMatrix::<f64>::identity(16, 16);
        assert!((t.basis.transpose() * &t.basis - &eye).norm() < 1e-6);
        assert!(
            t.objective.windows(2).all(|w| w[1] <= w[0] * (1.0 + 1e-12)),
            "{:?}",
            t.objective
        );
        // It finds the sparsifying basis: the residual falls far below the DCT start.
        assert!(
            t.objective.last().unwrap() < &(t.objective[0] * 0.05),
            "{:?}",
            t.objective
        );
    }

    #[test]
    fn dct_and_random_starts_reach_similar_objectives() {
        let (m, _) = sparse_data(12, 300, 4);
        let opts = TrainOptions {
            sparsity: 4,
            max_iterations: 200,
            ..TrainOptions::default()
        };
        let a = train(&m, &opts);
        let b = train(
            &m,
            &TrainOptions {
                init: Init::Random(7),
                ..opts
            },
        );
        let (fa, fb) = (*a.objective.last().unwrap(), *b.objective.last().unwrap());
        let total = m.norm_squared();
        assert!((fa - fb).abs() < 0.01 * total, "{fa} vs {fb} of {total}");
    }
}
