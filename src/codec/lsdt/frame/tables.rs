//! The per-take-tables entropy stage of `lsdt-frame` (parameters version 3; version 2
//! differs only in the "left" context and still decodes).
//!
//! The encoder runs the closed loop over the whole take first ([`Recorder`]), then counts
//! tokens per context, fits each context's two-parameter model (`entropy::geometric`), and
//! codes every chunk with rANS against tables built from those models. The models travel
//! with the take's parameters, so each chunk still decodes on its own.
//!
//! Contexts of a predicted coefficient: the size class of the same coefficient in the
//! previous frame, of the coefficient two rows back in this frame (both known to the
//! decoder; two rows rather than one so that the decoder need not finish a symbol before
//! it can find the next one's table), and the row's place in the basis (rows are ordered
//! by energy). How finely each is split is
//! the take's [`Shape`]: the encoder tries a few and keeps the smallest total, models
//! included — fine shapes pay on long takes, coarse ones on short takes.
//!
//! Residual-layer corrections (max bounds) are coded per frame as the number of corrected
//! points, the gaps between them, and three signed values per point.
//!
//! Chunk layout: `varint(rANS length) · rANS stream · raw bits` (signs and low bits).

use super::{check_chunk, FrameParams, TABLES_V2, TABLES_VERSION};
use crate::codec::entropy::geometric::{
    read_models, tables_of, token, write_models, Geometric, Stats, TOKENS, TOKEN_BITS,
};
use crate::codec::entropy::rans::{self, BitReader, BitWriter, Table, TableSet};
use crate::codec::entropy::tokens::{get_signed, get_unsigned, signed, signed_token, SIGNED_RAW};
use crate::codec::entropy::{get_varint, put_varint};
use crate::codec::error::{malformed, Result};
use crate::codec::lsdt::spatial::Spatial;
use crate::codec::rate::Smallest;
use crate::codec::residual::FrameResidual;
use crate::codec::wire::Reader;
use crate::codec::{ChunkDecoder, ChunkOut};

/// How finely coefficient contexts are split.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shape {
    /// Row buckets (rows split evenly).
    pub rows: u8,
    /// Size classes of the same coefficient in the previous frame.
    pub prev: u8,
    /// Size classes of the coefficient [`Tables::lag`] rows back in this frame.
    pub left: u8,
}

/// What the encoder tries, finest first.
const SHAPES: [Shape; 3] = [
    Shape {
        rows: 8,
        prev: 5,
        left: 3,
    },
    Shape {
        rows: 4,
        prev: 4,
        left: 2,
    },
    Shape {
        rows: 2,
        prev: 3,
        left: 1,
    },
];

/// Residual contexts: the count after a frame without / with corrections, the gaps, and the
/// values of each axis.
const RESIDUAL_CONTEXTS: usize = 6;

impl Shape {
    fn predicted(&self) -> usize {
        usize::from(self.rows) * usize::from(self.prev) * usize::from(self.left)
    }

    fn contexts(&self) -> usize {
        self.predicted() + usize::from(self.rows) + RESIDUAL_CONTEXTS
    }

    fn valid(&self) -> bool {
        (1..=16).contains(&self.rows)
            && (1..=8).contains(&self.prev)
            && (1..=8).contains(&self.left)
    }
}

/// Size class of a value: 0 for 0, then its bit length, capped at `n − 1`.
#[inline]
fn class(v: i32, n: usize) -> usize {
    ((32 - v.unsigned_abs().leading_zeros()) as usize).min(n - 1)
}

/// Context numbers of one layout (`j` points) under a shape.
struct Contexts {
    prev: usize,
    left: usize,
    rows: usize,
    /// Row bucket of each row.
    row: Vec<usize>,
    intra: usize,
    residual: usize,
}

impl Contexts {
    fn new(shape: Shape, j: usize) -> Contexts {
        let rows = usize::from(shape.rows);
        Contexts {
            prev: usize::from(shape.prev),
            left: usize::from(shape.left),
            rows,
            row: (0..j).map(|r| r * rows / j.max(1)).collect(),
            intra: shape.predicted(),
            residual: shape.predicted() + rows,
        }
    }

    #[inline]
    fn coef(&self, intra: bool, r: usize, prev: i32, left: i32) -> usize {
        if intra {
            self.intra + self.row[r]
        } else {
            (class(prev, self.prev) * self.left + class(left, self.left)) * self.rows + self.row[r]
        }
    }
}

