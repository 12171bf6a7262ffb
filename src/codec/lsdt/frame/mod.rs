//! `lsdt-frame` — the zero-latency codec of Hou et al. 2016: each frame is predicted from the
//! previous *reconstructed* frame (closed loop, so quantisation error never accumulates), the
//! prediction residual is decorrelated by the shared LSDT basis, hard-thresholded, quantised
//! and entropy coded.
//!
//! Departures from the paper, and why:
//! - Periodic intra frames (the paper has none): every chunk starts with a frame coded
//!   without prediction, so any range decodes from the nearest chunk start. The period is
//!   the chunk length (about a second by default).
//! - Optional second-order prediction (`2x̂ₜ₋₁ − x̂ₜ₋₂`): on smooth capture at 120 fps it
//!   leaves a smaller residual than the paper's `x̂ₜ₋₁`; the encoder tries both.
//! - For max bounds the residual layer runs inside the loop: a frame is corrected before
//!   the next is predicted from it, so every sample meets the bound.
//! - The step is searched for the fewest bytes that meet the bound, not fixed.
//!
//! Two entropy stages share that loop ([`Quantiser`]):
//! - [`tables`] (parameters version 2), what whole takes are coded with: the encoder sees the
//!   take, fits a small parametric model per context and stores it with the take; chunks
//!   are rANS coded against those tables, which decodes several times faster than adaptive
//!   binary coding (the codec's point is speed) at about the same size.
//! - [`adaptive`] (version 1), what live streams are coded with, since their statistics are
//!   not known when the first chunk must go out: the adaptive binary range coder, one frame
//!   at a time ([`FrameEncoder`]).

mod adaptive;
mod tables;

use std::sync::Arc;

use super::spatial::{Scratch, Spatial};
use crate::codec::basis::{Basis, BasisKind};
use crate::codec::container::estimated_bytes;
use crate::codec::error::{malformed, Error, Result};
use crate::codec::measure::{max_mean, quantise};
use crate::codec::rate::{max_then_mean, Ladder, Ranked, Smallest};
use crate::codec::residual::FrameResidual;
use crate::codec::stream::{StreamCoder, StreamSpec, Streaming};
use crate::codec::wire::{Reader, Writer};
use crate::codec::{
    default_chunk_frames, ChunkDecoder, ChunkOut, Codec, CodecId, CodecOutput, Input, Target,
};

pub use adaptive::FrameEncoder;
pub use tables::{Shape, Tables};

/// Parameters of takes coded with the adaptive entropy stage.
const ADAPTIVE_VERSION: u8 = 1;
/// Parameters of takes coded against per-take tables (followed by the tables), the "left"
/// context two rows back; what batch encodes write.
const TABLES_VERSION: u8 = 3;
/// As version 3 with the "left" context one row back: still decoded.
const TABLES_V2: u8 = 2;

/// Values within `0.5 + DEADZONE` steps of zero quantise to zero (the paper's hard
/// threshold): small coefficients cost more bits than the error they remove.
const DEADZONE: f64 = 0.1;

/// How a take was coded: fixed for all its chunks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameParams {
    /// Coefficient quantisation step, in the take's units.
    pub step: f64,
    /// Residual-layer bound in the take's units; 0 for none.
    pub residual_t: f64,
    /// Frames per chunk: each chunk starts with an intra frame.
    pub intra_period: usize,
    /// Prediction order: 1 (previous frame) or 2 (linear extrapolation).
    pub order: u8,
}

/// The entropy stage a take's chunks were coded with.
#[derive(Debug, Clone)]
pub enum Coding {
    Adaptive,
    Tables(Tables),
}

impl FrameParams {
    /// Parameters of a take coded with the adaptive entropy stage (what streams use).
    pub fn to_bytes(&self) -> Vec<u8> {
        self.with_version(ADAPTIVE_VERSION).0
    }

    fn with_version(&self, version: u8) -> Writer {
        let mut w = Writer::new();
        w.bytes(&[version, self.order]);
        w.f64(self.step)
            .f64(self.residual_t)
            .u32(self.intra_period as u32);
        w
    }

