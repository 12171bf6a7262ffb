//! `quant`: uniform scalar quantisation with the step derived from the bound, temporal
//! prediction of the integers (first or second order, whichever is smaller per chunk), and
//! the adaptive range coder. Prediction works on the integers, so it is lossless and the
//! error stays exactly the quantiser's: at most step/2 per coordinate, step·√3/2 per point.

use super::entropy::{magnitude_context, Decoder, Encoder, IntModel};
use super::error::{malformed, Error, Result};
use super::measure::{max_mean, quantise};
use super::wire::Reader;
use super::{
    default_chunk_frames, ChunkDecoder, ChunkOut, Codec, CodecId, CodecOutput, Input, Target,
};

/// Context classes per neighbour (magnitude buckets, see `magnitude_context`).
const BUCKETS: usize = 6;
/// Trajectories back whose residual at the same frame conditions the model: the same axis
/// of the previous point, which moves with this one more often than not.
const NEIGHBOUR: usize = 3;

/// Model index from the previous residual in time and the neighbour's at this frame.
#[inline]
fn context(previous: i32, neighbour: i32) -> usize {
    magnitude_context(previous, BUCKETS) * BUCKETS + magnitude_context(neighbour, BUCKETS)
}

mod tables;

pub struct Quant;

/// Quantise with `step` and reconstruct, as the decoder will.
pub fn dequantised(data: &[f32], step: f64) -> Vec<f32> {
    data.iter()
        .map(|&x| (f64::from(quantise(f64::from(x) / step)) * step) as f32)
        .collect()
}