/// A take's models: the side data that the chunks' tables are built from.
#[derive(Debug, Clone, PartialEq)]
pub struct Tables {
    pub shape: Shape,
    /// Rows back to the coefficient of the "left" context: 2 since version 3, 1 in
    /// version 2 (which still decodes). Two rows back leaves the decoder two symbols to
    /// find each table (0.3–0.8 % larger takes measured on CMU 01_03, 10–15 % faster
    /// decoding).
    pub lag: usize,
    /// Per context; `None` where the take has no symbols.
    models: Vec<Option<Geometric>>,
}

impl Tables {
    /// The take's parameters in version 2: the loop's, the shape, the models.
    pub fn params_bytes(&self, p: &FrameParams) -> Vec<u8> {
        let version = if self.lag == 1 {
            TABLES_V2
        } else {
            TABLES_VERSION
        };
        let mut w = p.with_version(version);
        let models = write_models(&self.models);
        w.bytes(&[self.shape.rows, self.shape.prev, self.shape.left])
            .u32(models.len() as u32)
            .bytes(&models);
        w.0
    }

    pub(super) fn read(r: &mut Reader<'_>, version: u8) -> Result<Tables> {
        let shape = Shape {
            rows: r.u8()?,
            prev: r.u8()?,
            left: r.u8()?,
        };
        if !shape.valid() {
            return Err(malformed(format!("lsdt-frame context shape {shape:?}")));
        }
        let n = r.u32()? as usize;
        let models = read_models(r.take(n)?, shape.contexts())
            .ok_or_else(|| malformed("lsdt-frame entropy models"))?;
        let lag = if version == TABLES_V2 { 1 } else { 2 };
        Ok(Tables { shape, lag, models })
    }

    fn rans_tables(&self) -> Vec<Table> {
        tables_of(&self.models)
    }
}

/// Where the walk over a take's symbols sends each one.
trait Sink {
    /// Token `t` of magnitude `m` in context `ctx`, followed by `bits` raw bits `raw`.
    fn put(&mut self, ctx: usize, m: u32, t: u32, bits: u32, raw: u32);
}

#[inline]
fn put_signed(sink: &mut impl Sink, ctx: usize, v: i32) {
    let (m, t, bits, raw) = signed_token(v);
    sink.put(ctx, m, t, bits, raw);
}

#[inline]
fn put_unsigned(sink: &mut impl Sink, ctx: usize, m: u32) {
    let (t, bits, extra) = token(m);
    sink.put(ctx, m, t, bits, extra);
}

/// The encoder's record of a take: every frame's coefficients and corrections.
pub(super) struct Recorder {
    j: usize,
    intra: Vec<bool>,
    q: Vec<i32>,
    residual: bool,
    /// Corrected points `(point, steps per axis)` of all frames, and where each frame's end.
    corrections: Vec<(u32, [i32; 3])>,
    ends: Vec<usize>,
}

impl Recorder {
    pub(super) fn new(points: usize) -> Recorder {
        Recorder {
            j: points,
            intra: Vec::new(),
            q: Vec::new(),
            residual: false,
            corrections: Vec::new(),
            ends: Vec::new(),
        }
    }

    pub(super) fn record(&mut self, intra: bool, q: &[i32], residual: Option<&FrameResidual>) {
        self.intra.push(intra);
        self.q.extend_from_slice(q);
        if let Some(r) = residual {
            self.residual = true;
            let (flags, steps) = r.corrections();
            for (p, _) in flags.iter().enumerate().filter(|(_, &f)| f) {
                self.corrections
                    .push((p as u32, [steps[p * 3], steps[p * 3 + 1], steps[p * 3 + 2]]));
            }
        }
        self.ends.push(self.corrections.len());
    }

    /// Send the symbols of frames `a..b` (a chunk: `a` is an intra frame) to `sink`.
    fn walk(&self, ctx: &Contexts, lag: usize, a: usize, b: usize, sink: &mut impl Sink) {
        let (j, w) = (self.j, self.j * 3);
        let zeros = vec![0i32; w];
        let mut prev_any = false;
        for f in a..b {
            let intra = f == a;
            let q = &self.q[f * w..(f + 1) * w];
            let prev = if intra {
                &zeros[..]
            } else {
                &self.q[(f - 1) * w..f * w]
            };
            for d in 0..3 {
                for r in 0..j {
                    let i = d * j + r;
                    let left = if r >= lag { q[i - lag] } else { 0 };
                    put_signed(sink, ctx.coef(intra, r, prev[i], left), q[i]);
                }
            }
            if self.residual {
                let start = if f == 0 { 0 } else { self.ends[f - 1] };
                let list = &self.corrections[start..self.ends[f]];
                put_unsigned(
                    sink,
                    ctx.residual + usize::from(prev_any),
                    list.len() as u32,
                );
                prev_any = !list.is_empty();
                let mut next = 0;
                for &(p, steps) in list {
                    put_unsigned(sink, ctx.residual + 2, p - next);
                    next = p + 1;
                    for (k, &v) in steps.iter().enumerate() {
                        put_signed(sink, ctx.residual + 3 + k, v);
                    }
                }
            }
        }
    }