    /// Parameters and entropy stage of a take.
    pub fn parse(b: &[u8]) -> Result<(FrameParams, Coding)> {
        let mut r = Reader::new(b);
        let version = r.u8()?;
        if ![ADAPTIVE_VERSION, TABLES_V2, TABLES_VERSION].contains(&version) {
            return Err(Error::Unsupported(format!(
                "lsdt-frame parameters version {version}"
            )));
        }
        let p = FrameParams {
            order: r.u8()?,
            step: r.f64()?,
            residual_t: r.f64()?,
            intra_period: r.u32()? as usize,
        };
        let finite = p.step.is_finite() && p.residual_t.is_finite();
        if !(finite && p.step > 0.0 && p.residual_t >= 0.0)
            || p.intra_period == 0
            || !(1..=2).contains(&p.order)
        {
            return Err(malformed(format!("lsdt-frame parameters {p:?}")));
        }
        let coding = if version != ADAPTIVE_VERSION {
            Coding::Tables(Tables::read(&mut r, version)?)
        } else {
            Coding::Adaptive
        };
        r.finish()?;
        Ok((p, coding))
    }
}

#[inline]
fn deadzone(x: f64) -> i32 {
    let m = (x.abs() - DEADZONE).max(0.0);
    quantise(m).saturating_mul(if x < 0.0 { -1 } else { 1 })
}

/// What encoder and decoder both keep within a chunk: the last reconstructions and the
/// residual layer. Reset at each intra frame.
struct Loop {
    p: FrameParams,
    w: usize,
    prev: Vec<f32>,
    prev2: Vec<f32>,
    /// Frames coded in the current chunk.
    n: usize,
    residual: Option<FrameResidual>,
}

impl Loop {
    fn new(p: FrameParams, points: usize) -> Loop {
        let w = points * 3;
        Loop {
            p,
            w,
            prev: vec![0.0; w],
            prev2: vec![0.0; w],
            n: 0,
            residual: (p.residual_t > 0.0).then(|| FrameResidual::new(points, p.residual_t)),
        }
    }

    fn reset(&mut self) {
        self.n = 0;
        if let Some(r) = &mut self.residual {
            *r = FrameResidual::new(self.w / 3, self.p.residual_t);
        }
    }

    /// The prediction of the next frame, written to `out`.
    #[inline]
    fn predict(&self, out: &mut [f32]) {
        match (self.n, self.p.order) {
            (0, _) => out.fill(0.0),
            (1, _) | (_, 1) => out.copy_from_slice(&self.prev),
            _ => {
                for ((o, &a), &b) in out.iter_mut().zip(&self.prev).zip(&self.prev2) {
                    *o = 2.0 * a - b;
                }
            }
        }
    }

    fn intra(&self) -> bool {
        self.n == 0
    }

    /// Remember the frame just reconstructed.
    fn advance(&mut self, recon: &[f32]) {
        std::mem::swap(&mut self.prev, &mut self.prev2);
        self.prev.copy_from_slice(recon);
        self.n += 1;
        if self.n == self.p.intra_period {
            self.reset();
        }
    }
}

/// The encoder's side of the loop, whatever the entropy stage: predict, transform the
/// residual, quantise, reconstruct as the decoder will, correct.
struct Quantiser {
    spatial: Arc<Spatial>,
    state: Loop,
    /// The last frame's coefficients, `[d][r]`.
    q: Vec<i32>,
    /// The last frame's reconstruction.
    recon: Vec<f32>,
    residual_buf: Vec<f64>,
    coefs: Vec<f64>,
    filled: Vec<f32>,
    present: Vec<bool>,
    scratch: Scratch,
}

impl Quantiser {
    fn new(p: FrameParams, spatial: Arc<Spatial>) -> Quantiser {
        let points = spatial.points();
        let w = points * 3;
        let scratch = spatial.scratch();
        Quantiser {
            spatial,
            state: Loop::new(p, points),
            q: vec![0; w],
            recon: vec![0.0; w],
            residual_buf: vec![0.0; w],
            coefs: vec![0.0; w],
            filled: vec![0.0; w],
            present: vec![true; points],
            scratch,
        }
    }

