//! `mdtt` — Hou, Chau, Magnenat-Thalmann, He, "Human Motion Capture Data Tailored Transform
//! Coding", IEEE TVCG 21(7), 2015, with a residual layer for max-error bounds.
//!
//! The take (`frames × 3n`, per-coordinate mean removed) is cut into clips of `L` frames
//! (the paper's best L ≈ 280 at 120 fps, scaled with the frame rate). Each clip's
//! trajectories are projected on the first `l` DCT-II vectors, `M_i D̃_i`; the take's
//! spatial basis `B` is the `k` leading eigenvectors of `C = Σ M_i D̃_i D̃_iᵀ M_iᵀ`, and a
//! clip is coded as `S_i = Bᵀ M_i D̃_i` (k × l), quantised and range coded. `B` and the mean
//! travel once per take in the header; each clip is one chunk.
//!
//! Departures from the paper, and why:
//! - `l = r·k` starts from the paper's `r = 0.1·⌈L₁₂₀/50⌉`, where `L₁₂₀` is the clip length
//!   in 120 fps frames (r relates temporal bandwidth to spatial rank, so it must not change
//!   when the same motion is sampled at 30 fps); the search then also tries other ratios.
//! - The coefficient step is searched from the bound rather than the paper's `Q` fractional
//!   bits, which are tied to the units of the paper's data.
//! - `B` is stored at 16 bits per entry as in the paper when that is what the bound needs,
//!   otherwise at 10–14 bits, range coded.
//! - `k`, `l`, the steps are searched per take for the fewest bytes that meet the bound on
//!   decoded output; for max bounds a residual layer ([`super::residual`]) corrects the
//!   samples the truncated transform leaves too far (clip-edge ringing, fast moves).
//!
//! # Layout
//! - [`params`]: the header block (shape, steps, mean, basis) and its bytes.
//! - [`transform`]: clip DCTs, covariance, eigenvectors, the shared inverse.
//! - [`database`]: the database mode, `mdtt-shared` — `K` bases shared by a library.
//! - this module: candidate coding, the parameter search, the chunk decoder.

pub mod database;
pub mod params;
mod search;
pub mod transform;

use nalgebra::DMatrix;

use super::entropy::{Decoder, Encoder, IntModel};
use super::error::{malformed, Error, Result};
use super::linalg::LeastSquares;
use super::measure::{max_mean, quantise};
use super::rate::{self, Ceiling, Trial};
use super::residual;
use super::{ChunkDecoder, ChunkOut, Codec, CodecId, CodecOutput, Input, Target};
pub use params::Params;
use params::{quantise_basis, MAX_BASIS_BITS};
use search::{Bandwidth, Choice, Plan, Shape};
use transform::clips_for;
pub use transform::{clip_len, ratio, ClipMode};
use transform::{coefs_for, reconstruct, Analysis};

pub struct Mdtt;

/// Range-coder context of coefficient (basis `b`, frequency `j`): both indices on a log
/// scale, since energy falls off along both.
fn coef_context(b: usize, j: usize) -> usize {
    let lg = |v: usize| (usize::BITS - v.leading_zeros()) as usize;
    lg(b).min(5) * 6 + lg(j).min(5)
}
const COEF_CONTEXTS: usize = 36;

/// Rounding offset taken off each coefficient's magnitude before rounding: values within
/// 0.5 + DEADZONE of zero become zero. Small coefficients cost more bits than the error
/// they remove; the decoder is unaffected (it only multiplies by the step).
const DEADZONE: f64 = 0.2;

#[inline]
fn deadzone(x: f64, dz: f64) -> i32 {
    let m = (x.abs() - dz).max(0.0);
    quantise(m).saturating_mul(if x < 0.0 { -1 } else { 1 })
}