/// The largest step whose reconstruction meets `target`.
pub fn step_for(data: &[f32], valid: Option<&[bool]>, target: Target) -> Result<f64> {
    let meets = |step: f64| {
        let (max, mean) = max_mean(data, &dequantised(data, step), valid);
        target.holds(max, mean)
    };
    let amplitude = data.iter().fold(0f64, |a, &x| a.max(f64::from(x).abs()));
    // Integers must stay well inside i32 after prediction (which can double them).
    let min_step = amplitude / f64::from(1 << 28);
    // Per coordinate error ≤ step/2, so step = 2t/√3 meets a max bound of t by
    // construction, and a mean bound of t too.
    let t = target.tightest();
    let mut step = 2.0 * t / 3f64.sqrt();
    if target.mean.is_some() {
        // The mean error of uniform quantisation is ~0.48·step: grow while both bounds
        // hold (the max stops it where the mean does not), then bisect.
        let (mut lo, mut hi) = (step, step);
        while meets(hi) && hi < 1e12 {
            lo = hi;
            hi *= 2.0;
        }
        for _ in 0..30 {
            let mid = (lo * hi).sqrt();
            if meets(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        step = lo;
    }
    // Float rounding of the reconstruction can put a sample a hair over; shrink until not.
    for _ in 0..200 {
        if step < min_step {
            break;
        }
        if meets(step) {
            return Ok(step);
        }
        step *= 0.999;
    }
    Err(Error::Invalid(format!(
        "bound {t} is too tight to quantise coordinates of magnitude {amplitude}"
    )))
}

impl Codec for Quant {
    fn id(&self) -> CodecId {
        CodecId::Quant
    }

    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput> {
        encode_version(input, target, None)
    }

    /// 1: the step alone (8 bytes); 2: rANS tables, its version first.
    fn versions(&self) -> &'static [u8] {
        &[1, tables::VERSION]
    }

    fn version_of(&self, params: &[u8]) -> Option<u8> {
        if params.len() == 8 {
            Some(1)
        } else {
            params.first().copied()
        }
    }

    fn decoder(
        &self,
        params: &[u8],
        _points: usize,
        _shared: &super::Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        // Version 1 parameters are the step alone; later ones start with their version.
        if params.len() == 8 {
            let mut r = Reader::new(params);
            let step = r.f64()?;
            r.finish()?;
            if !(step.is_finite() && step > 0.0) {
                return Err(malformed("quant step is not positive"));
            }
            return Ok(Box::new(QuantDecoder { step }));
        }
        match params.split_first() {
            Some((&tables::VERSION, rest)) => Ok(Box::new(tables::Tables::parse(rest)?)),
            _ => Err(malformed("quant parameters of an unknown version")),
        }
    }
}

/// Encode with parameters `version` 1 or 2, or (`None`) with whichever codes the take
/// smaller, as [`Quant`] does.
pub fn encode_version(
    input: &Input<'_>,
    target: Target,
    version: Option<u8>,
) -> Result<CodecOutput> {
    let step = step_for(input.data, input.valid, target)?;
    let w = input.width();
    let q: Vec<i32> = input
        .data
        .iter()
        .map(|&x| quantise(f64::from(x) / step))
        .collect();
    let per = default_chunk_frames(input.fps);
    let starts: Vec<(usize, usize)> = (0..input.frames)
        .step_by(per)
        .map(|f0| (f0, per.min(input.frames - f0)))
        .collect();
    // Version 2 (rANS against per-take tables) decodes about twice as fast; version 1
    // (adaptive binary contexts) is smaller on some takes (measured on the corpus:
    // version 2 is 5 % smaller on the Bandai and misc BVH takes, 2–6 % larger on CMU
    // and C3D, 10 % on TRC). Both are coded and the smaller kept, so no take grows.
    let symbols: Vec<tables::ChunkSymbols> = starts
        .iter()
        .map(|&(f0, n)| tables::chunk_symbols(&q[f0 * w..(f0 + n) * w], n, w))
        .collect();
    let (params, coded) = tables::encode(step, &symbols.iter().collect::<Vec<_>>());
    let v1: Vec<Vec<u8>> = starts
        .iter()
        .map(|&(f0, n)| {
            let block = &q[f0 * w..(f0 + n) * w];
            let a = encode_block(block, n, w, 1);
            let b = encode_block(block, n, w, 2);
            if b.len() < a.len() {
                b
            } else {
                a
            }
        })
        .collect();
    let size = |p: usize, c: &[Vec<u8>]| p + c.iter().map(Vec::len).sum::<usize>();
    let first = match version {
        Some(1) => true,
        Some(tables::VERSION) => false,
        Some(v) => return Err(Error::Invalid(format!("quant has no version {v}"))),
        None => size(8, &v1) < size(params.len(), &coded),
    };
    let (params, coded) = if first {
        (step.to_le_bytes().to_vec(), v1)
    } else {
        (params, coded)
    };
    let chunks = starts
        .iter()
        .zip(coded)
        .map(|(&(_, n), bytes)| ChunkOut { frames: n, bytes })
        .collect();
    Ok(CodecOutput { params, chunks })
}

#[inline]
fn predict(prev1: i32, prev2: i32, f: usize, order: u8) -> i32 {
    match (f, order) {
        (0, _) => 0,
        (1, _) | (_, 1) => prev1,
        _ => prev1.wrapping_mul(2).wrapping_sub(prev2),
    }
}

/// The integers the entropy stage sees for one chunk (`frames × w` quantised values):
/// trajectory after trajectory, the first value as is, then prediction residuals.
pub fn prediction_residuals(q: &[i32], frames: usize, w: usize, order: u8) -> Vec<i32> {
    let mut out = Vec::with_capacity(q.len());
    for c in 0..w {
        let (mut p1, mut p2) = (0i32, 0i32);
        for f in 0..frames {
            let v = q[f * w + c];
            out.push(v.wrapping_sub(predict(p1, p2, f, order)));
            p2 = p1;
            p1 = v;
        }
    }
    out
}

/// How many points back a trajectory may take its reference from.
const MAX_REFERENCE: usize = 8;

/// Pick the reference for trajectory `c`: 0 for none, or `k` for trajectory `c − 3k` (the
/// same axis of a point `k` before), whichever leaves the smallest differences. Points on
/// one rigid segment accelerate alike, so their prediction residuals nearly cancel — and
/// duplicated points (zero-length bones, a marker exported twice) cancel exactly.
fn choose_reference(r: &[i32], c: usize, frames: usize) -> usize {
    let own = &r[c * frames..(c + 1) * frames];
    let cost = |reference: Option<&[i32]>| -> u64 {
        own.iter()
            .enumerate()
            .map(|(f, &v)| u64::from(v.wrapping_sub(reference.map_or(0, |x| x[f])).unsigned_abs()))
            .sum()
    };
    let mut best = (cost(None), 0);
    for k in 1..=MAX_REFERENCE.min(c / 3) {
        let rc = c - 3 * k;
        let cand = cost(Some(&r[rc * frames..(rc + 1) * frames]));
        if cand < best.0 {
            best = (cand, k);
        }
    }
    best.1
}

/// Integers of one chunk (`frames × w`) → bytes: the predictor order, then per trajectory
/// its reference (`choose_reference`) and the differences of its
/// [`prediction_residuals`] from the reference's, through the range coder, each in the
/// context of the previous difference and of the neighbouring trajectory's residual.
pub fn encode_block(q: &[i32], frames: usize, w: usize, order: u8) -> Vec<u8> {
    let mut enc = Encoder::new();
    let mut m = BlockModels::new();
    let residuals = prediction_residuals(q, frames, w, order);
    for c in 0..w {
        let k = choose_reference(&residuals, c, frames);
        m.reference.encode(&mut enc, k as i32);
        let mut last = 0;
        for f in 0..frames {
            let d = residuals[c * frames + f]
                .wrapping_sub(reference_value(&residuals, c, k, f, frames));
            if f == 0 {
                m.intra.encode(&mut enc, d);
            } else {
                m.diffs[diff_context(&residuals, c, f, frames, last)].encode(&mut enc, d);
                last = d;
            }
        }
    }
    let mut out = vec![order];
    out.extend(enc.finish());
    out
}

#[inline]
fn reference_value(r: &[i32], c: usize, k: usize, f: usize, frames: usize) -> i32 {
    if k == 0 {
        0
    } else {
        r[(c - 3 * k) * frames + f]
    }
}

struct BlockModels {
    reference: IntModel,
    intra: IntModel,
    diffs: Vec<IntModel>,
}

impl BlockModels {
    fn new() -> Self {
        BlockModels {
            reference: IntModel::default(),
            intra: IntModel::default(),
            diffs: vec![IntModel::default(); BUCKETS * BUCKETS],
        }
    }
}

/// Context of a difference: the previous one on this trajectory and the neighbouring
/// trajectory's residual at the same frame.
#[inline]
fn diff_context(r: &[i32], c: usize, f: usize, frames: usize, last: i32) -> usize {
    let above = if c >= NEIGHBOUR {
        r[(c - NEIGHBOUR) * frames + f]
    } else {
        0
    };
    context(last, above)
}

/// A chunk's predictor order (its first byte, 1 or 2) and the bytes after it: the same in
/// every version.
fn split_order(bytes: &[u8]) -> Result<(u8, &[u8])> {
    let (&order, rest) = bytes
        .split_first()
        .ok_or_else(|| malformed("empty quant chunk"))?;
    if order != 1 && order != 2 {
        return Err(malformed(format!("predictor order {order}")));
    }
    Ok((order, rest))
}

/// Inverse of [`encode_block`].
pub fn decode_block(
    bytes: &[u8],
    frames: usize,
    w: usize,
    mut emit: impl FnMut(usize, i32),
) -> Result<()> {
    let (order, rest) = split_order(bytes)?;
    let mut dec = Decoder::new(rest);
    let mut m = BlockModels::new();
    let mut residuals = vec![0i32; w * frames];
    for c in 0..w {
        let k = m.reference.decode(&mut dec);
        let k = usize::try_from(k)
            .ok()
            .filter(|&k| k <= MAX_REFERENCE && 3 * k <= c)
            .ok_or_else(|| malformed(format!("trajectory {c} refers {k} points back")))?;
        let (mut p1, mut p2, mut last) = (0i32, 0i32, 0i32);
        for f in 0..frames {
            let d = if f == 0 {
                m.intra.decode(&mut dec)
            } else {
                let d = m.diffs[diff_context(&residuals, c, f, frames, last)].decode(&mut dec);
                last = d;
                d
            };
            let r = d.wrapping_add(reference_value(&residuals, c, k, f, frames));
            residuals[c * frames + f] = r;
            let v = r.wrapping_add(predict(p1, p2, f, order));
            emit(f * w + c, v);
            p2 = p1;
            p1 = v;
        }
    }
    if dec.overran() {
        return Err(malformed("quant chunk ends early"));
    }
    Ok(())
}

struct QuantDecoder {
    step: f64,
}

impl ChunkDecoder for tables::Tables {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        let w = out.len() / frames.max(1);
        let step = self.step;
        self.decode(bytes, frames, w, |i, v| {
            out[i] = (f64::from(v) * step) as f32
        })
    }
}

/// Version 1: the step alone in the parameters, every chunk through the adaptive binary
/// coder ([`decode_block`]).
impl ChunkDecoder for QuantDecoder {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        let w = out.len() / frames.max(1);
        let step = self.step;
        decode_block(bytes, frames, w, |i, v| {
            out[i] = (f64::from(v) * step) as f32
        })
    }
}
