//! `mdtt-shared` — MDTT's database mode (Hou et al. 2015): instead of a spatial basis per
//! take, `K` bases shared by a library, learned once by deterministic annealing; each clip is
//! coded with whichever of them suits it best, and a take stores no basis of its own.
//!
//! Training ([`train_set`]) alternates, as the paper does, soft assignments `W` of clips to
//! bases (`W_ik ∝ exp(−d_ik / T)`, `d_ik` the energy of clip `i` that the leading `r` columns
//! of basis `k` miss) and bases from the assignments (eigenvectors of `Σ_i W_ik X_i X_iᵀ`),
//! halving the temperature `T` each round until assignments are hard. `K` is chosen by the
//! total stored size of the training takes, bases included.
//!
//! Departures from the paper: the rank `k`, bandwidth `l` and step are searched per take for
//! the fewest bytes that meet the bound (as in per-take `mdtt`); bases are stored whole
//! (all `3J` columns, f32) so that each take picks its own rank; the residual layer holds max
//! bounds.

use nalgebra::DMatrix;

use super::search::{self, Bandwidth, Choice, Plan, Shape};
use super::transform::{clip_len, ratio, reconstruct, Analysis};
use super::{decode_clip, encode_coefs, Params};
use crate::codec::basis::{Basis, BasisKind, Matrix};
use crate::codec::container::estimated_bytes;
use crate::codec::entropy::{Decoder, Encoder, IntModel};
use crate::codec::error::{malformed, Error, Result};
use crate::codec::measure::max_mean;
use crate::codec::rate::{self, Ceiling, Smallest, Trial};
use crate::codec::residual;
use crate::codec::wire::{Reader, Writer};
use crate::codec::{ChunkDecoder, ChunkOut, Codec, CodecId, CodecOutput, Input, Target};
use crate::rng::Rng;

const PARAMS_VERSION: u8 = 1;

/// A take's parameters: clip shape, steps and mean; the bases are the library's.
#[derive(Debug, Clone, PartialEq)]
struct SharedParams {
    clip: usize,
    k: usize,
    l: usize,
    coef_step: f64,
    residual_t: f64,
    mean: Vec<f32>,
}

impl SharedParams {
    fn coding(&self) -> super::ClipCoding {
        super::ClipCoding {
            clip: self.clip,
            k: self.k,
            l: self.l,
            coef_step: self.coef_step,
            residual_t: self.residual_t,
        }
    }

    fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.bytes(&[PARAMS_VERSION]);
        w.u32(self.clip as u32)
            .u32(self.k as u32)
            .u32(self.l as u32)
            .f64(self.coef_step)
            .f64(self.residual_t);
        for &m in &self.mean {
            w.f32(m);
        }
        w.0
    }

    fn parse(b: &[u8], width: usize) -> Result<SharedParams> {
        let mut r = Reader::new(b);
        let v = r.u8()?;
        if v != PARAMS_VERSION {
            return Err(Error::Unsupported(format!(
                "mdtt-shared parameters version {v}"
            )));
        }
        let (clip, k, l) = (r.u32()? as usize, r.u32()? as usize, r.u32()? as usize);
        let (coef_step, residual_t) = (r.f64()?, r.f64()?);
        if clip == 0 || clip > crate::codec::MAX_CLIP || k == 0 || k > width || l == 0 || l > clip {
            return Err(malformed(format!(
                "mdtt-shared shape L={clip} k={k} l={l} for {width} coordinates"
            )));
        }
        if !(coef_step.is_finite() && coef_step > 0.0 && residual_t.is_finite()) || residual_t < 0.0
        {
            return Err(malformed("mdtt-shared steps are out of range"));
        }
        let mean = (0..width).map(|_| r.f32()).collect::<Result<Vec<_>>>()?;
        r.finish()?;
        Ok(SharedParams {
            clip,
            k,
            l,
            coef_step,
            residual_t,
            mean,
        })
    }

    /// The per-basis [`Params`] the shared reconstruction takes: the leading `k` columns of
    /// each basis, column-major.
    fn per_basis(&self, bases: &[Matrix]) -> Vec<Params> {
        let w = self.mean.len();
        bases
            .iter()
            .map(|m| {
                let mut basis = Vec::with_capacity(w * self.k);
                for c in 0..self.k {
                    basis.extend((0..w).map(|r| m.at(r, c)));
                }
                Params {
                    clip: self.clip,
                    k: self.k,
                    l: self.l,
                    coef_step: self.coef_step,
                    residual_t: self.residual_t,
                    basis_bits: vec![0; self.k],
                    mean: self.mean.clone(),
                    basis,
                }
            })
            .collect()
    }
}

