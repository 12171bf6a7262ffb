//! `lsdt-clip` — the clip codec of Hou et al. 2016: a clip of `L` frames (the latency) is
//! transformed by the DCT along each trajectory, then by the shared LSDT basis along the
//! points of each coordinate; the coefficients are hard-thresholded, uniformly quantised and
//! entropy coded. Each clip is one chunk, so any range decodes from the clips it overlaps.
//!
//! Nothing is stored per take but a few parameters: the spatial basis is the library's, the
//! temporal one is the DCT. That is why it wins on short takes, where a per-take basis
//! (`mdtt`) costs more than it saves.
//!
//! Departures from the paper: the step is searched for the fewest bytes that meet the bound;
//! for max bounds the residual layer corrects what the transform leaves too far.
//!
//! Two entropy stages: batch encodes fit models to the whole take and code clips with rANS
//! ([`tables`], parameters version 2); live streams code each clip with adaptive range-coder
//! models as it fills (version 1).

mod tables;

use std::sync::Arc;

use super::spatial::Spatial;
use crate::codec::basis::{Basis, BasisKind};
use crate::codec::container::estimated_bytes;
use crate::codec::dct;
use crate::codec::entropy::geometric::{read_models, tables_of, write_models, Geometric};
use crate::codec::entropy::{magnitude_context, Decoder, Encoder, IntModel};
use crate::codec::error::{malformed, Error, Result};
use crate::codec::measure::{max_mean, quantise};
use crate::codec::rate::{max_then_mean, Best, Ladder, Trial};
use crate::codec::residual;
use crate::codec::simd::dispatch;
use crate::codec::stream::{StreamCoder, StreamSpec, Streaming};
use crate::codec::wire::{Reader, Writer};
use crate::codec::{ChunkDecoder, ChunkOut, Codec, CodecId, CodecOutput, Input, Target};

/// Parameters of the adaptive stage (live streams).
const ADAPTIVE_VERSION: u8 = 1;
/// Parameters followed by the take's models ([`tables`]).
const TABLES_VERSION: u8 = 2;
const DEADZONE: f64 = 0.1;