    /// Chunk boundaries: each chunk runs from an intra frame to the next.
    fn chunks(&self) -> Vec<(usize, usize)> {
        let starts: Vec<usize> = (0..self.intra.len()).filter(|&f| self.intra[f]).collect();
        starts
            .iter()
            .enumerate()
            .map(|(k, &a)| (a, starts.get(k + 1).copied().unwrap_or(self.intra.len())))
            .collect()
    }

    /// Fit the models (trying each shape) and code the chunks.
    pub(super) fn finish(self) -> (Tables, Vec<ChunkOut>) {
        self.finish_with(2, &SHAPES)
    }

    /// The take's coded size in bits as [`Recorder::finish`] would make it, estimated with
    /// one mid-grained shape only: a fraction of the cost, for ranking the settings a
    /// rate control tries before coding the best of them.
    pub(super) fn estimate_bits(&self) -> f64 {
        self.fit(&self.chunks(), 2, SHAPES[1]).0
    }

    /// Fit the models of `shape`: the estimated size in bits (raw bits, tokens under the
    /// fitted models, the models themselves) and the tables.
    fn fit(&self, chunks: &[(usize, usize)], lag: usize, shape: Shape) -> (f64, Tables) {
        let ctx = Contexts::new(shape, self.j);
        let mut stats = Counter {
            stats: vec![Stats::default(); shape.contexts()],
            raw: 0,
        };
        for &(a, b) in chunks {
            self.walk(&ctx, lag, a, b, &mut stats);
        }
        let fitted: Vec<Option<(Geometric, f64)>> = stats.stats.iter().map(Stats::fit).collect();
        let models: Vec<Option<Geometric>> = fitted.iter().map(|f| f.map(|f| f.0)).collect();
        let bits = stats.raw as f64
            + fitted.iter().flatten().map(|f| f.1).sum::<f64>()
            + 8.0 * write_models(&models).len() as f64;
        (bits, Tables { shape, lag, models })
    }

    /// [`Recorder::finish`] with the left context `lag` rows back (1: version 2), trying
    /// `shapes`.
    pub(super) fn finish_with(self, lag: usize, shapes: &[Shape]) -> (Tables, Vec<ChunkOut>) {
        let chunks = self.chunks();
        let mut best = Smallest::new();
        for &shape in shapes {
            let (bits, tables) = self.fit(&chunks, lag, shape);
            best.offer(bits, tables);
        }
        let tables = best.into_best().expect("at least one shape");
        let ctx = Contexts::new(tables.shape, self.j);
        let rans_tables = tables.rans_tables();
        let out = chunks
            .iter()
            .map(|&(a, b)| {
                let mut coder = Coder {
                    tables: &rans_tables,
                    rans: rans::Encoder::new(),
                    bits: BitWriter::new(),
                };
                self.walk(&ctx, tables.lag, a, b, &mut coder);
                let stream = coder.rans.finish();
                let raw = coder.bits.finish();
                let mut bytes = Vec::with_capacity(stream.len() + raw.len() + 4);
                put_varint(&mut bytes, stream.len() as u64);
                bytes.extend_from_slice(&stream);
                bytes.extend_from_slice(&raw);
                ChunkOut {
                    frames: b - a,
                    bytes,
                }
            })
            .collect();
        (tables, out)
    }
}

struct Counter {
    stats: Vec<Stats>,
    raw: u64,
}

impl Sink for Counter {
    #[inline]
    fn put(&mut self, ctx: usize, m: u32, t: u32, bits: u32, _: u32) {
        self.stats[ctx].add(m, t);
        self.raw += u64::from(bits);
    }
}

struct Coder<'a> {
    tables: &'a [Table],
    rans: rans::Encoder,
    bits: BitWriter,
}

