//! `bvh-lossless`: a skeleton's channel values exactly as the file printed them.
//!
//! Each value is kept as its printed digits (an integer), the power of ten of its last
//! digit and its notation ([`crate::motion::decimal`]). Per chunk, every channel picks a
//! temporal predictor (previous value, linear or quadratic extrapolation) and how its
//! exponent is predicted (unchanged, as `%f` prints; or the same number of significant
//! digits as the previous value, as `%g` prints); the residuals go to the adaptive binary
//! range coder with contexts from the running size of the channel's residuals. Prediction is
//! done in integers on the printed grid, so encoder and decoder agree bit for bit on every
//! machine. Decoding gives back the same characters for every value, hence the same f64 and
//! the same FK positions: errors are zero by construction, and verified like any codec's.
//!
//! Chunks decode on their own (each starts with no history); they are longer than a
//! position codec's (2 s, at least 128 frames) because the first frame of a chunk costs
//! several times a predicted one.

use std::sync::Arc;

use super::entropy::ints::IntModel;
use super::entropy::io::{code_residual, Io};
use super::entropy::rangecoder::{Bit, Decoder, Encoder};
use super::error::{malformed, Error, Result};
use super::skeletal::{no_skeleton, rig_of, ChannelDecoder, Posed};
use super::skeleton::{Channels, Skeleton};
use super::{ChunkDecoder, ChunkOut, Codec, CodecId, CodecOutput, Input, Shared, Target};
use crate::motion::decimal::{Notation, Printed, PrintedValues};

const VERSION: u8 = 1;
/// Longest verbatim token a decoder accepts (the reader keeps any; longer ones would need a
/// file of absurd numbers, and are refused at encode).
const MAX_TOKEN: usize = 256;
/// The largest exponent a decoder accepts; f64 spans 10^±324.
const MAX_EXP: i32 = 400;
/// Contexts for residual sizes (the bit length of their running mean).
const SIZE_CONTEXTS: usize = 24;
const POW10: [i64; 19] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
    1_000_000_000,
    10_000_000_000,
    100_000_000_000,
    1_000_000_000_000,
    10_000_000_000_000,
    100_000_000_000_000,
    1_000_000_000_000_000,
    10_000_000_000_000_000,
    100_000_000_000_000_000,
    1_000_000_000_000_000_000,
];

pub struct BvhLossless;

/// Frames per chunk: about two seconds, at least 128 frames.
pub fn chunk_frames(fps: f64) -> usize {
    ((2.0 * fps).round() as usize).clamp(128, 1024)
}

impl Codec for BvhLossless {
    fn id(&self) -> CodecId {
        CodecId::BvhLossless
    }

    fn encode(&self, input: &Input<'_>, _target: Target) -> Result<CodecOutput> {
        let (rig, skeleton) = input.skeleton_for(CodecId::BvhLossless)?;
        let cc = rig.channel_count();
        let printed = match &skeleton.printed {
            Some(p) => p.clone(),
            // Values that were never text (generated, or converted): the shortest characters
            // that parse back to each f64.
            None => {
                let mut p = PrintedValues::default();
                for v in &skeleton.values {
                    p.push_token(&v.to_string());
                }
                p
            }
        };
        if let Some(t) = printed.verbatim.iter().find(|t| t.len() > MAX_TOKEN) {
            return Err(Error::Invalid(format!(
                "a channel value of {} characters (at most {MAX_TOKEN} are kept)",
                t.len()
            )));
        }
        let frames = skeleton.frame_count();
        let per = chunk_frames(input.fps);
        let mut chunks = Vec::with_capacity(frames.div_ceil(per));
        for f0 in (0..frames).step_by(per) {
            let n = per.min(frames - f0);
            let mut enc = Encoder::new();
            let mut chunk = Chunk::new(cc);
            chunk.code(&mut enc, n, Some((&printed, f0 * cc)))?;
            chunks.push(ChunkOut {
                frames: n,
                bytes: enc.finish(),
            });
        }
        Ok(CodecOutput {
            params: vec![VERSION],
            chunks,
        })
    }

