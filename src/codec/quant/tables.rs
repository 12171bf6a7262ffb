//! `quant` parameters version 2: the same integers as version 1 (predictor order per chunk,
//! a reference per trajectory, prediction-residual differences in the same contexts), coded
//! as rANS tokens against per-take tables instead of adaptive binary decisions.
//!
//! Why: the adaptive binary coder spends four to six serial decisions on a coordinate, and
//! decoding capped near 0.4 M frames/s on a 38-point skeleton; one table lookup per value
//! decodes several times faster. The tables are fitted to the whole take first (two
//! parameters per context, `entropy::geometric`) and travel with its parameters, so every
//! chunk still decodes on its own.
//!
//! Params: `2u8`, step `f64`, the context models ([`write_models`]). Chunk: order `u8`,
//! `varint(rANS length)`, the rANS stream, then the raw bits (low bits and signs).

use super::{context, predict, prediction_residuals, split_order, MAX_REFERENCE, NEIGHBOUR};
use crate::codec::entropy::geometric::{read_models, tables_of, token, write_models, Stats};
use crate::codec::entropy::rans::{self, BitReader, BitWriter, TableSet};
use crate::codec::entropy::tokens::{get_signed, get_unsigned, signed_token};
use crate::codec::entropy::{get_varint, put_varint};
use crate::codec::error::{malformed, Result};

/// The parameters version this module writes.
pub const VERSION: u8 = 2;

/// Context of a trajectory's reference.
const REFERENCE: usize = 0;
/// Context of a trajectory's first value in a chunk.
const INTRA: usize = 1;
/// Contexts of the differences: [`context`] of the previous difference and the neighbour's
/// residual, after these two.
const DIFFS: usize = 2;
/// Every context.
pub const CONTEXTS: usize = DIFFS + super::BUCKETS * super::BUCKETS;

/// One chunk's integers in coding order: `(context, value)`; references are unsigned.
pub struct ChunkSymbols {
    order: u8,
    symbols: Vec<(usize, i32)>,
}

/// The symbols of a chunk of `frames × w` quantised values, with the predictor order whose
/// differences are smaller (as bits of magnitude: what the tokens cost).
pub fn chunk_symbols(q: &[i32], frames: usize, w: usize) -> ChunkSymbols {
    let cost = |s: &ChunkSymbols| -> u64 {
        s.symbols
            .iter()
            .map(|&(_, v)| u64::from(32 - v.unsigned_abs().leading_zeros()))
            .sum()
    };
    let a = symbols_with(q, frames, w, 1);
    let b = symbols_with(q, frames, w, 2);
    if cost(&b) < cost(&a) {
        b
    } else {
        a
    }
}

fn symbols_with(q: &[i32], frames: usize, w: usize, order: u8) -> ChunkSymbols {
    let residuals = prediction_residuals(q, frames, w, order);
    let mut symbols = Vec::with_capacity(q.len() + w);
    for c in 0..w {
        let k = super::choose_reference(&residuals, c, frames);
        symbols.push((REFERENCE, k as i32));
        let mut last = 0;
        for f in 0..frames {
            let d = residuals[c * frames + f]
                .wrapping_sub(super::reference_value(&residuals, c, k, f, frames));
            if f == 0 {
                symbols.push((INTRA, d));
            } else {
                let above = if c >= NEIGHBOUR {
                    residuals[(c - NEIGHBOUR) * frames + f]
                } else {
                    0
                };
                symbols.push((DIFFS + context(last, above), d));
                last = d;
            }
        }
    }
    ChunkSymbols { order, symbols }
}

/// The take's parameters and chunks: models fitted to every chunk's symbols, then each chunk
/// coded with them.
pub fn encode(step: f64, chunks: &[&ChunkSymbols]) -> (Vec<u8>, Vec<Vec<u8>>) {
    let mut stats = vec![Stats::default(); CONTEXTS];
    for ch in chunks {
        for &(ctx, v) in &ch.symbols {
            let (m, t, _, _) = signed_token(v);
            stats[ctx].add(m, t);
        }
    }
    let models: Vec<_> = stats.iter().map(|s| s.fit().map(|(g, _)| g)).collect();
    let tables = tables_of(&models);
    let mut params = vec![VERSION];
    params.extend_from_slice(&step.to_le_bytes());
    params.extend(write_models(&models));
    let coded = chunks
        .iter()
        .map(|ch| {
            let mut enc = rans::Encoder::new();
            let mut bits = BitWriter::new();
            for &(ctx, v) in &ch.symbols {
                if ctx == REFERENCE {
                    let (t, n, extra) = token(v as u32);
                    enc.put(&tables[ctx], t as usize);
                    bits.put(extra, n);
                } else {
                    let (_, t, n, raw) = signed_token(v);
                    enc.put(&tables[ctx], t as usize);
                    bits.put(raw, n);
                }
            }
            let stream = enc.finish();
            let mut out = vec![ch.order];
            put_varint(&mut out, stream.len() as u64);
            out.extend(stream);
            out.extend(bits.finish());
            out
        })
        .collect();
    (params, coded)
}