impl Sink for Coder<'_> {
    #[inline]
    fn put(&mut self, ctx: usize, _: u32, t: u32, bits: u32, raw: u32) {
        self.rans.put(&self.tables[ctx], t as usize);
        self.bits.put(raw, bits);
    }
}

pub(super) struct Decoder {
    p: FrameParams,
    spatial: Spatial,
    ctx: Contexts,
    tables: TableSet,
    /// A predicted coefficient's context is the sum of three parts, kept here as table
    /// offsets ([`TableSet::offset`]): by the token of the same coefficient in the previous
    /// frame, by the row, and by the token two rows back. Only the last depends on a
    /// symbol of this frame, so the chain from a symbol to the table of the symbol two
    /// rows on is a load and two adds.
    prev_part: [usize; TOKENS],
    row_part: Vec<usize>,
    left_part: [usize; TOKENS],
    /// Intra contexts by row.
    intra_part: Vec<usize>,
    lag: usize,
}

impl Decoder {
    pub(super) fn new(p: FrameParams, spatial: Spatial, t: &Tables) -> Result<Decoder> {
        let ctx = Contexts::new(t.shape, spatial.points());
        if t.models.len() != t.shape.contexts() {
            return Err(malformed("lsdt-frame entropy models"));
        }
        let mut prev_part = [0; TOKENS];
        let mut left_part = [0; TOKENS];
        for (t, &bits) in TOKEN_BITS.iter().enumerate() {
            let bits = usize::from(bits);
            prev_part[t] = TableSet::offset(bits.min(ctx.prev - 1) * ctx.left * ctx.rows);
            left_part[t] = TableSet::offset(bits.min(ctx.left - 1) * ctx.rows);
        }
        Ok(Decoder {
            p,
            spatial,
            row_part: ctx.row.iter().map(|&r| TableSet::offset(r)).collect(),
            intra_part: ctx
                .row
                .iter()
                .map(|&r| TableSet::offset(ctx.intra + r))
                .collect(),
            ctx,
            tables: TableSet::new(&t.rans_tables()),
            prev_part,
            left_part,
            lag: t.lag,
        })
    }
}

/// One frame's coefficients as the decoder reads them.
struct Frame {
    /// Coefficients; only the non-zero rows' are written.
    q: Vec<i32>,
    /// Each coefficient's token, and the previous frame's (the next frame's contexts).
    tokens: Vec<u8>,
    prev_tokens: Vec<u8>,
    /// Non-zero rows per coordinate, for the inverse transform.
    rows: [Vec<u16>; 3],
}

impl Decoder {
    /// One coordinate's tokens of a frame into `tokens`; returns how many are non-zero,
    /// their rows listed in `rows`. The decoder's inner loop, kept to the rANS decode and
    /// the next context (the raw bits of the few non-zero rows come after, in
    /// [`Decoder::values`]): fewer instructions per symbol let the processor overlap more
    /// symbols' table loads. Monomorphised for intra and predicted frames so that neither
    /// pays for the other's context, and for the two ways of refilling rANS states
    /// ([`rans::Decoder::get_at`]).
    #[inline(always)]
    fn tokens<const INTRA: bool, const LAG: usize, const BRANCHLESS: bool>(
        &self,
        dec: &mut rans::Decoder<'_>,
        tokens: &mut [u8],
        prev: &[u8],
        rows: &mut [u16],
    ) -> usize {
        let set = &self.tables;
        let mut n = 0;
        // The context's "left" part: the token `LAG` rows back ([`Tables::lag`]).
        let (mut left, mut left2) = (self.left_part[0], self.left_part[0]);
        let parts = if INTRA {
            &self.intra_part
        } else {
            &self.row_part
        };
        let cells = tokens.iter_mut().zip(prev).zip(parts);
        for (r, ((token, &prev), &part)) in cells.enumerate() {
            let offset = if INTRA {
                part
            } else {
                let left = if LAG == 1 { left } else { left2 };
                self.prev_part[usize::from(prev) & (TOKENS - 1)] + part + left
            };
            let t = dec.get_at::<BRANCHLESS>(set, offset);
            *token = t as u8;
            left2 = left;
            left = self.left_part[t];
            // Branch-free list of the non-zero rows (n ≤ r, always in bounds).
            rows[n] = r as u16;
            n += usize::from(t != 0);
        }
        n
    }

    /// The values of the non-zero `rows` from their tokens and raw bits (row order, as
    /// the encoder wrote them).
    #[inline(always)]
    fn values(bits: &mut BitReader<'_>, tokens: &[u8], rows: &[u16], q: &mut [i32]) {
        for &r in rows {
            let t = usize::from(tokens[usize::from(r)]) & (TOKENS - 1);
            q[usize::from(r)] = signed(t, bits.get(SIGNED_RAW[t]));
        }
    }
}