    fn versions(&self) -> &'static [u8] {
        &[VERSION]
    }

    fn decoder(
        &self,
        params: &[u8],
        _points: usize,
        shared: &Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        if params != [VERSION] {
            return Err(malformed("bvh-lossless parameters"));
        }
        let rig = rig_of(shared, CodecId::BvhLossless)?;
        Ok(Box::new(Posed(LosslessDecoder { rig })))
    }

    fn codes_channels(&self) -> bool {
        true
    }

    fn unsuited(&self, motion: &crate::motion::Motion) -> Option<String> {
        no_skeleton(motion)
    }
}

struct LosslessDecoder {
    rig: Arc<Skeleton>,
}

impl ChannelDecoder for LosslessDecoder {
    fn rig(&self) -> &Skeleton {
        &self.rig
    }

    fn channels(&self, bytes: &[u8], frames: usize) -> Result<Channels> {
        let cc = self.rig.channel_count();
        let mut dec = Decoder::new(bytes);
        let mut chunk = Chunk::new(cc);
        let printed = chunk.code(&mut dec, frames, None)?;
        if dec.overran() {
            return Err(malformed("bvh-lossless chunk is truncated"));
        }
        let values = (0..printed.values.len())
            .map(|i| printed.value(i))
            .collect();
        Ok(Channels {
            values,
            printed: Some(printed),
        })
    }
}

/// How one channel is predicted within a chunk, and what it has seen.
#[derive(Clone, Default)]
struct Track {
    /// Temporal predictor: 0 previous value, 1 linear, 2 quadratic extrapolation.
    order: u8,
    /// Predict the exponent from the significant digits (as `%g` prints) rather than keep it.
    significant: bool,
    /// The channel's last three values (digits, exponent), most recent first.
    hist: [Option<(i64, i16)>; 3],
    notation: u8,
    negative_zero: bool,
    exp_missed: bool,
    /// Running mean of residual magnitudes, × 16.
    size: u32,
}

impl Track {
    /// The digits predicted at exponent `e`, if there is a history.
    fn predict(&self, e: i16) -> Option<i64> {
        let n = self.hist.iter().take_while(|h| h.is_some()).count();
        if n == 0 {
            return None;
        }
        let at = |k: usize| self.hist[k].and_then(|(d, he)| rescale(d, he, e));
        let order = usize::from(self.order).min(n - 1);
        match order {
            0 => at(0),
            1 => at(0)?.checked_mul(2)?.checked_sub(at(1)?),
            _ => at(0)?
                .checked_sub(at(1)?)?
                .checked_mul(3)?
                .checked_add(at(2)?),
        }
    }

    /// The exponent predicted for the next value, if there is a history.
    fn predict_exp(&self) -> Option<i16> {
        let (d0, e0) = self.hist[0]?;
        if !self.significant || d0 == 0 {
            return Some(e0);
        }
        let p = self.predict(e0).filter(|&p| p != 0)?;
        let shift = digit_count(p) as i32 - digit_count(d0) as i32;
        i16::try_from(i32::from(e0) + shift).ok()
    }

    fn size_context(&self) -> usize {
        ((32 - (self.size >> 4).leading_zeros()) as usize).min(SIZE_CONTEXTS - 1)
    }

    fn seen(&mut self, d: i64, e: i16, residual: i64) {
        self.hist = [Some((d, e)), self.hist[0], self.hist[1]];
        let r = residual.unsigned_abs().min(1 << 24) as u32;
        self.size = (3 * self.size + 16 * r) / 4;
    }
}

/// `d × 10^from` on the grid `10^to`, rounded half away from zero; `None` on overflow.
fn rescale(d: i64, from: i16, to: i16) -> Option<i64> {
    let k = i32::from(from) - i32::from(to);
    if k >= 0 {
        d.checked_mul(*POW10.get(k as usize)?)
    } else {
        let Some(&q) = POW10.get((-k) as usize) else {
            return Some(0);
        };
        let r = (d.unsigned_abs() + q.unsigned_abs() / 2) / q.unsigned_abs();
        Some(if d < 0 { -(r as i64) } else { r as i64 })
    }
}

fn digit_count(d: i64) -> u32 {
    d.unsigned_abs().checked_ilog10().unwrap_or(0) + 1
}