/// Clip length as latency: one second, the paper's operating point.
pub fn default_clip(fps: f64) -> usize {
    (fps.round() as usize).clamp(8, 1024)
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipParams {
    /// Frames per clip (the latency).
    pub clip: usize,
    pub step: f64,
    /// Residual-layer bound in the take's units; 0 for none.
    pub residual_t: f64,
}

/// How a take's clips are entropy coded.
pub enum Coding {
    Adaptive,
    /// Per-take models, one per context ([`tables`]).
    Tables(Vec<Option<Geometric>>),
}

impl ClipParams {
    /// Version 1: parameters of the adaptive stage (live streams).
    pub fn to_bytes(&self) -> Vec<u8> {
        self.writer(ADAPTIVE_VERSION).0
    }

    /// Version 2: the parameters, then the take's models.
    fn tables_bytes(&self, models: &[Option<Geometric>]) -> Vec<u8> {
        let models = write_models(models);
        let mut w = self.writer(TABLES_VERSION);
        w.u32(models.len() as u32).bytes(&models);
        w.0
    }

    fn writer(&self, version: u8) -> Writer {
        let mut w = Writer::new();
        w.bytes(&[version]);
        w.u32(self.clip as u32).f64(self.step).f64(self.residual_t);
        w
    }

    pub fn parse(b: &[u8]) -> Result<(ClipParams, Coding)> {
        let mut r = Reader::new(b);
        let version = r.u8()?;
        if version != ADAPTIVE_VERSION && version != TABLES_VERSION {
            return Err(Error::Unsupported(format!(
                "lsdt-clip parameters version {version}"
            )));
        }
        let p = ClipParams {
            clip: r.u32()? as usize,
            step: r.f64()?,
            residual_t: r.f64()?,
        };
        let coding = if version == TABLES_VERSION {
            let n = r.u32()? as usize;
            let models = read_models(r.take(n)?, tables::MODELS)
                .ok_or_else(|| malformed("lsdt-clip entropy models"))?;
            Coding::Tables(models)
        } else {
            Coding::Adaptive
        };
        r.finish()?;
        if !(p.step.is_finite() && p.step > 0.0 && p.residual_t.is_finite())
            || p.residual_t < 0.0
            || p.clip == 0
            || p.clip > crate::codec::MAX_CLIP
        {
            return Err(malformed(format!("lsdt-clip parameters {p:?}")));
        }
        Ok((p, coding))
    }
}

/// Context of coefficient (frequency `k`, basis row `r`) given the same coefficient one
/// frequency lower: energy falls along frequency, and a row active at one frequency tends
/// to be active at the next.
fn context(k: usize, r: usize, below: i32) -> usize {
    let lg = |v: usize| (usize::BITS - v.leading_zeros()) as usize;
    (lg(k).min(6) * 6 + lg(r).min(5)) * 3 + magnitude_context(below, 3)
}
const CONTEXTS: usize = 7 * 6 * 3;

#[inline]
fn deadzone(x: f64) -> i32 {
    let m = (x.abs() - DEADZONE).max(0.0);
    quantise(m).saturating_mul(if x < 0.0 { -1 } else { 1 })
}

/// The DCT table (`n × n`, row-major (t, k)) in f32, as both sides synthesise with it.
fn table(n: usize) -> Vec<f32> {
    dct::basis(n, n).into_iter().map(|v| v as f32).collect()
}

dispatch! {
    /// Reconstruct `n` frames from quantised coefficients `q` (`(kmax + 1) × w`, frequency
    /// major): inverse spatial transform per frequency, then the inverse DCT. One function for
    /// encoder and decoder, so the residual layer sees exactly what the decoder will. Compiled
    /// for AVX2 too and chosen at run time ([`dispatch!`]): element-wise loops, so the same bits either way
    /// (see `mdtt::transform::reconstruct`).
    fn synthesise(spatial: &Spatial, q: &[i32], step: f32, n: usize, table: &[f32], out: &mut [f32]) {
        let w = spatial.points() * 3;
        let kn = q.len() / w;
        let mut freq = vec![0f32; kn * w];
        let mut scratch = spatial.scratch();
        for (k, f) in freq.chunks_exact_mut(w).enumerate() {
            spatial.inverse_add(&q[k * w..(k + 1) * w], step, &mut scratch, f);
        }
        out[..n * w].fill(0.0);
        for t in 0..n {
            let row = &mut out[t * w..(t + 1) * w];
            for (k, f) in freq.chunks_exact(w).enumerate() {
                let d = table[t * n + k];
                for (o, &v) in row.iter_mut().zip(f) {
                    *o += d * v;
                }
            }
        }
    }
}

/// A take cut into clips, with every clip's transform coefficients (they do not depend on
/// the step, so a search computes them once).
struct Analysis {
    clips: Vec<(usize, usize)>,
    /// Per clip: `n × w` spatial-then-temporal coefficients, frequency major.
    coefs: Vec<Vec<f64>>,
    tables: Vec<(usize, Vec<f32>)>,
}

impl Analysis {
    fn new(input: &Input<'_>, spatial: &Spatial, clip: usize) -> Analysis {
        let w = input.width();
        let clips: Vec<(usize, usize)> = (0..input.frames)
            .step_by(clip)
            .map(|f0| (f0, clip.min(input.frames - f0)))
            .collect();
        let mut tables: Vec<(usize, Vec<f32>)> = Vec::new();
        let mut coefs = Vec::with_capacity(clips.len());
        for &(f0, n) in &clips {
            let d = dct::basis(n, n);
            let mut freq = vec![0.0f64; w];
            let mut c = vec![0.0f64; n * w];
            for k in 0..n {
                freq.fill(0.0);
                for t in 0..n {
                    let dk = d[t * n + k];
                    let x = &input.data[(f0 + t) * w..(f0 + t + 1) * w];
                    for (a, &v) in freq.iter_mut().zip(x) {
                        *a += dk * f64::from(v);
                    }
                }
                spatial.forward(&freq, &mut c[k * w..(k + 1) * w]);
            }
            coefs.push(c);
            if !tables.iter().any(|(len, _)| *len == n) {
                tables.push((n, table(n)));
            }
        }
        Analysis {
            clips,
            coefs,
            tables,
        }
    }

    fn table(&self, n: usize) -> &[f32] {
        &self
            .tables
            .iter()
            .find(|(len, _)| *len == n)
            .expect("tabulated")
            .1
    }
}

/// Clip `i` quantised with `p` and reconstructed into `recon` (the take's frames) as the
/// decoder will, before any residual layer: its coefficients (the first `kn` frequencies,
/// `kn × 3J`) and `kn`.
fn quantise_clip(
    spatial: &Spatial,
    a: &Analysis,
    i: usize,
    p: ClipParams,
    recon: &mut [f32],
) -> (Vec<i32>, usize) {
    let w = spatial.points() * 3;
    let (f0, n) = a.clips[i];
    let mut q: Vec<i32> = a.coefs[i].iter().map(|&c| deadzone(c / p.step)).collect();
    let kn = q
        .chunks_exact(w)
        .rposition(|row| row.iter().any(|&v| v != 0))
        .map_or(0, |k| k + 1);
    q.truncate(kn * w);
    let out = &mut recon[f0 * w..(f0 + n) * w];
    synthesise(spatial, &q, p.step as f32, n, a.table(n), out);
    (q, kn)
}

/// The residual layer of clip `i` (`recon` as [`quantise_clip`] left it) into `enc`.
fn residual_clip(
    input: &Input<'_>,
    a: &Analysis,
    i: usize,
    p: ClipParams,
    recon: &mut [f32],
    enc: &mut Encoder,
) {
    let (w, (f0, n)) = (input.width(), a.clips[i]);
    let valid = input
        .valid
        .map(|v| &v[f0 * input.points..(f0 + n) * input.points]);
    let orig = &input.data[f0 * w..(f0 + n) * w];
    let out = &mut recon[f0 * w..(f0 + n) * w];
    residual::encode(enc, orig, out, valid, input.points, p.residual_t);
}

/// Code every clip with fixed parameters and adaptive models (version 1); returns the
/// chunks and (max, mean) error.
fn code(
    input: &Input<'_>,
    spatial: &Spatial,
    a: &Analysis,
    p: ClipParams,
) -> (Vec<ChunkOut>, f64, f64) {
    let w = input.width();
    let j = input.points;
    let mut recon = vec![0f32; input.data.len()];
    let mut chunks = Vec::with_capacity(a.clips.len());
    for i in 0..a.clips.len() {
        let (q, kn) = quantise_clip(spatial, a, i, p, &mut recon);
        let mut enc = Encoder::new();
        let mut count = IntModel::default();
        count.encode(&mut enc, kn as i32);
        let mut models = vec![IntModel::default(); CONTEXTS];
        for k in 0..kn {
            for (i, r) in (0..3).flat_map(|_| 0..j).enumerate() {
                let below = if k > 0 { q[(k - 1) * w + i] } else { 0 };
                models[context(k, r, below)].encode(&mut enc, q[k * w + i]);
            }
        }
        if p.residual_t > 0.0 {
            residual_clip(input, a, i, p, &mut recon, &mut enc);
        }
        chunks.push(ChunkOut {
            frames: a.clips[i].1,
            bytes: enc.finish(),
        });
    }
    let (max, mean) = max_mean(input.data, &recon, input.valid);
    (chunks, max, mean)
}

/// Code every clip with fixed parameters and models fitted to the take (version 2).
fn code_tables(input: &Input<'_>, spatial: &Spatial, a: &Analysis, p: ClipParams) -> Trial {
    let mut recon = vec![0f32; input.data.len()];
    let mut clips = Vec::with_capacity(a.clips.len());
    for i in 0..a.clips.len() {
        let (q, kn) = quantise_clip(spatial, a, i, p, &mut recon);
        let residual = (p.residual_t > 0.0).then(|| {
            let mut enc = Encoder::new();
            residual_clip(input, a, i, p, &mut recon, &mut enc);
            enc.finish()
        });
        clips.push((q, kn, residual));
    }
    let models = tables::fit(clips.iter().map(|c| (&c.0[..], c.1)), input.points);
    let coders = tables_of(&models);
    let chunks = clips
        .into_iter()
        .zip(&a.clips)
        .map(|((q, kn, residual), &(_, n))| ChunkOut {
            frames: n,
            bytes: tables::code_clip(&coders, &q, kn, input.points, residual),
        })
        .collect();
    let (max, mean) = max_mean(input.data, &recon, input.valid);
    let params = p.tables_bytes(&models);
    Trial::new(CodecOutput { params, chunks }, max, mean)
}

/// Parameters for live streams, where no search is possible: the bound as a max bound,
/// held by the residual layer, at the step the batch search most often picks.
pub fn stream_params(t: f64, fps: f64) -> ClipParams {
    ClipParams {
        clip: default_clip(fps),
        step: 1.3 * t,
        residual_t: t,
    }
}

/// Encode with fixed parameters (live streams code each clip as it fills).
pub fn encode_fixed(input: &Input<'_>, p: ClipParams) -> Result<Vec<ChunkOut>> {
    let spatial = Spatial::for_take(input.shared, input.points, "lsdt-clip")?;
    let a = Analysis::new(input, &spatial, p.clip.max(1));
    Ok(code(input, &spatial, &a, p).0)
}

/// Encode with clips of `clip` frames, searching the step for the fewest bytes that meet
/// `target`.
pub fn encode_with_clip(input: &Input<'_>, target: Target, clip: usize) -> Result<CodecOutput> {
    let spatial = Spatial::for_take(input.shared, input.points, "lsdt-clip")?;
    let clip = clip
        .clamp(1, input.frames.max(1))
        .min(crate::codec::MAX_CLIP);
    let a = Analysis::new(input, &spatial, clip);
    let mut best = Best::new(target);
    max_then_mean(target, SEARCH, |step, residual_t| {
        let p = ClipParams {
            clip,
            step,
            residual_t,
        };
        best.offer(code_tables(input, &spatial, &a, p), p).is_some()
    });
    let (trial, p) = best.into_best().ok_or_else(|| Error::BoundMissed {
        codec: "lsdt-clip".into(),
        detail: format!("no setting meets {target}"),
    })?;
    // On a take of a few clips the models can cost more than they save; the adaptive stage
    // codes the same reconstruction, so it meets the target too.
    let (adaptive, _, _) = code(input, &spatial, &a, p);
    let params = p.to_bytes();
    if estimated_bytes(params.len(), &adaptive) < trial.bytes {
        return Ok(CodecOutput {
            params,
            chunks: adaptive,
        });
    }
    Ok(trial.out)
}

/// The steps [`encode_with_clip`] tries: around the max bound with the residual layer
/// holding it (the fewest bytes meet a max bound there), and for noise-like takes around a
/// mean bound with the residual layer at the mean.
const SEARCH: Ladder = Ladder {
    at_max: &[0.6, 0.9, 1.3, 1.8, 2.5, 3.5],
    noise: &[1.3, 2.0],
};

pub struct LsdtClip;

impl Codec for LsdtClip {
    fn id(&self) -> CodecId {
        CodecId::LsdtClip
    }

    fn basis_kind(&self) -> Option<BasisKind> {
        Some(BasisKind::Lsdt)
    }

    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput> {
        encode_with_clip(input, target, default_clip(input.fps))
    }

    /// 1: live streams (adaptive); 2: whole takes (tables).
    fn versions(&self) -> &'static [u8] {
        &[ADAPTIVE_VERSION, TABLES_VERSION]
    }

    fn decoder(
        &self,
        params: &[u8],
        points: usize,
        shared: &crate::codec::Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        let (p, coding) = ClipParams::parse(params)?;
        let spatial = Spatial::for_take(shared.basis.as_deref(), points, "lsdt-clip")?;
        let full = std::sync::OnceLock::new();
        let tables = match coding {
            Coding::Adaptive => None,
            Coding::Tables(models) => Some(tables::ClipTables::new(&models)),
        };
        Ok(Box::new(ClipDecoder {
            p,
            spatial,
            full,
            points,
            tables,
        }))
    }
    fn streaming(&self) -> Option<&dyn Streaming> {
        Some(self)
    }
}