    /// Quantise one frame (`points × 3`; NaN or `valid[p] == false` marks a missing sample,
    /// which is coded as its prediction). Afterwards `q` holds its coefficients, the residual
    /// layer its corrections and `recon` what a decoder will reconstruct; code them, then
    /// [`Quantiser::advance`]. Returns whether this is an intra frame.
    fn quantise(&mut self, frame: &[f32], valid: Option<&[bool]>) -> bool {
        let w = self.state.w;
        debug_assert_eq!(frame.len(), w);
        let step = self.state.p.step;
        let intra = self.state.intra();
        self.state.predict(&mut self.recon);
        for i in 0..w {
            let missing = frame[i].is_nan() || valid.is_some_and(|v| !v[i / 3]);
            self.filled[i] = if missing { self.recon[i] } else { frame[i] };
            self.residual_buf[i] = f64::from(self.filled[i]) - f64::from(self.recon[i]);
        }
        self.spatial.forward(&self.residual_buf, &mut self.coefs);
        for (q, &c) in self.q.iter_mut().zip(&self.coefs) {
            *q = deadzone(c / step);
        }
        self.spatial
            .inverse_add(&self.q, step as f32, &mut self.scratch, &mut self.recon);
        if let Some(r) = &mut self.state.residual {
            for (p, ok) in self.present.iter_mut().enumerate() {
                *ok = valid.is_none_or(|v| v[p])
                    && !frame[p * 3..p * 3 + 3].iter().any(|x| x.is_nan());
            }
            r.correct(&self.filled, &mut self.recon, Some(&self.present));
        }
        intra
    }

    fn advance(&mut self) {
        self.state.advance(&self.recon);
    }

    /// End the chunk: the next frame is an intra frame.
    fn reset(&mut self) {
        self.state.reset();
    }
}

pub struct LsdtFrame;

/// Run the closed loop over every frame with fixed parameters; returns what it decided and
/// the (max, mean) error of its reconstruction. The entropy stage comes after, and only for
/// settings worth coding ([`tables::Recorder::finish`]).
fn quantise_take(
    input: &Input<'_>,
    spatial: &Arc<Spatial>,
    p: FrameParams,
) -> (tables::Recorder, f64, f64) {
    let w = input.width();
    let mut quantiser = Quantiser::new(p, spatial.clone());
    let mut frames = tables::Recorder::new(input.points);
    let mut recon = vec![0f32; input.data.len()];
    for f in 0..input.frames {
        let v = input
            .valid
            .map(|v| &v[f * input.points..(f + 1) * input.points]);
        let intra = quantiser.quantise(&input.data[f * w..(f + 1) * w], v);
        frames.record(intra, &quantiser.q, quantiser.state.residual.as_ref());
        recon[f * w..(f + 1) * w].copy_from_slice(&quantiser.recon);
        quantiser.advance();
    }
    let (max, mean) = max_mean(input.data, &recon, input.valid);
    (frames, max, mean)
}

/// The parameters a live stream is coded with when no search is possible: the bound as a
/// max bound (a mean bound is then met too), enforced by the residual layer, with the step
/// that the batch search most often picks.
pub fn stream_params(t: f64, fps: f64) -> FrameParams {
    FrameParams {
        step: 1.2 * t,
        residual_t: t,
        intra_period: default_chunk_frames(fps),
        order: 2,
    }
}

/// Encode with a given intra period (frames per chunk), searching step and order for the
/// fewest bytes that meet `target`.
pub fn encode_with_period(
    input: &Input<'_>,
    target: Target,
    intra_period: usize,
) -> Result<CodecOutput> {
    let spatial = Arc::new(Spatial::for_take(input.shared, input.points, "lsdt-frame")?);
    // Settings that meet the target, ranked by an estimate of their size; only the best few
    // are fitted with every context shape and coded (fitting all of them was most of the
    // search's time, and the estimate ranks settings as the coded sizes do but for near-ties).
    let mut ranked = Ranked::new(CODED_CANDIDATES);
    let period = intra_period.max(1);
    for order in [1u8, 2] {
        max_then_mean(target, SEARCH, |step, residual_t| {
            let p = FrameParams {
                step,
                residual_t,
                intra_period: period,
                order,
            };
            let (frames, max, mean) = quantise_take(input, &spatial, p);
            let met = target.holds(max, mean);
            if met {
                ranked.offer(frames.estimate_bits(), (p, frames));
            }
            met
        });
    }
    let mut best = Smallest::new();
    for (p, frames) in ranked.into_items() {
        let (tables, chunks) = frames.finish();
        let params = tables.params_bytes(&p);
        best.offer(
            estimated_bytes(params.len(), &chunks),
            CodecOutput { params, chunks },
        );
    }
    best.into_best().ok_or_else(|| Error::BoundMissed {
        codec: "lsdt-frame".into(),
        detail: format!("no setting meets {target}"),
    })
}