/// The adaptive models of one chunk.
struct Models {
    any_verbatim: Bit,
    verbatim: [Bit; 2],
    token_len: IntModel,
    order: [Bit; 2],
    significant: Bit,
    exp: [IntModel; 2],
    first_exp: IntModel,
    digits: Vec<IntModel>,
    first_digits: IntModel,
    negative_zero: [Bit; 2],
    /// By previous notation × magnitude class (tiny, ordinary, huge), two decisions each.
    notation: [[Bit; 2]; 12],
}

impl Models {
    fn new() -> Models {
        Models {
            any_verbatim: Bit::default(),
            verbatim: [Bit::default(); 2],
            token_len: IntModel::default(),
            order: [Bit::default(); 2],
            significant: Bit::default(),
            exp: [IntModel::default(), IntModel::default()],
            first_exp: IntModel::default(),
            digits: vec![IntModel::default(); SIZE_CONTEXTS],
            first_digits: IntModel::default(),
            negative_zero: [Bit::default(); 2],
            notation: [[Bit::default(); 2]; 12],
        }
    }
}

/// One chunk's coding state.
struct Chunk {
    channels: usize,
    tracks: Vec<Track>,
    m: Models,
}

impl Chunk {
    fn new(channels: usize) -> Chunk {
        Chunk {
            channels,
            tracks: vec![Track::default(); channels],
            m: Models::new(),
        }
    }

    /// Code `frames` frames: from `input` (all values, and where this chunk starts in them)
    /// when encoding; decoded into the returned values when decoding.
    fn code<I: Io>(
        &mut self,
        io: &mut I,
        frames: usize,
        input: Option<(&PrintedValues, usize)>,
    ) -> Result<PrintedValues> {
        let cc = self.channels;
        let given = |i: usize| input.map(|(p, start)| (p, p.values[start + i]));
        let mut out = PrintedValues {
            values: Vec::with_capacity(frames * cc),
            verbatim: Vec::new(),
        };
        let any = input.is_some_and(|(p, s)| {
            p.values[s..s + frames * cc]
                .iter()
                .any(|v| v.notation == Notation::Verbatim)
        });
        let any = io.bit(&mut self.m.any_verbatim, any);
        if let Some((p, s)) = input {
            for (c, t) in self.tracks.iter_mut().enumerate() {
                (t.order, t.significant) = choose_prediction(p, s + c, cc, frames);
            }
        }
        for t in &mut self.tracks {
            let hi = io.bit(&mut self.m.order[0], t.order >= 2);
            let lo = !hi && io.bit(&mut self.m.order[1], t.order == 1);
            t.order = if hi { 2 } else { u8::from(lo) };
            t.significant = io.bit(&mut self.m.significant, t.significant);
        }
        let mut last_verbatim = false;
        for i in 0..frames * cc {
            let c = i % cc;
            let want = given(i);
            if any {
                let v = want.is_some_and(|(_, p)| p.notation == Notation::Verbatim);
                last_verbatim = io.bit(&mut self.m.verbatim[usize::from(last_verbatim)], v);
                if last_verbatim {
                    let token = want.map(|(p, v)| p.verbatim[v.digits as usize].as_str());
                    let token = self.token(io, token)?;
                    out.verbatim.push(token);
                    out.values.push(Printed::verbatim(out.verbatim.len() - 1));
                    continue;
                }
            }
            let p = self.value(io, c, want.map(|(_, p)| p))?;
            out.values.push(p);
        }
        Ok(out)
    }

    fn token<I: Io>(&mut self, io: &mut I, token: Option<&str>) -> Result<String> {
        let bytes = token.map_or(&[][..], str::as_bytes);
        let len = io.int(&mut self.m.token_len, bytes.len() as i32);
        let len = usize::try_from(len)
            .ok()
            .filter(|&l| l <= MAX_TOKEN)
            .ok_or_else(|| malformed(format!("a verbatim value of {len} bytes")))?;
        let mut b = Vec::with_capacity(len);
        for k in 0..len {
            b.push(io.raw(u32::from(*bytes.get(k).unwrap_or(&0)), 8) as u8);
        }
        String::from_utf8(b).map_err(|_| malformed("a verbatim value is not UTF-8"))
    }