fn check_basis(b: &Basis, width: usize) -> Result<()> {
    if b.kind() != BasisKind::MdttSet {
        return Err(Error::Basis(format!(
            "mdtt-shared needs an mdtt-set basis, got {}",
            b.kind()
        )));
    }
    if b.points() * 3 != width {
        return Err(Error::Basis(format!(
            "basis for {} points, take has {}",
            b.points(),
            width / 3
        )));
    }
    Ok(())
}

/// Code the take with rank `c.k`, bandwidth `c.l` and step (no basis of its own, so no
/// basis precision): each clip with the basis whose leading `k` columns keep most of its
/// energy.
fn code(input: &Input<'_>, a: &mut Analysis, bases: &[Matrix], c: Choice, rt: f64) -> Trial {
    let w = a.w;
    let Choice {
        k, l, coef_step, ..
    } = c;
    let params = SharedParams {
        clip: a.clip,
        k,
        l,
        coef_step,
        residual_t: rt,
        mean: a.mean.clone(),
    };
    let per = params.per_basis(bases);
    let mut recon_all = vec![0f32; input.data.len()];
    let mut chunks = Vec::with_capacity(a.clips.len());
    for i in 0..a.clips.len() {
        let (f0, len) = a.clips[i];
        let lc = a.lc(len, l).min(a.coefs[i].ncols());
        let x = a.coefs[i].columns(0, lc);
        // Project on each basis's leading k columns; keep the one that holds most energy.
        let mut best = (0usize, f64::NEG_INFINITY, DMatrix::<f64>::zeros(k, lc));
        for (b, p) in per.iter().enumerate() {
            let bk = DMatrix::from_fn(w, k, |r, c| f64::from(p.basis[c * w + r]));
            let s = bk.transpose() * x;
            let kept = s.norm_squared();
            if kept > best.1 {
                best = (b, kept, s);
            }
        }
        let (b, _, s) = best;
        let mut enc = Encoder::new();
        IntModel::default().encode(&mut enc, b as i32);
        let deq = encode_coefs(&mut enc, &s, coef_step);
        let recon = &mut recon_all[f0 * w..(f0 + len) * w];
        reconstruct(
            &per[b],
            &deq,
            a.tables.get(len, lc),
            (len, lc),
            0..len,
            recon,
        );
        if rt > 0.0 {
            let valid = input
                .valid
                .map(|v| &v[f0 * input.points..(f0 + len) * input.points]);
            residual::encode(
                &mut enc,
                &input.data[f0 * w..(f0 + len) * w],
                recon,
                valid,
                input.points,
                rt,
            );
        }
        chunks.push(ChunkOut {
            frames: len,
            bytes: enc.finish(),
        });
    }
    let (max, mean) = max_mean(input.data, &recon_all, input.valid);
    let out = CodecOutput {
        params: params.to_bytes(),
        chunks,
    };
    Trial::new(out, max, mean)
}

/// `mdtt-shared`'s search: the ladder's rank kept, the smallest of its own bandwidth scan
/// (which codes the paper's ratio again), no basis precision (the bases are the library's),
/// no step tried at or past 64× the first, and where nothing meets a mean bound with the
/// residual layer at the max, the residual layer at 3, 1.4 and 1 times the mean. Each of
/// these differs from mdtt's, and each choice is part of the bytes it writes.
const PLAN: Plan = Plan {
    refine_rank: false,
    bandwidths: &[0.6, 0.8, 1.0, 1.3, 1.7, 2.2],
    bandwidth: Bandwidth::SmallestScanned,
    gamma: 0.0,
    gammas: &[],
    ceiling: Ceiling::Tried(64.0),
    fallbacks: &[3.0, 1.4, 1.0],
};

pub struct MdttShared;

impl Codec for MdttShared {
    fn id(&self) -> CodecId {
        CodecId::MdttShared
    }