/// Live streams: [`stream_params`] with the stream's chunk length as the clip; each clip is
/// coded once whole (or when flushed, as it stands).
impl Streaming for LsdtClip {
    fn open(&self, spec: &StreamSpec<'_>, t: f64) -> Result<(Vec<u8>, Box<dyn StreamCoder>)> {
        let basis = spec.basis()?;
        if spec.chunk_frames > crate::codec::MAX_CLIP {
            return Err(Error::Invalid(format!(
                "lsdt-clip codes clips of at most {} frames, asked for {}",
                crate::codec::MAX_CLIP,
                spec.chunk_frames
            )));
        }
        let p = ClipParams {
            clip: spec.chunk_frames,
            ..stream_params(t, spec.fps)
        };
        let coder = ClipStream {
            p,
            basis: basis.clone(),
            points: spec.points,
            fps: spec.fps,
            uncoded: Vec::new(),
        };
        Ok((p.to_bytes(), Box::new(coder)))
    }

    fn untrained_basis(&self, points: usize) -> Option<(Basis, &'static str)> {
        Some(super::spatial::untrained(points))
    }
}

struct ClipStream {
    p: ClipParams,
    basis: Arc<Basis>,
    points: usize,
    fps: f64,
    /// Frames not yet in a coded clip, as sent.
    uncoded: Vec<f32>,
}