/// A version 2 decoder's state: the step and the take's tables.
pub struct Tables {
    pub step: f64,
    set: TableSet,
}

impl Tables {
    /// Parse version 2 parameters (`bytes` after the version byte).
    pub fn parse(bytes: &[u8]) -> Result<Tables> {
        let (step, models) = bytes
            .split_first_chunk::<8>()
            .ok_or_else(|| malformed("quant parameters end early"))?;
        let step = f64::from_le_bytes(*step);
        if !(step.is_finite() && step > 0.0) {
            return Err(malformed("quant step is not positive"));
        }
        let models = read_models(models, CONTEXTS)
            .ok_or_else(|| malformed("quant context models do not parse"))?;
        Ok(Tables {
            step,
            set: TableSet::new(&tables_of(&models)),
        })
    }

    /// Decode one chunk of `frames × w` values, handing each to `emit` (index, integer).
    pub fn decode(
        &self,
        bytes: &[u8],
        frames: usize,
        w: usize,
        mut emit: impl FnMut(usize, i32),
    ) -> Result<()> {
        let (order, rest) = split_order(bytes)?;
        let mut pos = 0;
        let len = get_varint(rest, &mut pos)
            .and_then(|n| usize::try_from(n).ok())
            .filter(|&n| n <= rest.len() - pos)
            .ok_or_else(|| malformed("quant chunk's rANS length"))?;
        let (stream, raw) = rest[pos..].split_at(len);
        let mut dec = rans::Decoder::new(stream);
        let mut bits = BitReader::new(raw);
        let set = &self.set;
        let mut residuals = vec![0i32; w * frames];
        for c in 0..w {
            let k = get_unsigned(&mut dec, &mut bits, set, REFERENCE) as usize;
            if k > MAX_REFERENCE || 3 * k > c {
                return Err(malformed(format!("trajectory {c} refers {k} points back")));
            }
            let (mut p1, mut p2, mut last) = (0i32, 0i32, 0i32);
            for f in 0..frames {
                let d = if f == 0 {
                    get_signed(&mut dec, &mut bits, set, INTRA)
                } else {
                    let above = if c >= NEIGHBOUR {
                        residuals[(c - NEIGHBOUR) * frames + f]
                    } else {
                        0
                    };
                    let d = get_signed(&mut dec, &mut bits, set, DIFFS + context(last, above));
                    last = d;
                    d
                };
                let r = d.wrapping_add(if k == 0 {
                    0
                } else {
                    residuals[(c - 3 * k) * frames + f]
                });
                residuals[c * frames + f] = r;
                let v = r.wrapping_add(predict(p1, p2, f, order));
                emit(f * w + c, v);
                p2 = p1;
                p1 = v;
            }
        }
        if !(dec.finished_cleanly() && bits.finished_cleanly()) {
            return Err(malformed("quant chunk does not end where its symbols do"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::codec::{self, quant, CodecId, ErrorBound, Input, Target};
    use crate::motion::synthetic::walker;

    /// Both versions meet the bound through the checked pipeline; version 2's chunks fail
    /// cleanly, never panic, when cut short or damaged.
    #[test]
    fn version_2_round_trips_meets_the_bound_and_refuses_damage() {
        let m = walker(300, 7, 120.0, 5, 0.1);
        for version in [1u8, 2] {
            let enc = codec::encode(
                &m,
                CodecId::Quant,
                ErrorBound::max(0.5),
                codec::EncodeOptions::with_encoder(None, |i, t| {
                    quant::encode_version(i, t, Some(version))
                }),
            )
            .unwrap();
            let (max, _) = crate::codec::testing::measured(&m, &enc);
            assert!(max <= 0.5, "{max}");
            assert_eq!(enc.container.header.params.len() == 8, version == 1);
        }
        let m = walker(300, 7, 120.0, 5, 0.0);
        let input = Input {
            data: m.positions(),
            valid: None,
            frames: 300,
            points: 7,
            fps: 120.0,
            shared: None,
            skeleton: None,
            names: &[],
            torso: None,
        };
        let out = quant::encode_version(&input, Target::max(0.5), Some(2)).unwrap();
        assert_eq!(out.params[0], super::VERSION);
        let dec = codec::codec(CodecId::Quant)
            .unwrap()
            .decoder(&out.params, 7, &Default::default())
            .unwrap();
        let chunk = &out.chunks[0];
        let mut frames = vec![0f32; chunk.frames * 21];
        dec.decode_chunk(&chunk.bytes, chunk.frames, &mut frames)
            .unwrap();
        let b = &chunk.bytes;
        for cut in [0, 1, b.len() / 2, b.len() - 1] {
            assert!(dec
                .decode_chunk(&b[..cut], chunk.frames, &mut frames)
                .is_err());
        }
        for at in (0..b.len()).step_by(7) {
            let mut damaged = b.clone();
            damaged[at] ^= 0x5a;
            let _ = dec.decode_chunk(&damaged, chunk.frames, &mut frames);
        }
        assert!(quant::encode_version(&input, Target::max(0.5), Some(3)).is_err());
    }
}