    fn basis_kind(&self) -> Option<BasisKind> {
        Some(BasisKind::MdttSet)
    }

    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput> {
        let basis = input
            .shared
            .ok_or_else(|| Error::Basis("mdtt-shared needs an mdtt-set basis".into()))?;
        check_basis(basis, input.width())?;
        let bases = basis.matrices();
        let shape = Shape::new(input, target);
        let found = rate::with_fallback_residuals(target, PLAN.fallbacks, |rt| {
            let mut a = Analysis::new(input, shape.clip, shape.l(shape.w, 3.0));
            search::run(&shape, target, &PLAN, |c| code(input, &mut a, bases, c, rt))
        });
        let (best, _) = found.ok_or_else(|| Error::BoundMissed {
            codec: "mdtt-shared".into(),
            detail: format!("no setting meets {target}"),
        })?;
        Ok(best.out)
    }

    fn versions(&self) -> &'static [u8] {
        &[PARAMS_VERSION]
    }

    fn decoder(
        &self,
        params: &[u8],
        points: usize,
        shared: &crate::codec::Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        let basis = shared
            .basis
            .clone()
            .ok_or_else(|| Error::Basis("mdtt-shared needs its basis".into()))?;
        check_basis(&basis, points * 3)?;
        let p = SharedParams::parse(params, points * 3)?;
        let per = p.per_basis(basis.matrices());
        let full = super::FullClipTable::new(p.clip, p.l);
        Ok(Box::new(SharedDecoder {
            p,
            per,
            points,
            full,
        }))
    }

    /// As per-take `mdtt`, a clip DCT needs about a second of motion to be worth it.
    fn unsuited(&self, motion: &crate::motion::Motion) -> Option<String> {
        let (frames, points, fps) = (motion.frame_count(), motion.point_count(), motion.fps);
        if let Err(e) = super::check_points(points) {
            return Some(e.to_string());
        }
        let seconds = frames as f64 / fps;
        (seconds < 0.5).then(|| format!("take is {seconds:.2} s; clips need at least 0.5 s"))
    }
}

struct SharedDecoder {
    p: SharedParams,
    per: Vec<Params>,
    points: usize,
    full: super::FullClipTable,
}

impl ChunkDecoder for SharedDecoder {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        self.decode_rows(bytes, frames, 0..frames, out)
    }

    fn decode_rows(
        &self,
        bytes: &[u8],
        frames: usize,
        rows: std::ops::Range<usize>,
        out: &mut [f32],
    ) -> Result<()> {
        let mut dec = Decoder::new(bytes);
        let b = IntModel::default().decode(&mut dec);
        let basis = usize::try_from(b)
            .ok()
            .and_then(|b| self.per.get(b))
            .ok_or_else(|| malformed(format!("mdtt-shared chunk names basis {b}")))?;
        decode_clip(
            &mut dec,
            self.p.coding(),
            basis,
            &self.full,
            self.points,
            frames,
            rows,
            out,
        )
    }
}

/// How to train a set.
#[derive(Debug, Clone)]
pub struct SetOptions {
    /// Candidate numbers of bases; the one with the smallest total size wins.
    pub ks: Vec<usize>,
    /// Annealing rounds (the temperature halves each round).
    pub rounds: usize,
    pub seed: u64,
}

impl Default for SetOptions {
    fn default() -> Self {
        SetOptions {
            ks: vec![1, 2, 4, 8],
            rounds: 24,
            seed: 1,
        }
    }
}

/// A trained set and how it was chosen.
pub struct TrainedSet {
    pub basis: Basis,
    /// `(K, total bytes of the training takes coded with it, basis bytes)` per candidate.
    pub sizes: Vec<(usize, usize, usize)>,
    /// Rank at which the annealing measured distortion.
    pub rank: usize,
    /// Hard distortion `Σ_i min_k d_ik` after each round, for the chosen `K`.
    pub distortion: Vec<f64>,
    pub clips: usize,
}

/// Clips of training takes as the annealing sees them: covariances of their leading DCT
/// coefficients (each take about its own mean), energies, the global basis and the rank at
/// which distortion is measured (99.5 % of the energy).
struct Clips {
    covs: Vec<DMatrix<f64>>,
    energy: Vec<f64>,
    global: DMatrix<f64>,
    rank: usize,
}