    /// Code one value of channel `c` (`want` when encoding).
    fn value<I: Io>(&mut self, io: &mut I, c: usize, want: Option<Printed>) -> Result<Printed> {
        let t = &mut self.tracks[c];
        let w = want.unwrap_or(Printed::verbatim(0));
        // Exponent.
        let e = match t.predict_exp() {
            Some(pe) => {
                let r = io.int(
                    &mut self.m.exp[usize::from(t.exp_missed)],
                    i32::from(w.exp) - i32::from(pe),
                );
                t.exp_missed = r != 0;
                i32::from(pe) + r
            }
            None => io.int(&mut self.m.first_exp, i32::from(w.exp)),
        };
        if e.abs() > MAX_EXP {
            return Err(malformed(format!("exponent {e}")));
        }
        let e = e as i16;
        // Digits.
        let pred = t.predict(e);
        let model = match pred {
            Some(_) => &mut self.m.digits[t.size_context()],
            None => &mut self.m.first_digits,
        };
        let base = pred.unwrap_or(0);
        let r = if io.encoding() {
            w.digits
                .checked_sub(base)
                .ok_or_else(|| Error::Invalid("a residual overflows 64 bits".into()))?
        } else {
            0
        };
        let r = code_residual(io, model, r)?;
        let d = base
            .checked_add(r)
            .filter(|d| d.unsigned_abs() < POW10[18] as u64)
            .ok_or_else(|| malformed("a value has more than 18 digits"))?;
        t.seen(d, e, r);
        // A zero's sign.
        let negative_zero = d == 0
            && io.bit(
                &mut self.m.negative_zero[usize::from(t.negative_zero)],
                w.negative_zero,
            );
        t.negative_zero = negative_zero;
        // Notation, from the previous one and the value's size.
        let x = i32::from(e) + digit_count(d) as i32 - 1;
        let class = if x < -4 {
            0
        } else if x >= 6 {
            1
        } else {
            2
        };
        let ctx = &mut self.m.notation[usize::from(t.notation) * 3 + class];
        let n = if io.bit(&mut ctx[0], w.notation != Notation::Fixed) {
            if io.bit(&mut ctx[1], w.notation == Notation::ExpShort) {
                Notation::ExpShort
            } else {
                Notation::ExpC
            }
        } else {
            Notation::Fixed
        };
        if n == Notation::Fixed && !(-18..=0).contains(&e) {
            return Err(malformed(format!("fixed notation with exponent {e}")));
        }
        t.notation = n as u8;
        Ok(Printed {
            digits: d,
            exp: e,
            notation: n,
            negative_zero,
        })
    }
}