/// Quantise and code a clip's `k × lc` coefficients; returns them dequantised, as the
/// decoder will see them. Shared by per-take and shared-basis MDTT.
fn encode_coefs(enc: &mut Encoder, s: &DMatrix<f64>, step: f64) -> Vec<f32> {
    let (k, lc) = s.shape();
    let mut models = vec![IntModel::default(); COEF_CONTEXTS];
    let mut deq = vec![0f32; k * lc];
    for b in 0..k {
        for j in 0..lc {
            let q = deadzone(s[(b, j)] / step, DEADZONE);
            models[coef_context(b, j)].encode(enc, q);
            deq[b * lc + j] = (f64::from(q) * step) as f32;
        }
    }
    deq
}

/// Decode what [`encode_coefs`] wrote.
fn decode_coefs(dec: &mut Decoder<'_>, k: usize, lc: usize, step: f64) -> Vec<f32> {
    let mut models = vec![IntModel::default(); COEF_CONTEXTS];
    let mut deq = vec![0f32; k * lc];
    for b in 0..k {
        for j in 0..lc {
            let q = models[coef_context(b, j)].decode(dec);
            deq[b * lc + j] = (f64::from(q) * step) as f32;
        }
    }
    deq
}

/// The DCT table of a full clip (`clip × l`), kept by a decoder and made when it first
/// decodes a full clip: a decoder that serves only a short take's one shorter clip (or reads
/// a header claiming long clips) never tabulates it. Shorter clips' tables are kept beside
/// it.
struct FullClipTable {
    clip: usize,
    l: usize,
    table: std::sync::OnceLock<Vec<f32>>,
    short: ShortTables,
}

impl FullClipTable {
    fn new(clip: usize, l: usize) -> Self {
        FullClipTable {
            clip,
            l,
            table: std::sync::OnceLock::new(),
            short: ShortTables::default(),
        }
    }

    fn get(&self) -> &[f32] {
        self.table.get_or_init(|| {
            crate::codec::dct::basis(self.clip, self.l)
                .into_iter()
                .map(|v| v as f32)
                .collect()
        })
    }
}

/// Clips shorter than the full one whose DCT tables a decoder keeps: adaptive clips
/// ([`ClipMode::Adaptive`]) come in many lengths, and a table costs a `cos` per entry.
const SHORT_TABLES: usize = 32;

/// The DCT tables of shorter clips a decoder has made, by (length, kept), up to
/// [`SHORT_TABLES`] of them.
#[derive(Default)]
struct ShortTables(std::sync::Mutex<TablesByShape>);

/// DCT tables by (length, kept).
type TablesByShape = std::collections::HashMap<(usize, usize), std::sync::Arc<Vec<f32>>>;

impl ShortTables {
    fn get(&self, len: usize, keep: usize) -> std::sync::Arc<Vec<f32>> {
        let mut map = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(t) = map.get(&(len, keep)) {
            return t.clone();
        }
        let t: std::sync::Arc<Vec<f32>> = std::sync::Arc::new(
            crate::codec::dct::basis(len, keep)
                .into_iter()
                .map(|v| v as f32)
                .collect(),
        );
        if map.len() < SHORT_TABLES {
            map.insert((len, keep), t.clone());
        }
        t
    }
}

/// How a take's clips are coded: what [`decode_clip`] needs of the header's parameters
/// (`mdtt`'s own and `mdtt-shared`'s, whose bases live apart).
#[derive(Debug, Clone, Copy)]
struct ClipCoding {
    clip: usize,
    k: usize,
    l: usize,
    coef_step: f64,
    residual_t: f64,
}

impl Params {
    fn coding(&self) -> ClipCoding {
        ClipCoding {
            clip: self.clip,
            k: self.k,
            l: self.l,
            coef_step: self.coef_step,
            residual_t: self.residual_t,
        }
    }
}