/// The steps [`encode_with_period`] tries for each prediction order: around the max bound
/// with the residual layer holding it (the fewest bytes meet a max bound there), and for
/// noise-like takes around a mean bound with the residual layer at the mean.
const SEARCH: Ladder = Ladder {
    at_max: &[0.6, 0.9, 1.2, 1.6, 2.2, 3.0],
    noise: &[1.2, 2.0],
};

/// How many of the settings a search found to meet its target are coded in full (see
/// [`encode_with_period`]).
const CODED_CANDIDATES: usize = 2;

impl Codec for LsdtFrame {
    fn id(&self) -> CodecId {
        CodecId::LsdtFrame
    }

    fn basis_kind(&self) -> Option<BasisKind> {
        Some(BasisKind::Lsdt)
    }

    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput> {
        encode_with_period(input, target, default_chunk_frames(input.fps))
    }

    /// 1: live streams (adaptive); 2 and 3: whole takes (tables).
    fn versions(&self) -> &'static [u8] {
        &[ADAPTIVE_VERSION, TABLES_V2, TABLES_VERSION]
    }

    fn decoder(
        &self,
        params: &[u8],
        points: usize,
        shared: &crate::codec::Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        let (p, coding) = FrameParams::parse(params)?;
        let spatial = Spatial::for_take(shared.basis.as_deref(), points, "lsdt-frame")?;
        Ok(match coding {
            Coding::Adaptive => Box::new(adaptive::Decoder::new(p, spatial)),
            Coding::Tables(t) => Box::new(tables::Decoder::new(p, spatial, &t)?),
        })
    }

    fn streaming(&self) -> Option<&dyn Streaming> {
        Some(self)
    }
}

/// Live streams: [`stream_params`] with the stream's chunk length as the intra period, and
/// the adaptive stage, coding each frame as it arrives.
impl Streaming for LsdtFrame {
    fn open(&self, spec: &StreamSpec<'_>, t: f64) -> Result<(Vec<u8>, Box<dyn StreamCoder>)> {
        let basis = spec.basis()?;
        let p = FrameParams {
            intra_period: spec.chunk_frames,
            ..stream_params(t, spec.fps)
        };
        let coder = FrameStream {
            encoder: FrameEncoder::new(p, basis)?,
            width: spec.points * 3,
        };
        Ok((p.to_bytes(), Box::new(coder)))
    }

    fn untrained_basis(&self, points: usize) -> Option<(Basis, &'static str)> {
        Some(super::spatial::untrained(points))
    }
}

struct FrameStream {
    encoder: FrameEncoder,
    width: usize,
}

impl StreamCoder for FrameStream {
    fn push(&mut self, frames: &[f32], flush: bool) -> Result<Vec<ChunkOut>> {
        let mut out = Vec::new();
        for f in frames.chunks_exact(self.width) {
            out.extend(self.encoder.push(f, None).1);
        }
        if flush {
            out.extend(self.encoder.flush());
        }
        Ok(out)
    }
}

