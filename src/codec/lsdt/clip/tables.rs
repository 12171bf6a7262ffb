//! The per-take-tables entropy stage of `lsdt-clip` (parameters version 2): what batch
//! encodes write. Live streams keep the adaptive stage (version 1): a stream cannot know its
//! statistics before its first clip goes out.
//!
//! Why: adaptive models start from nothing in every chunk, and a one-second clip of a
//! 27-point skeleton is too few symbols to learn ~130 contexts. Models fitted once over the
//! whole take (`entropy::geometric`, stored with its parameters) make held-out Bandai takes
//! 4–16 % smaller (more the shorter the clip), side data included, and decode twice as fast.
//!
//! Symbols and contexts are the adaptive stage's: per clip the number of coded frequencies
//! `K` (context [`COUNT`]), then for `k < K`, coordinate, row, the coefficient in context
//! [`context`]`(k, r, same coefficient at k − 1)`, each a token ([`tokens`]) with raw bits.
//! Chunk: `varint(rANS length)`, `varint(raw length)` (only with a residual bound), the rANS
//! stream, the raw bits, then the residual layer range coded as in version 1 (the rest).

use super::{context, CONTEXTS};
use crate::codec::entropy::geometric::{tables_of, token, Geometric, Stats};
use crate::codec::entropy::rans::{self, BitReader, BitWriter, Table, TableSet};
use crate::codec::entropy::tokens::{get_signed, get_unsigned, signed_token};
use crate::codec::entropy::{get_varint, put_varint};
use crate::codec::error::{malformed, Result};

/// Context of a clip's frequency count.
const COUNT: usize = CONTEXTS;
/// Models per take.
pub(super) const MODELS: usize = CONTEXTS + 1;

/// Every symbol of one clip's coefficients (`q`: `kn × 3J`, frequency major) in coding
/// order, as `(context, value)`; the count first, as `(COUNT, kn)`.
fn walk(q: &[i32], kn: usize, points: usize, mut put: impl FnMut(usize, i32)) {
    let w = points * 3;
    put(COUNT, kn as i32);
    for k in 0..kn {
        for (i, r) in (0..3).flat_map(|_| 0..points).enumerate() {
            let below = if k > 0 { q[(k - 1) * w + i] } else { 0 };
            put(context(k, r, below), q[k * w + i]);
        }
    }
}

/// The models that code `clips` (each `(q, kn)`) in the fewest bits.
pub(super) fn fit<'a>(
    clips: impl Iterator<Item = (&'a [i32], usize)>,
    points: usize,
) -> Vec<Option<Geometric>> {
    let mut stats = vec![Stats::default(); MODELS];
    for (q, kn) in clips {
        walk(q, kn, points, |ctx, v| {
            let (m, t) = if ctx == COUNT {
                (v as u32, token(v as u32).0)
            } else {
                let (m, t, _, _) = signed_token(v);
                (m, t)
            };
            stats[ctx].add(m, t);
        });
    }
    stats.iter().map(|s| s.fit().map(|f| f.0)).collect()
}

/// One clip's chunk: its coefficients coded with `tables` (`tables_of` the take's models), then `residual` (the range-coded
/// residual layer; `None` when the take has no residual bound).
pub(super) fn code_clip(
    tables: &[Table],
    q: &[i32],
    kn: usize,
    points: usize,
    residual: Option<Vec<u8>>,
) -> Vec<u8> {
    let mut enc = rans::Encoder::new();
    let mut bits = BitWriter::new();
    walk(q, kn, points, |ctx, v| {
        let (t, n, raw) = if ctx == COUNT {
            token(v as u32)
        } else {
            let (_, t, n, raw) = signed_token(v);
            (t, n, raw)
        };
        enc.put(&tables[ctx], t as usize);
        bits.put(raw, n);
    });
    let (coded, raw) = (enc.finish(), bits.finish());
    let mut out = Vec::with_capacity(coded.len() + raw.len() + 8);
    put_varint(&mut out, coded.len() as u64);
    if residual.is_some() {
        put_varint(&mut out, raw.len() as u64);
    }
    out.extend_from_slice(&coded);
    out.extend_from_slice(&raw);
    if let Some(r) = residual {
        out.extend_from_slice(&r);
    }
    out
}

/// A chunk's coefficients as decoded by [`ClipTables::decode`].
pub(super) struct Decoded<'a> {
    /// The coded frequencies' coefficients, `K × 3J`, frequency major.
    pub q: Vec<i32>,
    /// The residual layer's bytes (empty without a residual bound).
    pub residual: &'a [u8],
}

/// The decoder's side of a take's tables.
pub(super) struct ClipTables {
    set: TableSet,
}

impl ClipTables {
    pub(super) fn new(models: &[Option<Geometric>]) -> ClipTables {
        ClipTables {
            set: TableSet::new(&tables_of(models)),
        }
    }

    /// Decode the coefficients of a chunk of `n` frames (`residual`: whether the take has a
    /// residual layer after them).
    pub(super) fn decode<'a>(
        &self,
        bytes: &'a [u8],
        n: usize,
        points: usize,
        residual: bool,
    ) -> Result<Decoded<'a>> {
        let mut pos = 0;
        let mut length = || {
            get_varint(bytes, &mut pos)
                .and_then(|v| usize::try_from(v).ok())
                .ok_or_else(|| malformed("lsdt-clip chunk header"))
        };
        let coded_len = length()?;
        let raw_len = if residual { Some(length()?) } else { None };
        let coded_end = pos
            .checked_add(coded_len)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| malformed("lsdt-clip chunk header"))?;
        let raw_end = match raw_len {
            Some(l) => coded_end
                .checked_add(l)
                .filter(|&e| e <= bytes.len())
                .ok_or_else(|| malformed("lsdt-clip chunk header"))?,
            None => bytes.len(),
        };
        let mut dec = rans::Decoder::new(&bytes[pos..coded_end]);
        let mut bits = BitReader::new(&bytes[coded_end..raw_end]);
        let kn = get_unsigned(&mut dec, &mut bits, &self.set, COUNT) as usize;
        if kn > n {
            return Err(malformed(format!(
                "lsdt-clip chunk codes {kn} frequencies of {n}"
            )));
        }
        let w = points * 3;
        let mut q = vec![0i32; kn * w];
        for k in 0..kn {
            for (i, r) in (0..3).flat_map(|_| 0..points).enumerate() {
                let below = if k > 0 { q[(k - 1) * w + i] } else { 0 };
                q[k * w + i] = get_signed(&mut dec, &mut bits, &self.set, context(k, r, below));
            }
        }
        if !dec.finished_cleanly() || !bits.finished_cleanly() {
            return Err(malformed("lsdt-clip chunk does not decode to its end"));
        }
        Ok(Decoded {
            q,
            residual: &bytes[raw_end..],
        })
    }
}