impl StreamCoder for ClipStream {
    fn push(&mut self, frames: &[f32], flush: bool) -> Result<Vec<ChunkOut>> {
        self.uncoded.extend_from_slice(frames);
        let w = self.points * 3;
        let n = self.uncoded.len() / w;
        let whole = if flush {
            n
        } else {
            n / self.p.clip * self.p.clip
        };
        if whole == 0 {
            return Ok(Vec::new());
        }
        let data: Vec<f32> = self.uncoded.drain(..whole * w).collect();
        let valid = crate::codec::gaps::mask(&data);
        let filled = crate::codec::gaps::fill(&data, self.points);
        let input = Input {
            data: &filled,
            valid: Some(&valid),
            frames: whole,
            points: self.points,
            fps: self.fps,
            shared: Some(&self.basis),
            skeleton: None,
            names: &[],
            torso: None,
        };
        encode_fixed(&input, self.p)
    }
}

struct ClipDecoder {
    p: ClipParams,
    spatial: Spatial,
    /// DCT table of a full clip, made when the first full clip is decoded (a decoder may
    /// serve only a short take's one shorter clip, which computes its own).
    full: std::sync::OnceLock<Vec<f32>>,
    points: usize,
    /// The take's tables (version 2); `None` for adaptive models (version 1).
    tables: Option<tables::ClipTables>,
}