/// Refuse a chunk longer than the intra period (its frames past the period would be
/// predicted across an intra frame the encoder never wrote).
fn check_chunk(p: &FrameParams, frames: usize) -> Result<()> {
    if frames > p.intra_period {
        return Err(malformed(format!(
            "lsdt-frame chunk of {frames} frames, intra period {}",
            p.intra_period
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::entropy::{get_varint, rans};
    use crate::codec::lsdt::spatial::dct_basis;

    /// Smooth trajectories with a little noise: what mocap looks like to the codec.
    fn motion(frames: usize, points: usize) -> Vec<f32> {
        let mut rng = 99u64;
        (0..frames * points * 3)
            .map(|i| {
                let (f, c) = ((i / (points * 3)) as f32, (i % (points * 3)) as f32);
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                let noise = (rng % 1000) as f32 / 1000.0 - 0.5;
                100.0 * (f * 0.03 + c * 0.7).sin() + 10.0 * c + 0.3 * noise
            })
            .collect()
    }

    fn take<'a>(
        data: &'a [f32],
        valid: Option<&'a [bool]>,
        points: usize,
        basis: &'a Basis,
    ) -> Input<'a> {
        Input {
            data,
            valid,
            frames: data.len() / (points * 3),
            points,
            fps: 120.0,
            shared: Some(basis),
            skeleton: None,
            names: &[],
            torso: None,
        }
    }

    /// Parameters, chunks and (max, mean) error of a take coded with fixed settings.
    fn code(
        input: &Input<'_>,
        spatial: &Arc<Spatial>,
        p: FrameParams,
    ) -> (Vec<u8>, Vec<ChunkOut>, f64, f64) {
        let (frames, max, mean) = quantise_take(input, spatial, p);
        let (tables, chunks) = frames.finish();
        (tables.params_bytes(&p), chunks, max, mean)
    }

    fn decode(params: &[u8], chunks: &[ChunkOut], basis: &Basis, points: usize) -> Vec<f32> {
        let d = LsdtFrame
            .decoder(params, points, &Some(Arc::new(basis.clone())).into())
            .unwrap();
        let mut out = Vec::new();
        for c in chunks {
            let mut frames = vec![0f32; c.frames * points * 3];
            d.decode_chunk(&c.bytes, c.frames, &mut frames).unwrap();
            out.extend(frames);
        }
        out
    }

    #[test]
    fn tables_decode_to_exactly_what_the_encoder_reconstructed() {
        let (frames, points) = (130, 7);
        let data = motion(frames, points);
        let mut valid = vec![true; frames * points];
        valid[40 * points + 3] = false;
        let basis = dct_basis(points);
        let spatial = Arc::new(Spatial::new(&basis).unwrap());
        for (residual_t, order, valid) in [(0.0, 1, None), (0.4, 2, Some(&valid[..]))] {
            let input = take(&data, valid, points, &basis);
            let p = FrameParams {
                step: 0.5,
                residual_t,
                intra_period: 50,
                order,
            };
            let (params, chunks, max, mean) = code(&input, &spatial, p);
            assert_eq!(
                chunks.iter().map(|c| c.frames).collect::<Vec<_>>(),
                [50, 50, 30]
            );
            let (parsed, coding) = FrameParams::parse(&params).unwrap();
            assert_eq!(parsed, p);
            assert!(matches!(coding, Coding::Tables(_)));
            let out = decode(&params, &chunks, &basis, points);
            // The same error to the last bit: the decoder rebuilt the encoder's frames.
            assert_eq!(max_mean(&data, &out, valid), (max, mean));
            if residual_t > 0.0 {
                assert!(max <= residual_t, "{max}");
            }
            // The adaptive stage codes the same loop: the same frames come out.
            let mut e = FrameEncoder::new(p, &basis).unwrap();
            let mut adaptive = Vec::new();
            for f in 0..frames {
                let v = valid.map(|v| &v[f * points..(f + 1) * points]);
                let (recon, _) = e.push(&data[f * points * 3..(f + 1) * points * 3], v);
                adaptive.extend_from_slice(recon);
            }
            assert_eq!(adaptive, out);
            // Versions 2 and 3 (the left context one or two rows back) decode to the same
            // frames, with a shape that splits by that context.
            let shape = [Shape {
                rows: 2,
                prev: 3,
                left: 3,
            }];
            let coded: Vec<_> = [1, 2]
                .map(|lag| {
                    let (recorded, _, _) = quantise_take(&input, &spatial, p);
                    let (tables, chunks) = recorded.finish_with(lag, &shape);
                    (tables.params_bytes(&p), chunks)
                })
                .into();
            assert_eq!((coded[0].0[0], coded[1].0[0]), (TABLES_V2, TABLES_VERSION));
            assert_ne!(coded[0].1[0].bytes, coded[1].1[0].bytes);
            for (params, chunks) in &coded {
                assert_eq!(decode(params, chunks, &basis, points), out);
            }
        }
    }

    /// Fine steps give chunks that the decoder reads with branchless rANS refills, coarse
    /// ones chunks it reads with a branch (`rans::refills_often`); both rebuild the
    /// encoder's frames.
    #[test]
    fn both_refill_modes_decode_to_what_the_encoder_reconstructed() {
        let (frames, points) = (120, 9);
        let data = motion(frames, points);
        let basis = dct_basis(points);
        let spatial = Arc::new(Spatial::new(&basis).unwrap());
        let input = take(&data, None, points, &basis);
        let mut modes = Vec::new();
        for step in [0.05, 20.0] {
            let p = FrameParams {
                step,
                residual_t: 0.0,
                intra_period: 60,
                order: 2,
            };
            let (params, chunks, max, mean) = code(&input, &spatial, p);
            for c in &chunks {
                let mut pos = 0;
                let coded = get_varint(&c.bytes, &mut pos).unwrap() as usize;
                modes.push(rans::refills_often(coded, c.frames * points * 3));
            }
            let out = decode(&params, &chunks, &basis, points);
            assert_eq!(max_mean(&data, &out, None), (max, mean));
        }
        assert_eq!(modes, [true, true, false, false]);
    }

    #[test]
    fn size_estimates_rank_settings_as_their_coded_sizes_do() {
        let (frames, points) = (480, 12);
        let data = motion(frames, points);
        let basis = dct_basis(points);
        let spatial = Arc::new(Spatial::new(&basis).unwrap());
        let input = take(&data, None, points, &basis);
        let mut sizes = Vec::new();
        for step in [0.1, 0.3, 0.9, 2.7] {
            let p = FrameParams {
                step,
                residual_t: 1.0,
                intra_period: 120,
                order: 2,
            };
            let (frames, _, _) = quantise_take(&input, &spatial, p);
            let estimate = frames.estimate_bits() / 8.0;
            let (tables, chunks) = frames.finish();
            let coded = (tables.params_bytes(&p).len()
                + chunks.iter().map(|c| c.bytes.len()).sum::<usize>())
                as f64;
            assert!(
                (estimate - coded).abs() < 0.1 * coded,
                "step {step}: estimated {estimate:.0} bytes, coded {coded}"
            );
            sizes.push((estimate, coded));
        }
        for w in sizes.windows(2) {
            assert_eq!(w[0].0 > w[1].0, w[0].1 > w[1].1, "{sizes:?}");
        }
    }

    #[test]
    fn side_data_is_small_and_chunks_fail_cleanly_when_damaged() {
        let (frames, points) = (60, 9);
        let data = motion(frames, points);
        let basis = dct_basis(points);
        let spatial = Arc::new(Spatial::new(&basis).unwrap());
        let input = take(&data, None, points, &basis);
        let p = FrameParams {
            step: 0.3,
            residual_t: 0.2,
            intra_period: 60,
            order: 2,
        };
        let (params, chunks, _, _) = code(&input, &spatial, p);
        // Half a second of nine points: the models must not cost more than the frames.
        assert!(params.len() < 120, "{} bytes of side data", params.len());
        let d = LsdtFrame
            .decoder(&params, points, &Some(Arc::new(basis.clone())).into())
            .unwrap();
        let chunk = &chunks[0].bytes;
        let mut out = vec![0f32; frames * points * 3];
        for cut in [0, 1, chunk.len() / 2, chunk.len() - 1] {
            assert!(d.decode_chunk(&chunk[..cut], frames, &mut out).is_err());
        }
        let mut longer = chunk.clone();
        longer.push(0);
        assert!(d.decode_chunk(&longer, frames, &mut out).is_err());
        for i in 0..chunk.len() {
            let mut bad = chunk.clone();
            bad[i] ^= 0x5a;
            // Garbage or an error, never a panic.
            let _ = d.decode_chunk(&bad, frames, &mut out);
        }
        assert!(FrameParams::parse(&params[..params.len() - 1]).is_err());
    }
}