/// Frames `rows` of a clip of `frames` frames into `out`, from its coefficients and
/// residual corrections (what `dec` reads next): `p` says how they were coded, `basis` is
/// what the coefficients weight. Only the rows asked for are
/// synthesised and the residual stream is read no further than the last of them, so a
/// range read of part of a clip costs part of its decode.
#[allow(clippy::too_many_arguments)]
fn decode_clip(
    dec: &mut Decoder<'_>,
    p: ClipCoding,
    basis: &Params,
    full: &FullClipTable,
    points: usize,
    frames: usize,
    rows: std::ops::Range<usize>,
    out: &mut [f32],
) -> Result<()> {
    if frames > p.clip || rows.end > frames {
        return Err(malformed(format!(
            "mdtt chunk of {frames} frames (rows {rows:?}), clips are {}",
            p.clip
        )));
    }
    let lc = coefs_for(frames, p.clip, p.l);
    let deq = decode_coefs(dec, p.k, lc, p.coef_step);
    if frames == p.clip {
        reconstruct(basis, &deq, full.get(), (frames, lc), rows.clone(), out);
    } else {
        let d = full.short.get(frames, lc);
        reconstruct(basis, &deq, &d, (frames, lc), rows.clone(), out);
    }
    if p.residual_t > 0.0 {
        residual::decode_rows(dec, out, points, p.residual_t, rows);
    }
    if dec.overran() {
        return Err(malformed("mdtt chunk ends early"));
    }
    Ok(())
}

/// Starting basis precision of the search (see [`basis_bits`]).
const GAMMA0: f64 = 0.17;

/// Per-column basis precision. An error δ in column b of B moves the reconstruction by
/// δ·‖S_b‖, where ‖S_b‖² is that column's eigenvalue λ_b (its coefficients' energy over the
/// take). Matching that to the coefficient quantisation error (N_b coefficients of step q)
/// gives a basis step of γ·q·√(N_b/λ_b): weak columns need far fewer bits than strong ones.
fn basis_bits(eigenvalues: &[f64], coefficients: usize, coef_step: f64, gamma: f64) -> Vec<u8> {
    eigenvalues
        .iter()
        .map(|&lambda| {
            if gamma == 0.0 {
                return 16;
            }
            let step = gamma * coef_step * (coefficients as f64 / lambda.max(1e-30)).sqrt();
            (-step.log2()).ceil().clamp(1.0, f64::from(MAX_BASIS_BITS)) as u8
        })
        .collect()
}