/// The predictor order and exponent rule that code channel `first` (then every `stride`-th
/// value) of `frames` frames in the fewest bits, by a cheap estimate (the bit lengths of the
/// residuals).
fn choose_prediction(p: &PrintedValues, first: usize, stride: usize, frames: usize) -> (u8, bool) {
    let mut best = (u64::MAX, 0, false);
    for order in 0..3u8 {
        for significant in [false, true] {
            let mut t = Track {
                order,
                significant,
                ..Track::default()
            };
            let mut cost = 0u64;
            for f in 0..frames {
                let v = p.values[first + f * stride];
                if v.notation == Notation::Verbatim {
                    continue;
                }
                let pe = t.predict_exp();
                let er = pe.map_or(0, |pe| i64::from(v.exp) - i64::from(pe));
                let r = t
                    .predict(v.exp)
                    .and_then(|pd| v.digits.checked_sub(pd))
                    .unwrap_or(v.digits);
                cost += 2 * u64::from(64 - er.unsigned_abs().leading_zeros())
                    + u64::from(64 - r.unsigned_abs().leading_zeros());
                t.seen(v.digits, v.exp, r);
            }
            if cost < best.0 {
                best = (cost, order, significant);
            }
        }
    }
    (best.1, best.2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::testing::encoded;
    use crate::codec::{decode_all_with, ErrorBound, Reader, Stored};
    use crate::motion::format::Format;
    use crate::motion::formats::{read_as, ReadOptions};
    use crate::motion::synthetic::{dancer, dancer_bvh};

    fn load(text: &str) -> crate::motion::Motion {
        read_as(Format::Bvh, text.as_bytes(), &ReadOptions::default())
            .unwrap()
            .motion
    }

    fn motion_rows(text: &str) -> Vec<&str> {
        let at = text.find("Frame Time").unwrap();
        text[at..]
            .lines()
            .skip(1)
            .filter(|l| !l.trim().is_empty())
            .collect()
    }

    #[test]
    fn gives_back_every_value_with_the_same_characters() {
        let mut text = dancer_bvh(400, 120.0, 3, 4);
        // Odd spellings the codec keeps verbatim, %g exponents, negative zeros.
        text = text.replacen("\n0.", "\n+0.", 1);
        let rows: Vec<String> = motion_rows(&text)
            .iter()
            .enumerate()
            .map(|(f, r)| {
                let mut toks: Vec<String> = r.split(' ').map(String::from).collect();
                toks[5] = ["-0.0000", "5.1072e-06", "1e-5", "-0", "7"][f % 5].into();
                toks.join(" ")
            })
            .collect();
        let head = &text[..text.find("Frame Time").unwrap()];
        let text = format!("{head}Frame Time: 0.008333\n{}\n", rows.join("\n"));
        let m = load(&text);
        let enc = encoded(&m, CodecId::BvhLossless, ErrorBound::max(0.0));
        let rig = Arc::new(Skeleton::new(m.skeleton.clone().unwrap().joints).unwrap());
        assert_eq!(enc.container.header.rig, Some(rig.hash()));
        let shared = Shared {
            basis: None,
            rig: Some(rig.clone()),
        };
        let reader = Reader::new(enc.container.header.clone(), shared.clone()).unwrap();
        let source = Stored::new(0, enc.container.chunks.iter().map(Vec::as_slice));
        // Whole take and a range across a chunk boundary, character for character.
        for (a, b) in [(0, 400), (100, 333)] {
            let ch = reader
                .read_channels(a..b, rig.channel_count(), &source)
                .unwrap();
            let p = ch.printed.unwrap();
            let cc = rig.channel_count();
            for (f, row) in rows[a..b].iter().enumerate() {
                let mut s = String::new();
                for c in 0..cc {
                    if c > 0 {
                        s.push(' ');
                    }
                    p.write(f * cc + c, &mut s);
                }
                assert_eq!(&s, row, "frame {}", a + f);
            }
        }
        assert!(decode_all_with(&enc.container, Shared::default()).is_err());
        assert_eq!(
            decode_all_with(&enc.container, shared).unwrap(),
            m.positions()
        );
    }

    #[test]
    fn codes_smooth_channels_in_a_few_bits_each() {
        let text = dancer_bvh(1200, 120.0, 5, 4);
        let m = load(&text);
        let enc = encoded(&m, CodecId::BvhLossless, ErrorBound::max(0.0));
        let values = m.skeleton.as_ref().unwrap().values.len();
        let bits = 8.0 * enc.stored_bytes as f64 / values as f64;
        // The jitter alone (0.05 wide at 4 decimals) is ~9 bits of noise per value, ~11 after a
        // quadratic predictor amplifies it.
        assert!(bits < 12.5, "{bits:.2} bits per value");
        assert!(
            enc.stored_bytes * 3 < text.len(),
            "{} of {}",
            enc.stored_bytes,
            text.len()
        );
    }

    #[test]
    fn damaged_chunks_fail_cleanly() {
        let m = dancer(300, 60.0, 9);
        let enc = encoded(&m, CodecId::BvhLossless, ErrorBound::max(0.0));
        let rig = Arc::new(Skeleton::new(m.skeleton.clone().unwrap().joints).unwrap());
        let d = BvhLossless
            .decoder(
                &[VERSION],
                m.point_count(),
                &Shared {
                    basis: None,
                    rig: Some(rig),
                },
            )
            .unwrap();
        let chunk = &enc.container.chunks[0];
        let frames = enc.container.header.chunks[0].frames as usize;
        let (_, bytes) =
            crate::codec::container::unpack_chunk(chunk, frames * m.point_count()).unwrap();
        for cut in [0, 1, bytes.len() / 2] {
            let _ = d.decode_channels(&bytes[..cut], frames);
        }
        for i in 0..bytes.len().min(200) {
            let mut b = bytes.to_vec();
            b[i] ^= 0xa5;
            let _ = d.decode_channels(&b, frames);
        }
    }
}