impl ChunkDecoder for Decoder {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        check_chunk(&self.p, frames)?;
        let mut pos = 0;
        let split = get_varint(bytes, &mut pos)
            .and_then(|n| usize::try_from(n).ok())
            .and_then(|n| n.checked_add(pos))
            .filter(|&end| end <= bytes.len())
            .ok_or_else(|| malformed("lsdt-frame chunk header"))?;
        let (coded, raw) = (&bytes[pos..split], &bytes[split..]);
        let symbols = frames * 3 * self.spatial.points();
        match (self.lag, rans::refills_often(coded.len(), symbols)) {
            (1, false) => self.decode::<1, false>(coded, raw, frames, out),
            (1, true) => self.decode::<1, true>(coded, raw, frames, out),
            (_, false) => self.decode::<2, false>(coded, raw, frames, out),
            (_, true) => self.decode::<2, true>(coded, raw, frames, out),
        }
    }
}

impl Decoder {
    /// One chunk from its rANS stream (`coded`) and its raw bits.
    fn decode<const LAG: usize, const BRANCHLESS: bool>(
        &self,
        coded: &[u8],
        raw: &[u8],
        frames: usize,
        out: &mut [f32],
    ) -> Result<()> {
        let mut dec = rans::Decoder::new(coded);
        let mut bits = BitReader::new(raw);
        let (set, c) = (&self.tables, &self.ctx);
        let j = self.spatial.points();
        let w = j * 3;
        let step = self.p.step as f32;
        let residual = (self.p.residual_t > 0.0).then(|| FrameResidual::new(j, self.p.residual_t));
        let mut f = Frame {
            q: vec![0; w],
            tokens: vec![0; w],
            prev_tokens: vec![0; w],
            rows: [vec![0; j], vec![0; j], vec![0; j]],
        };
        // The loop's state (this frame, the last two) in the transform's layout.
        let mut cur = self.spatial.planar();
        let mut prev = cur.clone();
        let mut prev2 = cur.clone();
        let mut scratch = self.spatial.scratch();
        let mut prev_any = false;
        for (n, frame) in out.chunks_exact_mut(w).take(frames).enumerate() {
            let intra = n == 0;
            match (n, self.p.order) {
                (0, _) => cur.clear(),
                (1, _) | (_, 1) => cur.copy_from(&prev),
                _ => cur.extrapolate(&prev, &prev2),
            }
            for d in 0..3 {
                let q = &mut f.q[d * j..(d + 1) * j];
                let tokens = &mut f.tokens[d * j..(d + 1) * j];
                let prev = &f.prev_tokens[d * j..(d + 1) * j];
                let rows = &mut f.rows[d][..j];
                let n = if intra {
                    self.tokens::<true, LAG, BRANCHLESS>(&mut dec, tokens, prev, rows)
                } else {
                    self.tokens::<false, LAG, BRANCHLESS>(&mut dec, tokens, prev, rows)
                };
                Self::values(&mut bits, tokens, &rows[..n], q);
                self.spatial
                    .inverse_add_planar(d, &rows[..n], q, step, &mut scratch, &mut cur);
            }
            if let Some(r) = &residual {
                let n = get_unsigned(&mut dec, &mut bits, set, c.residual + usize::from(prev_any));
                if n as usize > j {
                    return Err(malformed("lsdt-frame corrections exceed the points"));
                }
                prev_any = n > 0;
                let mut next = 0usize;
                for _ in 0..n {
                    let p = next + get_unsigned(&mut dec, &mut bits, set, c.residual + 2) as usize;
                    if p >= j {
                        return Err(malformed("lsdt-frame correction past the last point"));
                    }
                    for k in 0..3 {
                        let v = get_signed(&mut dec, &mut bits, set, c.residual + 3 + k);
                        cur.add(p * 3 + k, r.correction(v));
                    }
                    next = p + 1;
                }
            }
            cur.write_interleaved(frame);
            std::mem::swap(&mut f.tokens, &mut f.prev_tokens);
            std::mem::swap(&mut prev2, &mut prev);
            std::mem::swap(&mut prev, &mut cur);
        }
        if !dec.finished_cleanly() || !bits.finished_cleanly() {
            return Err(malformed("lsdt-frame chunk does not decode to its end"));
        }
        Ok(())
    }
}