impl ChunkDecoder for ClipDecoder {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        let n = frames;
        if n > self.p.clip {
            return Err(malformed(format!(
                "lsdt-clip chunk of {n} frames, clips are {}",
                self.p.clip
            )));
        }
        let own;
        let t = if n == self.p.clip {
            self.full.get_or_init(|| table(n))
        } else {
            own = table(n);
            &own
        };
        let residual = self.p.residual_t > 0.0;
        let out = &mut out[..n * self.points * 3];
        match &self.tables {
            Some(tables) => {
                let d = tables.decode(bytes, n, self.points, residual)?;
                synthesise(&self.spatial, &d.q, self.p.step as f32, n, t, out);
                if residual {
                    let mut dec = Decoder::new(d.residual);
                    residual::decode(&mut dec, out, self.points, self.p.residual_t);
                    if dec.overran() {
                        return Err(malformed("lsdt-clip chunk ends early"));
                    }
                }
                Ok(())
            }
            None => self.decode_adaptive(bytes, n, t, out),
        }
    }
}

impl ClipDecoder {
    /// A version-1 chunk of `n` frames (`t`: the clip's DCT table).
    fn decode_adaptive(&self, bytes: &[u8], n: usize, t: &[f32], out: &mut [f32]) -> Result<()> {
        let w = self.points * 3;
        let mut dec = Decoder::new(bytes);
        let kn = IntModel::default().decode(&mut dec);
        if kn < 0 || kn as usize > n {
            return Err(malformed(format!(
                "lsdt-clip chunk codes {kn} frequencies of {n}"
            )));
        }
        let kn = kn as usize;
        let mut models = vec![IntModel::default(); CONTEXTS];
        let mut q = vec![0i32; kn * w];
        for k in 0..kn {
            for (i, r) in (0..3).flat_map(|_| 0..self.points).enumerate() {
                let below = if k > 0 { q[(k - 1) * w + i] } else { 0 };
                q[k * w + i] = models[context(k, r, below)].decode(&mut dec);
            }
        }
        synthesise(&self.spatial, &q, self.p.step as f32, n, t, out);
        if self.p.residual_t > 0.0 {
            residual::decode(&mut dec, out, self.points, self.p.residual_t);
        }
        if dec.overran() {
            return Err(malformed("lsdt-clip chunk ends early"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::lsdt::spatial::dct_basis;
    use crate::motion::synthetic::walker;
    use crate::motion::Motion;

    /// A synthetic take as codec input, coded with `basis`.
    fn take<'a>(m: &'a Motion, basis: &'a Basis) -> Input<'a> {
        Input {
            data: m.positions(),
            valid: None,
            frames: m.frame_count(),
            points: m.point_count(),
            fps: m.fps,
            shared: Some(basis),
            skeleton: None,
            names: &[],
            torso: None,
        }
    }

    /// What [`in_tables`] coded with.
    struct Coding<'a> {
        input: &'a Input<'a>,
        spatial: &'a Spatial,
        a: &'a Analysis,
        p: ClipParams,
        basis: &'a Basis,
    }

    /// `m` coded by the tables stage in clips of 60 at `step`, without and then with a
    /// residual layer, each handed to `check`.
    fn in_tables(m: &Motion, step: f64, mut check: impl FnMut(Coding<'_>, Trial)) {
        let basis = dct_basis(m.point_count());
        let spatial = Spatial::new(&basis).unwrap();
        let input = take(m, &basis);
        let a = Analysis::new(&input, &spatial, 60);
        for residual_t in [0.0, 0.3] {
            let p = ClipParams {
                clip: 60,
                step,
                residual_t,
            };
            let trial = code_tables(&input, &spatial, &a, p);
            let c = Coding {
                input: &input,
                spatial: &spatial,
                a: &a,
                p,
                basis: &basis,
            };
            check(c, trial);
        }
    }

    /// Chunks of `params` decoded one by one into a take.
    fn decode(
        params: &[u8],
        chunks: &[ChunkOut],
        basis: &Basis,
        points: usize,
    ) -> Result<Vec<f32>> {
        let d = LsdtClip.decoder(params, points, &Some(Arc::new(basis.clone())).into())?;
        let mut out = Vec::new();
        for c in chunks {
            let mut frames = vec![0f32; c.frames * points * 3];
            d.decode_chunk(&c.bytes, c.frames, &mut frames)?;
            out.extend(frames);
        }
        Ok(out)
    }

    #[test]
    fn both_stages_decode_to_exactly_what_the_encoder_reconstructed() {
        // 250 frames in clips of 60: the last clip is shorter.
        let m = walker(250, 6, 60.0, 3, 0.0);
        let points = m.point_count();
        in_tables(&m, 1.5, |c, trial| {
            let Trial {
                out: CodecOutput { params, chunks },
                max,
                mean,
                ..
            } = trial;
            let (input, spatial, a, p, basis) = (c.input, c.spatial, c.a, c.p, c.basis);
            let residual_t = p.residual_t;
            assert_eq!(params[0], TABLES_VERSION);
            assert_eq!(
                chunks.iter().map(|c| c.frames).collect::<Vec<_>>(),
                [60, 60, 60, 60, 10]
            );
            let out = decode(&params, &chunks, basis, points).unwrap();
            // The same error to the last bit: the decoder rebuilt the encoder's frames.
            assert_eq!(max_mean(input.data, &out, None), (max, mean));
            if residual_t > 0.0 {
                assert!(max <= residual_t, "{max}");
            }
            // The adaptive stage (live streams) codes the same reconstruction.
            let (adaptive, _, _) = code(input, spatial, a, p);
            assert_eq!(
                decode(&p.to_bytes(), &adaptive, basis, points).unwrap(),
                out
            );
            // Per-take models pay for themselves on this take.
            let size = |c: &[ChunkOut]| c.iter().map(|c| c.bytes.len()).sum::<usize>();
            assert!(
                params.len() + size(&chunks) < p.to_bytes().len() + size(&adaptive),
                "tables {} + {} vs adaptive {}",
                params.len(),
                size(&chunks),
                size(&adaptive)
            );
        });
    }

    /// The search keeps whichever stage is smaller: per-take models on a long take, the
    /// adaptive models on a take too short to pay for them.
    #[test]
    fn short_takes_keep_the_adaptive_stage_when_it_is_smaller() {
        for (frames, version) in [(600, TABLES_VERSION), (12, ADAPTIVE_VERSION)] {
            let m = walker(frames, 6, 60.0, 5, 0.0);
            let basis = dct_basis(m.point_count());
            let input = take(&m, &basis);
            let out = encode_with_clip(&input, Target::max(0.5), 60).unwrap();
            assert_eq!(out.params[0], version, "{frames} frames");
            let decoded = decode(&out.params, &out.chunks, &basis, m.point_count()).unwrap();
            assert!(max_mean(input.data, &decoded, None).0 <= 0.5);
        }
    }

    #[test]
    fn damaged_tables_chunks_and_params_are_errors() {
        let m = walker(120, 5, 60.0, 4, 0.0);
        let points = m.point_count();
        in_tables(&m, 1.0, |c, trial| {
            let CodecOutput { params, chunks } = trial.out;
            let (basis, residual_t) = (c.basis, c.p.residual_t);
            let bytes = &chunks[0].bytes;
            // Any byte flipped: an error or other frames, never a panic.
            for i in 0..bytes.len() {
                let mut b = bytes.clone();
                b[i] ^= 0x5a;
                let _ = decode(
                    &params,
                    &[ChunkOut {
                        frames: 60,
                        bytes: b,
                    }],
                    basis,
                    points,
                );
            }
            assert!(decode(&params[..params.len() - 1], &chunks, basis, points).is_err());
            // Without a residual layer the chunk ends with the raw bits, and a decoder must
            // read exactly to its end (the range-coded residual layer, as in version 1, may
            // read a few bytes past it; the container's checksum catches that damage).
            if residual_t == 0.0 {
                for len in [bytes.len() - 1, bytes.len() + 1] {
                    let mut b = bytes.clone();
                    b.resize(len, 0);
                    let c = ChunkOut {
                        frames: 60,
                        bytes: b,
                    };
                    assert!(decode(&params, &[c], basis, points).is_err(), "{len}");
                }
            }
        });
        let mut future = ClipParams {
            clip: 60,
            step: 1.0,
            residual_t: 0.0,
        }
        .to_bytes();
        future[0] = 3;
        assert!(matches!(
            ClipParams::parse(&future),
            Err(Error::Unsupported(_))
        ));
    }
}