/// Code the take with choice `c`; `residual_t` > 0 adds the residual layer at that bound.
fn code(input: &Input<'_>, a: &mut Analysis, c: Choice, residual_t: f64) -> Trial {
    let w = a.w;
    let (basis, eigenvalues) = a.basis(c.l, c.k);
    let bits = basis_bits(
        &eigenvalues,
        a.coefficient_count(c.l),
        c.coef_step,
        c.basis_gamma,
    );
    let mut params = Params {
        clip: a.clip,
        k: c.k,
        l: c.l,
        coef_step: c.coef_step,
        residual_t,
        basis_bits: bits,
        mean: a.mean.clone(),
        basis: Vec::with_capacity(w * c.k),
    };
    for b in 0..c.k {
        for r in 0..w {
            params
                .basis
                .push(quantise_basis(basis[(r, b)], params.basis_bits[b]).1);
        }
    }
    // The stored basis is only nearly orthonormal, so project by least squares onto its
    // span, S = (B̂ᵀB̂)⁻¹ B̂ᵀ M D̃, rather than by B̂ᵀ: a coarsely stored weak column must not
    // pull energy out of the strong ones.
    let projector = LeastSquares::new(DMatrix::from_column_slice(
        w,
        c.k,
        &params
            .basis
            .iter()
            .map(|&v| f64::from(v))
            .collect::<Vec<_>>(),
    ));
    let mut chunks = Vec::with_capacity(a.clips.len());
    let mut recon_all = vec![0f32; input.data.len()];
    for i in 0..a.clips.len() {
        let (f0, len) = a.clips[i];
        let lc = a.lc(len, c.l).min(a.coefs[i].ncols());
        let s = projector.solve(a.coefs[i].columns(0, lc));
        let mut enc = Encoder::new();
        let deq = encode_coefs(&mut enc, &s, c.coef_step);
        let recon = &mut recon_all[f0 * w..(f0 + len) * w];
        reconstruct(
            &params,
            &deq,
            a.tables.get(len, lc),
            (len, lc),
            0..len,
            recon,
        );
        if residual_t > 0.0 {
            let valid = input
                .valid
                .map(|v| &v[f0 * input.points..(f0 + len) * input.points]);
            let orig = &input.data[f0 * w..(f0 + len) * w];
            residual::encode(&mut enc, orig, recon, valid, input.points, residual_t);
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

/// The residual layer holds every sample to the max bound; a mean bound is met by the
/// transform.
fn residual_for(target: Target) -> f64 {
    target.max
}

/// MDTT's bases are `3J × 3J`, found by an eigendecomposition of that size: refuse layouts
/// past [`crate::limits::MDTT_MAX_POINTS`] before allocating anything of that size.
pub fn check_points(points: usize) -> Result<()> {
    let limit = crate::limits::MDTT_MAX_POINTS;
    if points > limit {
        return Err(Error::Limit {
            what: "points for an MDTT basis",
            actual: points as u64,
            limit: limit as u64,
        });
    }
    Ok(())
}

/// Encode with fixed parameters (the paper's setting): rank `k`, `l = r·k`, coefficient
/// step `coef_step`, 16-bit basis.
pub fn encode_with(
    input: &Input<'_>,
    k: usize,
    coef_step: f64,
    target: Target,
) -> Result<CodecOutput> {
    check_points(input.points)?;
    if input.frames == 0 {
        return Err(Error::Invalid(
            "mdtt codes clips of frames: the take has none".into(),
        ));
    }
    let w = input.width();
    let k = k.clamp(1, w);
    let clip = clip_len(input.fps).min(input.frames);
    let l = ((ratio(clip, input.fps) * k as f64).round() as usize).clamp(1, clip);
    let mut a = Analysis::new(input, clip, l);
    let c = Choice {
        k,
        l,
        coef_step,
        basis_gamma: 0.0,
    };
    Ok(code(input, &mut a, c, residual_for(target)).out)
}

/// Search the parameters for the fewest bytes that meet `target`, with clips cut as `mode`
/// says.
pub fn encode_clips(input: &Input<'_>, target: Target, mode: ClipMode) -> Result<CodecOutput> {
    check_points(input.points)?;
    let shape = Shape::new(input, target);
    let found = rate::with_fallback_residuals(target, PLAN.fallbacks, |rt| {
        let clips = clips_for(input, shape.clip, mode);
        let mut a = Analysis::with_clips(input, shape.clip, shape.l(shape.w, 3.0), clips);
        search::run(&shape, target, &PLAN, |c| code(input, &mut a, c, rt))
    });
    let (best, _) = found.ok_or_else(|| Error::BoundMissed {
        codec: "mdtt".into(),
        detail: format!("no setting meets {target}"),
    })?;
    Ok(best.out)
}

/// Per-take MDTT's search: ranks refined beside the best rung, the basis precision
/// searched, and where nothing meets a mean bound with the residual layer at the max, the
/// residual layer at 3, 2, 1.4 and 1 times the mean (noise-like or tiny takes).
const PLAN: Plan = Plan {
    refine_rank: true,
    bandwidths: &[0.6, 0.8, 1.3, 1.7, 2.2, 3.0],
    bandwidth: Bandwidth::OfTheBest,
    gamma: GAMMA0,
    gammas: &[0.0, 0.08, 0.12, 0.25, 0.5],
    ceiling: Ceiling::FromBelow(64.0),
    fallbacks: &[3.0, 2.0, 1.4, 1.0],
};

impl Codec for Mdtt {
    fn id(&self) -> CodecId {
        CodecId::Mdtt
    }

    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput> {
        encode_clips(input, target, ClipMode::Equal)
    }

    /// A per-take basis costs more than it saves on takes under a second (measured on the
    /// Bandai takes, mean 6 s, where mdtt already loses at max bounds).
    fn unsuited(&self, motion: &crate::motion::Motion) -> Option<String> {
        let (frames, points, fps) = (motion.frame_count(), motion.point_count(), motion.fps);
        if let Err(e) = check_points(points) {
            return Some(e.to_string());
        }
        let seconds = frames as f64 / fps;
        (seconds < 1.0).then(|| {
            format!("take is {seconds:.2} s; a per-take basis needs at least 1 s to pay for itself")
        })
    }

    /// One layout, with no version byte.
    fn versions(&self) -> &'static [u8] {
        &[1]
    }

    fn version_of(&self, _params: &[u8]) -> Option<u8> {
        Some(1)
    }

    fn decoder(
        &self,
        params: &[u8],
        points: usize,
        _shared: &super::Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        let p = Params::parse(params, points)?;
        let full = FullClipTable::new(p.clip, p.l);
        Ok(Box::new(MdttDecoder { p, points, full }))
    }
}

struct MdttDecoder {
    p: Params,
    points: usize,
    /// DCT table of a full clip; the last, shorter clip computes its own.
    full: FullClipTable,
}

impl ChunkDecoder for MdttDecoder {
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
        let p = &self.p;
        let mut dec = Decoder::new(bytes);
        decode_clip(
            &mut dec,
            p.coding(),
            p,
            &self.full,
            self.points,
            frames,
            rows,
            out,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::transform::clips;
    use super::*;
    use crate::codec::linalg::leading_eigenvectors;

    /// A smooth synthetic motion of full spatial rank: every coordinate mixes eight
    /// sinusoids with its own (pseudo-random) weights.
    pub(crate) fn smooth(frames: usize, points: usize) -> Vec<f32> {
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let w = points * 3;
        let weights: Vec<f64> = (0..w * 8).map(|_| rnd()).collect();
        let freqs = [0.4, 0.9, 1.3, 2.2, 3.1, 4.5, 6.0, 8.3];
        let mut d = Vec::with_capacity(frames * w);
        for f in 0..frames {
            let t = f as f64 / 120.0;
            for c in 0..w {
                let v: f64 = (0..8)
                    .map(|i| {
                        100.0 / (1.0 + i as f64)
                            * weights[c * 8 + i]
                            * (freqs[i] * t + c as f64).sin()
                    })
                    .sum();
                d.push((v + c as f64 * 10.0) as f32);
            }
        }
        d
    }

    #[test]
    fn adaptive_clips_start_where_the_behaviour_changes_and_meet_the_bound() {
        use crate::codec::{encode, EncodeOptions, ErrorBound};
        let m = crate::motion::synthetic::two_behaviours();
        let bound = ErrorBound::max(1.0);
        let enc = encode(
            &m,
            CodecId::Mdtt,
            bound,
            EncodeOptions::with_encoder(None, |i, t| encode_clips(i, t, ClipMode::Adaptive)),
        )
        .unwrap();
        let (max, _) = crate::codec::testing::measured(&m, &enc);
        assert!(max <= 1.0, "{max}");
        let starts_of = |enc: &crate::codec::Encoded| -> Vec<u32> {
            let chunks = &enc.container.header.chunks;
            chunks.iter().map(|c| c.first_frame).collect()
        };
        let starts = starts_of(&enc);
        // Equal clips start at multiples of 280 frames; adaptive ones at the cut near 400.
        assert!(
            starts.iter().any(|&s| s.abs_diff(400) <= 60),
            "clips start at {starts:?}"
        );
        let equal = encode(
            &m,
            CodecId::Mdtt,
            bound,
            EncodeOptions::with_encoder(None, |i, t| encode_clips(i, t, ClipMode::Equal)),
        )
        .unwrap();
        assert_eq!(starts_of(&equal), vec![0, 280, 560]);
    }

    #[test]
    fn basis_and_coefficients_match_a_dense_svd_reference() {
        let (frames, points) = (600, 6);
        let data = smooth(frames, points);
        let input = Input {
            data: &data,
            valid: None,
            frames,
            points,
            fps: 120.0,
            shared: None,
            skeleton: None,
            names: &[],
            torso: None,
        };
        let (k, l) = (5, 3);
        let mut a = Analysis::new(&input, clip_len(120.0), l);
        let b = leading_eigenvectors(&a.covariance(l), k);

        // Reference: stack every clip's M_i D̃_i, computed naively from the DCT definition,
        // and take the left singular vectors of the stack.
        let w = points * 3;
        let clip = clip_len(120.0);
        let mut stacked = Vec::new();
        for (f0, len) in clips(frames, clip) {
            let lc = coefs_for(len, clip, l);
            for j in 0..lc {
                for c in 0..w {
                    // The codec removes the mean as stored (f32), so the reference does too.
                    let mean = f64::from(
                        ((0..frames).map(|f| f64::from(data[f * w + c])).sum::<f64>()
                            / frames as f64) as f32,
                    );
                    let s = if j == 0 {
                        (1.0 / len as f64).sqrt()
                    } else {
                        (2.0 / len as f64).sqrt()
                    };
                    let v: f64 = (0..len)
                        .map(|t| {
                            let x = f64::from(data[(f0 + t) * w + c]) - mean;
                            x * s
                                * (std::f64::consts::PI * (t as f64 + 0.5) * j as f64 / len as f64)
                                    .cos()
                        })
                        .sum();
                    stacked.push(v);
                }
            }
        }
        let m = DMatrix::from_column_slice(w, stacked.len() / w, &stacked);
        let svd = m.clone().svd(true, false);
        let mut idx: Vec<usize> = (0..svd.singular_values.len()).collect();
        idx.sort_by(|&x, &y| svd.singular_values[y].total_cmp(&svd.singular_values[x]));
        let u = svd.u.unwrap();
        let uk = DMatrix::from_fn(w, k, |r, c| u[(r, idx[c])]);
        // Same subspace: the projectors agree.
        let diff = (&b * b.transpose() - &uk * uk.transpose()).norm();
        assert!(diff < 1e-8, "projector difference {diff}");
        // Same coefficients: S = Bᵀ M_i D̃_i for the first clip, from the naive stack.
        let lc0 = coefs_for(clip, clip, l);
        let s_ref = b.transpose() * m.columns(0, lc0);
        let s = b.transpose() * a.coefs[0].columns(0, lc0);
        assert!((s - s_ref).norm() < 1e-6);
        // B is orthonormal.
        assert!((b.transpose() * &b - DMatrix::identity(k, k)).norm() < 1e-10);
    }

    /// A range read of part of a clip synthesises only its rows and stops reading the
    /// residual stream after them: the rows must be bit for bit those of the whole clip,
    /// wherever they lie (first, middle, last rows; a short last clip), residual layer on.
    #[test]
    fn rows_of_a_clip_decode_as_the_whole_clip_does() {
        use crate::codec::testing::encoded;
        use crate::codec::{ErrorBound, Shared};
        let m = crate::motion::synthetic::walker(700, 7, 120.0, 5, 0.0);
        let enc = encoded(&m, CodecId::Mdtt, ErrorBound::max(0.3));
        let c = &enc.container;
        let dec = Mdtt
            .decoder(&c.header.params, 7, &Shared::default())
            .unwrap();
        let p = Params::parse(&c.header.params, 7).unwrap();
        assert!(p.residual_t > 0.0, "the residual layer is exercised");
        let w = 21;
        for (i, meta) in c.header.chunks.iter().enumerate() {
            let n = meta.frames as usize;
            let (_, bytes) = crate::codec::container::unpack_chunk(&c.chunks[i], n * 7).unwrap();
            let mut whole = vec![0f32; n * w];
            dec.decode_chunk(bytes, n, &mut whole).unwrap();
            for rows in [0..1, 0..n / 2, n / 3..n / 3 + 17, n - 5..n, n - 1..n] {
                let mut part = vec![0f32; rows.len() * w];
                dec.decode_rows(bytes, n, rows.clone(), &mut part).unwrap();
                let want = &whole[rows.start * w..rows.end * w];
                assert!(
                    part.iter()
                        .zip(want)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "chunk {i} rows {rows:?}"
                );
            }
            let mut past = vec![0f32; w];
            assert!(dec.decode_rows(bytes, n, n..n + 1, &mut past).is_err());
        }
    }
}