fn clips_of(takes: &[Input<'_>]) -> Result<(Clips, usize)> {
    let first = takes
        .first()
        .ok_or_else(|| Error::Invalid("no takes to train on".into()))?;
    let (points, w) = (first.points, first.width());
    if takes.iter().any(|t| t.points != points) {
        return Err(Error::Invalid("takes of different layouts".into()));
    }
    let mut covs = Vec::new();
    for t in takes {
        let clip = clip_len(t.fps).min(t.frames);
        if clip == 0 {
            // A take without frames has no clip to learn from.
            continue;
        }
        let l = ((ratio(clip, t.fps) * w as f64 * 0.5).round() as usize).clamp(1, clip);
        let a = Analysis::new(t, clip, l);
        covs.extend(a.coefs.iter().map(|x| x * x.transpose()));
    }
    if covs.is_empty() {
        return Err(Error::Invalid("no frames in the takes to train on".into()));
    }
    let energy: Vec<f64> = covs.iter().map(|c| c.trace()).collect();
    let total: DMatrix<f64> = covs.iter().fold(DMatrix::zeros(w, w), |a, c| a + c);
    let (global, values) = eigen_full(&total);
    let sum: f64 = values.iter().sum();
    let mut acc = 0.0;
    let rank = values
        .iter()
        .position(|v| {
            acc += v;
            acc >= 0.995 * sum
        })
        .map_or(w, |i| i + 1);
    Ok((
        Clips {
            covs,
            energy,
            global,
            rank,
        },
        points,
    ))
}

/// `k` bases by deterministic annealing, and the hard distortion after each temperature.
fn bases_for(c: &Clips, k: usize, opts: &SetOptions) -> (Vec<DMatrix<f64>>, Vec<f64>) {
    let k = k.clamp(1, c.covs.len().max(1));
    if k == 1 {
        let d = c
            .covs
            .iter()
            .zip(&c.energy)
            .map(|(cv, e)| e - kept(&c.global, cv, c.rank))
            .sum();
        return (vec![c.global.clone()], vec![d]);
    }
    anneal(&c.covs, &c.energy, &c.global, k, c.rank, opts)
}

/// Train exactly `k` shared bases (no choice of `K`): for tests and callers that know it.
pub fn train_bases(takes: &[Input<'_>], k: usize, opts: &SetOptions) -> Result<Basis> {
    if let Some(t) = takes.first() {
        super::check_points(t.points)?;
    }
    let (c, points) = clips_of(takes)?;
    to_basis(points, &bases_for(&c, k, opts).0)
}

/// Train `K` shared bases for takes of one layout (inputs gap-filled, in consistent units)
/// and choose `K` by the total size of those takes coded at `targets`, bases included.
pub fn train_set(takes: &[Input<'_>], targets: &[Target], opts: &SetOptions) -> Result<TrainedSet> {
    if let Some(t) = takes.first() {
        super::check_points(t.points)?;
    }
    let (c, points) = clips_of(takes)?;
    let mut sizes = Vec::new();
    let mut best = Smallest::new();
    let mut tried = Vec::new();
    for &kk in &opts.ks {
        let kk = kk.clamp(1, c.covs.len().max(1));
        if tried.contains(&kk) {
            continue;
        }
        tried.push(kk);
        let (bases, dist) = bases_for(&c, kk, opts);
        let basis = to_basis(points, &bases)?;
        let mut bytes = 0usize;
        for (t, &target) in takes.iter().zip(targets) {
            let input = Input {
                shared: Some(&basis),
                ..*t
            };
            let out = MdttShared.encode(&input, target)?;
            bytes += estimated_bytes(out.params.len(), &out.chunks);
        }
        let basis_bytes = basis.bytes().len();
        sizes.push((kk, bytes, basis_bytes));
        best.offer(bytes + basis_bytes, (basis, dist));
    }
    let (basis, distortion) = best
        .into_best()
        .ok_or_else(|| Error::Invalid("no candidate K".into()))?;
    Ok(TrainedSet {
        basis,
        sizes,
        rank: c.rank,
        distortion,
        clips: c.covs.len(),
    })
}

/// Energy of a clip (covariance `c`) that the leading `r` columns of `b` keep.
fn kept(b: &DMatrix<f64>, c: &DMatrix<f64>, r: usize) -> f64 {
    let br = b.columns(0, r);
    (br.transpose() * c * br).trace()
}

/// Deterministic annealing for `k` bases; returns them and the hard distortion per round.
fn anneal(
    covs: &[DMatrix<f64>],
    energy: &[f64],
    global: &DMatrix<f64>,
    k: usize,
    r: usize,
    opts: &SetOptions,
) -> (Vec<DMatrix<f64>>, Vec<f64>) {
    let n = covs.len();
    let w = global.nrows();
    let mut rng = Rng::new(opts.seed);
    let d_global: f64 = covs
        .iter()
        .zip(energy)
        .map(|(c, e)| e - kept(global, c, r))
        .sum::<f64>()
        / n as f64;
    let mut temp = d_global.max(1e-12);
    // Seeds as in k-means++: a random clip, then repeatedly the clip the seeds so far fit
    // worst. Their bases give the first soft assignments; starting from the global basis
    // instead leaves every basis equal, a fixed point the annealing cannot leave when
    // leading eigenvalues tie.
    let mut seeds: Vec<DMatrix<f64>> = vec![eigen_full(&covs[rng.below(n)]).0];
    while seeds.len() < k {
        let worst = (0..n)
            .max_by(|&a, &b| {
                let da = seeds
                    .iter()
                    .map(|s| energy[a] - kept(s, &covs[a], r))
                    .fold(f64::INFINITY, f64::min);
                let db = seeds
                    .iter()
                    .map(|s| energy[b] - kept(s, &covs[b], r))
                    .fold(f64::INFINITY, f64::min);
                da.total_cmp(&db)
            })
            .unwrap_or(0);
        seeds.push(eigen_full(&covs[worst]).0);
    }
    let mut weights: Vec<Vec<f64>> = covs
        .iter()
        .zip(energy)
        .map(|(c, e)| {
            let d: Vec<f64> = seeds.iter().map(|s| e - kept(s, c, r)).collect();
            let dmin = d.iter().copied().fold(f64::INFINITY, f64::min);
            let p: Vec<f64> = d.iter().map(|x| (-(x - dmin) / temp).exp()).collect();
            let s: f64 = p.iter().sum();
            p.into_iter().map(|x| x / s).collect()
        })
        .collect();
    let mut bases = seeds;
    let mut distortion = Vec::new();
    // A few alternations at each temperature before it halves: cooling after a single one
    // freezes the first, poor split.
    const PER_TEMPERATURE: usize = 5;
    let mut assigned: Vec<usize> = vec![usize::MAX; n];
    // Every clip's assignment nearly hard in the last alternation: the split has happened.
    let mut all_hard = false;
    for step in 0..opts.rounds * PER_TEMPERATURE {
        let round = step / PER_TEMPERATURE;
        for (j, b) in bases.iter_mut().enumerate() {
            let mut c = DMatrix::<f64>::zeros(w, w);
            for (cov, wt) in covs.iter().zip(&weights) {
                if wt[j] > 1e-12 {
                    c += cov * wt[j];
                }
            }
            *b = eigen_full(&c).0;
        }
        let mut hard = 0.0;
        let mut settled = true;
        let quiet = all_hard || noise_off(round, opts.rounds);
        let mut hard_now = true;
        for (i, (cov, e)) in covs.iter().zip(energy).enumerate() {
            let d: Vec<f64> = bases.iter().map(|b| e - kept(b, cov, r)).collect();
            let dmin = d.iter().copied().fold(f64::INFINITY, f64::min);
            hard += dmin;
            // While the temperature is high the bases coincide and nothing breaks the tie:
            // a little noise on the assignments lets them split at the critical temperature
            // (the paper's perturbation); the last rounds run without it.
            let noise = if quiet { 0.0 } else { 0.1 };
            let p: Vec<f64> = d
                .iter()
                .map(|x| (-(x - dmin) / temp).exp() * (1.0 + noise * (rng.unit() - 0.5)))
                .collect();
            let s: f64 = p.iter().sum();
            weights[i] = p.into_iter().map(|x| x / s).collect();
            let (best, top) =
                weights[i]
                    .iter()
                    .enumerate()
                    .fold((0, 0.0), |a, (j, &v)| if v > a.1 { (j, v) } else { a });
            settled &= top > 1.0 - 1e-9 && assigned[i] == best;
            hard_now &= top > 0.99;
            assigned[i] = best;
        }
        all_hard = hard_now;
        // Hard assignments that did not change: the bases are final (large layouts would
        // otherwise pay for every remaining eigendecomposition).
        if settled && quiet {
            distortion.push(hard);
            break;
        }
        if step % PER_TEMPERATURE == PER_TEMPERATURE - 1 {
            distortion.push(hard);
            temp /= 2.0;
        }
    }
    (bases, distortion)
}

/// The perturbation stops for the last rounds (and once assignments are hard).
fn noise_off(round: usize, rounds: usize) -> bool {
    round + 4 >= rounds
}

/// All eigenvectors (columns, largest eigenvalue first, signs fixed) and eigenvalues.
fn eigen_full(c: &DMatrix<f64>) -> (DMatrix<f64>, Vec<f64>) {
    let eig = nalgebra::SymmetricEigen::new(c.clone());
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let mut b = DMatrix::<f64>::zeros(c.nrows(), c.ncols());
    for (dst, &src) in order.iter().enumerate() {
        let mut v = eig.eigenvectors.column(src).clone_owned();
        let imax = v.iamax();
        if v[imax] < 0.0 {
            v = -v;
        }
        b.set_column(dst, &v);
    }
    let values = order.iter().map(|&i| eig.eigenvalues[i].max(0.0)).collect();
    (b, values)
}

fn to_basis(points: usize, bases: &[DMatrix<f64>]) -> Result<Basis> {
    let matrices = bases
        .iter()
        .map(|b| Matrix {
            rows: b.nrows(),
            cols: b.ncols(),
            data: (0..b.nrows() * b.ncols())
                .map(|i| b[(i / b.ncols(), i % b.ncols())] as f32)
                .collect(),
        })
        .collect();
    Basis::new(BasisKind::MdttSet, points, matrices)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::mdtt::tests::smooth;

    #[test]
    fn annealing_two_bases_fits_two_styles_better_than_one() {
        // Clips of two kinds, each of rank 2 in its own coordinates: one basis needs rank 4
        // to hold both, two bases hold each at rank 2.
        let w = 6;
        let mut rng = Rng::new(9);
        let covs: Vec<DMatrix<f64>> = (0..40)
            .map(|i| {
                let x = DMatrix::from_fn(w, 8, |r, _| {
                    let active = if i % 2 == 0 {
                        r < 2
                    } else {
                        (2..4).contains(&r)
                    };
                    if active {
                        rng.unit() * 10.0 - 5.0
                    } else {
                        (rng.unit() - 0.5) * 0.01
                    }
                });
                &x * x.transpose()
            })
            .collect();
        let energy: Vec<f64> = covs.iter().map(|c| c.trace()).collect();
        let total = covs.iter().fold(DMatrix::zeros(w, w), |a, c| a + c);
        let global = eigen_full(&total).0;
        let one: f64 = covs
            .iter()
            .zip(&energy)
            .map(|(c, e)| e - kept(&global, c, 2))
            .sum();
        let opts = SetOptions::default();
        let (bases, d) = anneal(&covs, &energy, &global, 2, 2, &opts);
        assert_eq!(bases.len(), 2);
        let two = *d.last().unwrap();
        assert!(two < 0.01 * one, "two bases {two}, one {one}");
        // The hard distortion never rises once assignments settle.
        assert!(
            d.windows(2).skip(4).all(|p| p[1] <= p[0] * (1.0 + 1e-9)),
            "{d:?}"
        );
    }

    #[test]
    fn k_is_chosen_by_total_size_with_the_bases() {
        let (points, w) = (5, 15);
        let a = smooth(600, points);
        // A second "style": the same motion with coordinates permuted, so two bases fit.
        let b: Vec<f32> = a
            .chunks_exact(w)
            .flat_map(|f| (0..w).map(move |c| f[(c * 7) % w]))
            .collect();
        let inputs: Vec<Input<'_>> = [&a, &b]
            .iter()
            .map(|d| Input {
                data: d,
                valid: None,
                frames: 600,
                points,
                fps: 120.0,
                shared: None,
                skeleton: None,
                names: &[],
                torso: None,
            })
            .collect();
        let t = train_set(
            &inputs,
            &[Target::max(0.5), Target::max(0.5)],
            &SetOptions {
                ks: vec![1, 2],
                rounds: 12,
                seed: 3,
            },
        )
        .unwrap();
        assert_eq!(t.sizes.len(), 2);
        let chosen = t.basis.matrices().len();
        let best = t.sizes.iter().min_by_key(|s| s.1 + s.2).unwrap();
        assert_eq!(chosen, best.0);
        // Hard distortion settles (the last rounds agree) once the temperature is low.
        if chosen == 2 {
            let d = &t.distortion;
            assert!((d[d.len() - 1] - d[d.len() - 2]).abs() <= 1e-6 * d[0].abs().max(1.0));
        }
        // Each basis is orthonormal.
        for m in t.basis.matrices() {
            let b = DMatrix::from_row_slice(m.rows, m.cols, &m.data).map(f64::from);
            assert!((b.transpose() * &b - DMatrix::identity(w, w)).norm() < 1e-4);
        }
    }
}
