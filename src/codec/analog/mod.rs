//! `analog-lossless` and `analog-bounded`: a take's analog channels (force plates, EMG)
//! coded per channel by linear prediction ([`lpc`]) with residuals through the adaptive
//! range coder the point codecs use — FLAC's design, with an adaptive entropy stage in
//! place of Rice codes.
//!
//! The container is the point codecs' ([`Container`]): `points` counts channels, `frames`
//! are point frames, and the chunks cover the same frame ranges as the take's point chunks,
//! so a time range decodes only its own chunks of both. The header's params say how values
//! were stored ([`Layout`]); a chunk holds each channel in turn, its rows
//! `first_frame × per_frame ..` coded independently of every other chunk.
//!
//! Lossless codes the stored values exactly: 16-bit integers as they are, floats as
//! integers where every value in the chunk is one, and otherwise as their bit patterns in
//! an order-preserving integer map (so that nearby floats are nearby integers). Bounded
//! quantises each channel to a step of twice its bound (in stored units), which keeps every
//! value within the bound, then codes the step indices losslessly; a channel whose bound
//! is below one stored step is coded losslessly.

pub mod lpc;

use super::container::{verify_chunk, ChunkMeta, Container, Header};
use super::entropy::ints::{magnitude_context, IntModel};
use super::entropy::io::{code_residual, Io};
use super::entropy::rangecoder::{Bit, Decoder as RangeDecoder, Encoder as RangeEncoder};
use super::entropy::{get_varint, put_varint, unzigzag, zigzag};
use super::error::{malformed, Error, Result};
use super::rate::Smallest;
use super::wire::{Reader, Writer};
use super::CodecId;
use crate::motion::analog::{Analog, Channel, Samples};
use lpc::Predictor;

const PARAMS_VERSION: u8 = 1;
/// Every parameter version the analog decoders read (`tests/frozen` holds each).
pub const VERSIONS: [u8; 1] = [PARAMS_VERSION];
/// Residual contexts, by the bit length of a running mean of recent residuals.
const CONTEXTS: usize = 14;

/// How the values were stored and how each channel was coded: the header's params.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    pub per_frame: usize,
    pub storage: Storage,
    pub gen_scale: f32,
    pub channels: Vec<Channel>,
    /// Per channel, the quantiser step in stored units (`None`: lossless).
    pub steps: Vec<Option<f64>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    Signed,
    Unsigned,
    Float,
}

impl Storage {
    fn of(s: &Samples) -> Storage {
        match s {
            Samples::Int {
                unsigned: false, ..
            } => Storage::Signed,
            Samples::Int { unsigned: true, .. } => Storage::Unsigned,
            Samples::Float(_) => Storage::Float,
        }
    }

    fn byte(self) -> u8 {
        self as u8
    }

    fn from_byte(b: u8) -> Option<Storage> {
        [Storage::Signed, Storage::Unsigned, Storage::Float]
            .into_iter()
            .find(|s| *s as u8 == b)
    }
}

fn put_str(w: &mut Writer, s: &str) {
    let mut b = Vec::new();
    put_varint(&mut b, s.len() as u64);
    w.bytes(&b).bytes(s.as_bytes());
}

impl Layout {
    fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new();
        let mut v = vec![PARAMS_VERSION];
        put_varint(&mut v, self.per_frame as u64);
        v.push(self.storage.byte());
        w.bytes(&v).f32(self.gen_scale);
        let mut n = Vec::new();
        put_varint(&mut n, self.channels.len() as u64);
        w.bytes(&n);
        for (c, step) in self.channels.iter().zip(&self.steps) {
            put_str(&mut w, &c.label);
            put_str(&mut w, &c.description);
            put_str(&mut w, &c.unit);
            w.f32(c.scale);
            let mut o = Vec::new();
            put_varint(&mut o, u64::from(zigzag(c.offset)));
            w.bytes(&o).f64(step.unwrap_or(0.0));
        }
        w.0
    }

    fn parse(b: &[u8], channels: usize) -> Result<Layout> {
        let mut r = Reader::new(b);
        let version = r.u8()?;
        if version != PARAMS_VERSION {
            return Err(Error::Unsupported(format!(
                "analog params version {version}"
            )));
        }
        let varint = |r: &mut Reader<'_>| -> Result<u64> {
            let rest = &b[r.position()..];
            let mut pos = 0;
            let v = get_varint(rest, &mut pos).ok_or_else(|| malformed("analog params varint"))?;
            r.take(pos)?;
            Ok(v)
        };
        let per_frame = varint(&mut r)?;
        if per_frame == 0 || per_frame > 1 << 16 {
            return Err(malformed(format!("{per_frame} analog samples per frame")));
        }
        let storage = Storage::from_byte(r.u8()?).ok_or_else(|| malformed("analog storage"))?;
        let gen_scale = r.f32()?;
        if varint(&mut r)? != channels as u64 {
            return Err(malformed("analog channel count disagrees with the header"));
        }
        let mut out = Vec::with_capacity(channels.min(b.len()));
        let mut steps = Vec::with_capacity(channels.min(b.len()));
        for _ in 0..channels {
            let mut s = || -> Result<String> {
                let n = varint(&mut r)?;
                let n = usize::try_from(n).map_err(|_| malformed("analog label length"))?;
                Ok(String::from_utf8_lossy(r.take(n)?).into_owned())
            };
            let (label, description, unit) = (s()?, s()?, s()?);
            let scale = r.f32()?;
            let offset =
                unzigzag(u32::try_from(varint(&mut r)?).map_err(|_| malformed("analog offset"))?);
            let step = r.f64()?;
            if !(step.is_finite() && step >= 0.0) {
                return Err(malformed("analog step"));
            }
            out.push(Channel {
                label,
                description,
                unit,
                scale,
                offset,
            });
            steps.push((step > 0.0).then_some(step));
        }
        if r.position() != b.len() {
            return Err(malformed("trailing bytes in analog params"));
        }
        Ok(Layout {
            per_frame: per_frame as usize,
            storage,
            gen_scale,
            channels: out,
            steps,
        })
    }

    /// Channel `c`'s factor from stored units to its unit.
    fn factor(&self, c: usize) -> f64 {
        (f64::from(self.channels[c].scale) * f64::from(self.gen_scale)).abs()
    }
}

/// Analog rows a chunk should hold at least (per channel): FLAC's block size. Smaller
/// chunks pay the adaptive models' learning and the predictor's coefficients again each
/// time (3 % more on the corpus at one second a chunk).
pub const MIN_CHUNK_ROWS: usize = 4096;

/// Analog chunks from the take's point chunks (`point_chunks`, frames each): consecutive
/// point chunks joined until a chunk holds [`MIN_CHUNK_ROWS`] rows, so that every analog
/// chunk starts and ends where point chunks do and a range decodes only the chunks it
/// overlaps of both.
pub fn chunk_frames(point_chunks: &[usize], per_frame: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut open = 0usize;
    for &f in point_chunks {
        open += f;
        if open * per_frame.max(1) >= MIN_CHUNK_ROWS {
            out.push(open);
            open = 0;
        }
    }
    if open > 0 {
        match out.last_mut() {
            // A short tail joins the chunk before it.
            Some(last) if open * per_frame.max(1) < MIN_CHUNK_ROWS / 2 => *last += open,
            _ => out.push(open),
        }
    }
    out
}

/// What encoding gave: the container and, per channel, the largest error in its unit.
pub struct Encoded {
    pub container: Container,
    pub max_error: Vec<f64>,
}

/// Encode `analog` (of a take at `fps`) in chunks of `chunk_frames` point frames each
/// (their sum is the take's frames), each channel within `bounds[c]` of its unit, or
/// losslessly where `bounds` is empty or a channel's bound is `None`.
pub fn encode(
    analog: &Analog,
    fps: f64,
    chunk_frames: &[usize],
    bounds: &[Option<f64>],
) -> Result<Encoded> {
    let n = analog.channel_count();
    let frames = analog.frames();
    if chunk_frames.iter().sum::<usize>() != frames || chunk_frames.contains(&0) {
        return Err(Error::Invalid(format!(
            "analog chunks of {chunk_frames:?} frames do not tile {frames} frames"
        )));
    }
    if !bounds.is_empty() && bounds.len() != n {
        return Err(Error::Invalid(format!(
            "{} bounds for {n} channels",
            bounds.len()
        )));
    }
    let storage = Storage::of(&analog.samples);
    let mut layout = Layout {
        per_frame: analog.per_frame,
        storage,
        gen_scale: analog.gen_scale,
        channels: analog.channels.clone(),
        steps: vec![None; n],
    };
    for (c, b) in bounds.iter().enumerate() {
        if let Some(b) = *b {
            if !(b.is_finite() && b > 0.0) {
                return Err(Error::Invalid(format!(
                    "analog bound {b} of {:?} is not a positive number",
                    analog.channels[c].label
                )));
            }
            let factor = layout.factor(c);
            let delta = if factor > 0.0 { b / factor } else { 0.0 };
            layout.steps[c] = match storage {
                // An integer step 2d + 1 keeps every value within d stored units.
                Storage::Signed | Storage::Unsigned => {
                    let d = delta.floor();
                    (d >= 1.0).then_some(2.0 * d.min(32_767.0) + 1.0)
                }
                // A hair inside twice the bound: the reconstruction rounds to f32.
                Storage::Float => (delta.is_finite() && delta > 0.0).then_some(2.0 * delta * 0.999),
            };
        }
    }
    let codec = if layout.steps.iter().any(Option::is_some) {
        CodecId::AnalogBounded
    } else {
        CodecId::AnalogLossless
    };
    let mut metas = Vec::with_capacity(chunk_frames.len());
    let mut payloads = Vec::with_capacity(chunk_frames.len());
    let mut max_error = vec![0.0f64; n];
    let mut first = 0usize;
    for &f in chunk_frames {
        let rows = analog.per_frame * f;
        let r0 = first * analog.per_frame;
        let mut enc = RangeEncoder::new();
        for (c, err) in max_error.iter_mut().enumerate() {
            let column: Vec<f64> = (r0..r0 + rows)
                .map(|r| analog.samples.get(r * n + c))
                .collect();
            let mut column_io = Column::from_values(&layout, c, &analog.samples, r0, rows);
            if matches!(column_io.mode, Mode::Bits | Mode::Grid) {
                // Floats that are not integers: on a grid, as predicted bit patterns, or as
                // their fields, whichever codes smallest.
                let floats: Vec<f32> = match &analog.samples {
                    Samples::Float(v) => (r0..r0 + rows).map(|r| v[r * n + c]).collect(),
                    Samples::Int { .. } => Vec::new(),
                };
                let mut candidates = vec![
                    Column {
                        mode: Mode::Bits,
                        x: floats.iter().map(|&f| ordered(f)).collect(),
                        quantum: 0.0,
                        fix: Vec::new(),
                    },
                    Column {
                        mode: Mode::Fields,
                        x: floats.iter().map(|&f| i64::from(f.to_bits())).collect(),
                        quantum: 0.0,
                        fix: Vec::new(),
                    },
                ];
                candidates.extend(grids(&floats).into_iter().map(|(q, x, fix)| Column {
                    mode: Mode::Grid,
                    x,
                    quantum: q,
                    fix,
                }));
                let mut best = Smallest::new();
                for col in candidates {
                    let mut e = RangeEncoder::new();
                    let mut trial = Column {
                        x: col.x.clone(),
                        fix: col.fix.clone(),
                        ..col
                    };
                    code_column(&mut e, &layout, c, &mut trial)?;
                    best.offer(e.finish().len(), col);
                }
                column_io = best.into_best().expect("two candidates at least");
            }
            code_column(&mut enc, &layout, c, &mut column_io)?;
            let decoded = column_io.values(&layout, c)?;
            let factor = layout.factor(c);
            for (i, a) in column.iter().enumerate() {
                let b = decoded.get(i);
                let e = if a.is_nan() && b.is_nan() {
                    0.0
                } else {
                    (a - b).abs() * factor
                };
                *err = err.max(e);
            }
        }
        let bytes = enc.finish();
        metas.push(ChunkMeta {
            first_frame: first as u32,
            frames: f as u32,
            len: bytes.len() as u32,
            crc32c: crc32c::crc32c(&bytes),
        });
        payloads.push(bytes);
        first += f;
    }
    for (c, e) in max_error.iter().enumerate() {
        if let Some(b) = bounds.get(c).copied().flatten() {
            if *e > b {
                return Err(Error::BoundMissed {
                    codec: codec.to_string(),
                    detail: format!(
                        "channel {:?}: {e} over its bound {b}",
                        analog.channels[c].label
                    ),
                });
            }
        } else if *e != 0.0 {
            return Err(Error::BoundMissed {
                codec: codec.to_string(),
                detail: format!("channel {:?} not lossless", analog.channels[c].label),
            });
        }
    }
    let header = Header {
        codec,
        frames: frames as u32,
        points: n as u32,
        fps,
        metres_per_unit: 1.0,
        params: layout.to_bytes(),
        basis: None,
        rig: None,
        chunks: metas,
    };
    Ok(Encoded {
        container: Container {
            header,
            chunks: payloads,
        },
        max_error,
    })
}

/// How one channel of one chunk is held while it is coded: as integers (stored integers,
/// integral floats, or quantiser indices) or as the ordered bit patterns of floats.
struct Column {
    mode: Mode,
    x: Vec<i64>,
    /// The grid step of [`Mode::Grid`].
    quantum: f64,
    /// [`Mode::Grid`]'s per-value corrections, in f32 units in the last place.
    fix: Vec<i64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// The stored values are these integers.
    Exact = 0,
    /// Float bit patterns, order-preserving.
    Bits = 1,
    /// Quantiser indices: the value is index × step.
    Steps = 2,
    /// Floats that all lie on one grid (ADC integers times a scale, as float-format files
    /// store them): the value is index × quantum, reproduced to the bit.
    Grid = 3,
    /// Floats that are noise to a predictor (filtered EMG crossing zero): sign, exponent
    /// (from the previous one) and mantissa coded apart.
    Fields = 4,
}

/// A [`Mode::Fields`] column: per value, its sign (in the context of the previous sign),
/// its exponent as a step from the previous one, and its 23 mantissa bits as they are.
fn code_fields<I: Io>(io: &mut I, col: &mut Column) -> Result<()> {
    let mut sign = [Bit::default(); 2];
    let mut steps = vec![IntModel::default(); 3];
    let (mut prev_sign, mut prev_exp, mut prev_step) = (0usize, 127i64, 0i64);
    for x in col.x.iter_mut() {
        let b = *x as u32;
        let s = io.bit(&mut sign[prev_sign], b >> 31 == 1);
        let ctx = prev_step.unsigned_abs().min(2) as usize;
        let step = code_residual(io, &mut steps[ctx], i64::from((b >> 23) & 0xff) - prev_exp)?;
        let e = prev_exp.wrapping_add(step);
        if !(0..=255).contains(&e) {
            return Err(malformed("float exponent out of range"));
        }
        let m = io.raw(b & 0x7f_ffff, 23);
        *x = i64::from((u32::from(s) << 31) | ((e as u32) << 23) | m);
        (prev_sign, prev_exp, prev_step) = (usize::from(s), e, step);
    }
    Ok(())
}

/// A grid's step, each value's index on it, and each value's correction from `index × step`
/// rounded to f32, in units in the last place (0 for a value on the grid).
type Grid = (f64, Vec<i64>, Vec<i64>);

/// The grid the values of `vals` lie on (ADC integers times a scale, as float-format files
/// store them): its step, the index of every value, and each value's correction in f32
/// units in the last place (a glitch, a filtered tail, or products rounded twice by the
/// writer), if at least half the values need none. The step is the floating-point GCD
/// (exact for exact multiples) of the first values or of them all, or the scale estimated
/// from the steps between values ([`scale_of`]).
fn grids(vals: &[f32]) -> Vec<Grid> {
    let gcd_of = |it: &mut dyn Iterator<Item = &f32>| -> Option<f64> {
        let mut q = 0f64;
        for &v in it {
            let a = f64::from(v).abs();
            if a == 0.0 || !a.is_finite() {
                continue;
            }
            q = if q == 0.0 { a } else { gcd(q, a) };
            if q < 1e-30 {
                return None;
            }
        }
        (q > 0.0).then_some(q)
    };
    // At least half the values on the grid: otherwise it is no grid.
    let allowed = vals.len() / 2;
    let fit = |q: f64| -> Option<Grid> {
        let mut x = Vec::with_capacity(vals.len());
        let mut fix = Vec::with_capacity(vals.len());
        let mut prev = 0i64;
        let mut off = 0usize;
        for &v in vals {
            let k = (f64::from(v) / q).round();
            let ki = if k.is_finite() && k.abs() < 2_147_483_648.0 {
                k as i64
            } else {
                prev
            };
            let d = ordered(v) - ordered((ki as f64 * q) as f32);
            if d != 0 {
                off += 1;
                if off > allowed {
                    return None;
                }
            }
            x.push(ki);
            fix.push(d);
            prev = ki;
        }
        Some((q, x, fix))
    };
    // Every step found: an exact GCD can be a degenerate one (a tiny power of two that
    // every float is a multiple of), so the encoder codes each and keeps the smallest.
    let mut steps: Vec<f64> = [
        gcd_of(&mut vals.iter().take(256)),
        gcd_of(&mut vals.iter()),
        scale_of(vals),
    ]
    .into_iter()
    .flatten()
    .collect();
    steps.dedup();
    steps.into_iter().filter_map(fit).collect()
}

/// The scale `q` a writer multiplied ADC integers by, when the products were rounded to
/// f32 (so that no exact GCD exists). The smallest step between distinct values estimates
/// it (refined on the largest value); then each value `v = fl32(k·q)` confines `q` to the
/// interval that rounds `k·q` to `v`, and the intersection of those intervals (skipping
/// values that would empty it: glitches, kept off the grid) is a `q` that reproduces every
/// other value to the bit.
fn scale_of(vals: &[f32]) -> Option<f64> {
    let mut v: Vec<f32> = vals.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f32::total_cmp);
    v.dedup();
    let steps: Vec<f64> = v
        .windows(2)
        .map(|w| f64::from(w[1]) - f64::from(w[0]))
        .filter(|d| *d > 0.0)
        .collect();
    let big = v.iter().map(|x| f64::from(x.abs())).fold(0.0f64, f64::max);
    let least = steps.iter().copied().fold(f64::INFINITY, f64::min);
    if !(least.is_finite() && least > 0.0) {
        return None;
    }
    // The steps are multiples of q give or take rounding: their approximate GCD (a
    // sparse chunk may never step by q itself).
    let eps = (least * 1e-3).max(f64::from(f32::EPSILON) * big * 4.0);
    let step = steps.iter().fold(least, |g, &d| approx_gcd(g, d, eps));
    if !(step > eps && big / step < 2_147_483_648.0) {
        return None;
    }
    let q0 = big / (big / step).round().max(1.0);
    let (mut lo, mut hi) = (0.0f64, f64::INFINITY);
    let mut skipped = 0usize;
    for &x in &v {
        let a = x.abs();
        if a == 0.0 {
            continue;
        }
        let k = (f64::from(a) / q0).round();
        if k < 1.0 {
            return None;
        }
        let bits = a.to_bits();
        let up = f64::from(f32::from_bits(bits + 1));
        let down = f64::from(f32::from_bits(bits - 1));
        let (l, h) = (
            (f64::from(a) + down) / 2.0 / k,
            (f64::from(a) + up) / 2.0 / k,
        );
        if l.max(lo) < h.min(hi) {
            (lo, hi) = (l.max(lo), h.min(hi));
        } else {
            skipped += 1;
            if skipped > v.len() / 50 + 2 {
                (lo, hi) = (0.0, f64::INFINITY);
                break;
            }
        }
    }
    let estimate = if hi.is_finite() && lo > 0.0 && lo < hi {
        (lo + hi) / 2.0
    } else {
        q0
    };
    // Writers multiply by an f32 scale: the f32s next to the estimate are candidates too;
    // the one that puts the most values exactly on the grid wins.
    let near = estimate as f32;
    let exact = |q: f64| {
        vals.iter()
            .take(4096)
            .filter(|&&v| ((f64::from(v) / q).round() * q) as f32 == v)
            .count()
    };
    std::iter::once(estimate)
        .chain(
            (-4i32..=4).map(|u| f64::from(f32::from_bits(near.to_bits().wrapping_add_signed(u)))),
        )
        .filter(|q| q.is_finite() && *q > 0.0)
        .max_by_key(|&q| exact(q))
}

/// Euclid on integers.
fn gcd_u64(a: u64, b: u64) -> u64 {
    let (mut a, mut b) = (a, b);
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// The GCD of two positive floats known only to within `eps`: Euclid's remainders, a
/// remainder within `eps` of 0 or of the divisor counting as none.
fn approx_gcd(a: f64, b: f64, eps: f64) -> f64 {
    let (mut a, mut b) = if a >= b { (a, b) } else { (b, a) };
    while b > eps {
        let r = a % b;
        if r < eps || b - r < eps {
            return b;
        }
        a = b;
        b = r;
    }
    a
}

/// The GCD of two positive floats by Euclid's remainders (exact in floating point), stopping
/// where the remainder is negligible.
fn gcd(a: f64, b: f64) -> f64 {
    let (mut a, mut b) = if a >= b { (a, b) } else { (b, a) };
    while b > a * 1e-12 {
        let r = a % b;
        a = b;
        b = r;
    }
    a
}

/// f32 bits to an integer that orders as the floats do (negative floats reversed).
fn ordered(v: f32) -> i64 {
    let b = v.to_bits();
    let u = if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    };
    i64::from(u) - (1 << 31)
}

fn unordered(x: i64) -> Option<f32> {
    let u = u32::try_from(x.checked_add(1 << 31)?).ok()?;
    let b = if u & 0x8000_0000 != 0 {
        u & 0x7FFF_FFFF
    } else {
        !u
    };
    Some(f32::from_bits(b))
}

impl Column {
    fn from_values(layout: &Layout, c: usize, s: &Samples, r0: usize, rows: usize) -> Column {
        let n = layout.channels.len();
        let at = |r: usize| (r0 + r) * n + c;
        match (s, layout.steps[c]) {
            (Samples::Int { values, .. }, None) => Column {
                mode: Mode::Exact,
                x: (0..rows).map(|r| i64::from(values[at(r)])).collect(),
                quantum: 0.0,
                fix: Vec::new(),
            },
            (Samples::Int { values, .. }, Some(step)) => {
                let q = step as i64;
                let d = (q - 1) / 2;
                Column {
                    mode: Mode::Steps,
                    x: (0..rows)
                        .map(|r| (i64::from(values[at(r)]) + d).div_euclid(q))
                        .collect(),
                    quantum: 0.0,
                    fix: Vec::new(),
                }
            }
            (Samples::Float(v), step) => {
                let vals: Vec<f32> = (0..rows).map(|r| v[at(r)]).collect();
                if let Some(step) = step {
                    let x: Option<Vec<i64>> = vals
                        .iter()
                        .map(|&f| {
                            let k = (f64::from(f) / step).round();
                            let back = (k * step) as f32;
                            (k.abs() < 2f64.powi(52)
                                && f64::from((back - f).abs()) <= step / 2.0 / 0.999)
                                .then_some(k as i64)
                        })
                        .collect();
                    if let Some(x) = x {
                        return Column {
                            mode: Mode::Steps,
                            x,
                            quantum: 0.0,
                            fix: Vec::new(),
                        };
                    }
                }
                let integral = vals
                    .iter()
                    .all(|&f| f.abs() < 16_777_216.0 && (f as i32 as f32).to_bits() == f.to_bits());
                if integral {
                    Column {
                        mode: Mode::Exact,
                        x: vals.iter().map(|&f| i64::from(f as i32)).collect(),
                        quantum: 0.0,
                        fix: Vec::new(),
                    }
                } else if let Some((q, x, fix)) = grids(&vals).into_iter().next() {
                    Column {
                        mode: Mode::Grid,
                        x,
                        quantum: q,
                        fix,
                    }
                } else {
                    Column {
                        mode: Mode::Bits,
                        x: vals.iter().map(|&f| ordered(f)).collect(),
                        quantum: 0.0,
                        fix: Vec::new(),
                    }
                }
            }
        }
    }

    /// The stored values the column decodes to, checked against the storage.
    fn values(&self, layout: &Layout, c: usize) -> Result<Stored> {
        let bad = || malformed(format!("analog channel {c} decodes outside its storage"));
        let step = || layout.steps[c].ok_or_else(bad);
        Ok(match (self.mode, layout.storage) {
            (Mode::Exact, Storage::Float) => Stored::Float(
                self.x
                    .iter()
                    .map(|&x| {
                        (x.unsigned_abs() <= 1 << 24)
                            .then_some(x as f32)
                            .ok_or_else(bad)
                    })
                    .collect::<Result<_>>()?,
            ),
            (Mode::Fields, Storage::Float) => Stored::Float(
                self.x
                    .iter()
                    .map(|&x| u32::try_from(x).map(f32::from_bits).map_err(|_| bad()))
                    .collect::<Result<_>>()?,
            ),
            (Mode::Fields, _) => return Err(bad()),
            (Mode::Bits, Storage::Float) => Stored::Float(
                self.x
                    .iter()
                    .map(|&x| unordered(x).ok_or_else(bad))
                    .collect::<Result<_>>()?,
            ),
            (Mode::Steps, Storage::Float) => {
                let step = step()?;
                Stored::Float(self.x.iter().map(|&x| (x as f64 * step) as f32).collect())
            }
            (Mode::Grid, Storage::Float) => {
                let q = self.quantum;
                if self.fix.len() != self.x.len() {
                    return Err(bad());
                }
                Stored::Float(
                    self.x
                        .iter()
                        .zip(&self.fix)
                        .map(|(&x, &d)| {
                            unordered(ordered((x as f64 * q) as f32).wrapping_add(d))
                                .ok_or_else(bad)
                        })
                        .collect::<Result<_>>()?,
                )
            }
            (Mode::Grid, _) => return Err(bad()),
            (Mode::Bits, _) => return Err(bad()),
            (mode, storage) => {
                let range = if storage == Storage::Unsigned {
                    0..=65_535i64
                } else {
                    -32_768..=32_767i64
                };
                let q = if mode == Mode::Steps {
                    step()? as i64
                } else {
                    1
                };
                Stored::Int(
                    self.x
                        .iter()
                        .map(|&x| {
                            let v = x.checked_mul(q).ok_or_else(bad)?;
                            // A quantised value may overshoot the 16-bit range by < step.
                            let v = if q > 1 {
                                v.clamp(*range.start(), *range.end())
                            } else {
                                v
                            };
                            if range.contains(&v) {
                                Ok(v as i32)
                            } else {
                                Err(bad())
                            }
                        })
                        .collect::<Result<_>>()?,
                )
            }
        })
    }
}

/// One channel's decoded stored values.
enum Stored {
    Int(Vec<i32>),
    Float(Vec<f32>),
}

impl Stored {
    fn get(&self, i: usize) -> f64 {
        match self {
            Stored::Int(v) => f64::from(v[i]),
            Stored::Float(v) => f64::from(v[i]),
        }
    }
}

/// Code one channel of one chunk, written once for both directions ([`Io`]): the mode,
/// the predictor, the warm-up values and the residuals. On decode, `col` is filled.
fn code_column<I: Io>(io: &mut I, layout: &Layout, c: usize, col: &mut Column) -> Result<()> {
    let rows = col.x.len();
    let mode = io.raw(col.mode as u32, 3);
    col.mode = match mode {
        0 => Mode::Exact,
        1 if layout.storage == Storage::Float => Mode::Bits,
        2 if layout.steps[c].is_some() => Mode::Steps,
        3 if layout.storage == Storage::Float => Mode::Grid,
        4 if layout.storage == Storage::Float => Mode::Fields,
        _ => return Err(malformed(format!("analog channel {c}: mode {mode}"))),
    };
    if col.mode == Mode::Fields {
        return code_fields(io, col);
    }
    if col.mode == Mode::Grid {
        let bits = col.quantum.to_bits();
        let hi = io.raw((bits >> 32) as u32, 32);
        let lo = io.raw(bits as u32, 32);
        col.quantum = f64::from_bits((u64::from(hi) << 32) | u64::from(lo));
        if !(col.quantum.is_finite() && col.quantum > 0.0) {
            return Err(malformed(format!("analog channel {c}: grid step")));
        }
    }
    // A factor every value shares (FLAC's "wasted bits", generalised: a 12-bit ADC stored
    // shifted into 16 bits, a quantised channel) is divided out before prediction.
    let common = if io.encoding() {
        col.x
            .iter()
            .fold(0u64, |g, &v| gcd_u64(g, v.unsigned_abs()))
            .max(1)
    } else {
        1
    };
    let common = code_residual(io, &mut IntModel::default(), common as i64 - 1)? + 1;
    if !(1..=1 << 32).contains(&common) {
        return Err(malformed(format!(
            "analog channel {c}: common factor {common}"
        )));
    }
    if io.encoding() && common > 1 {
        col.x.iter_mut().for_each(|v| *v /= common);
    }
    let chosen = if io.encoding() {
        Some(lpc::choose(&col.x).0)
    } else {
        None
    };
    let predictor = code_predictor(io, chosen.as_ref())?;
    if predictor.order() > rows {
        return Err(malformed(format!(
            "analog channel {c}: order past the chunk"
        )));
    }
    let mut warm = IntModel::default();
    let mut prev = 0i64;
    for t in 0..predictor.order() {
        let d = code_residual(io, &mut warm, col.x[t].wrapping_sub(prev))?;
        col.x[t] = prev.wrapping_add(d);
        prev = col.x[t];
    }
    let mut models = vec![IntModel::default(); CONTEXTS];
    // A running mean of |residual| × 16: the context is its size.
    let mut mean16: u64 = 16;
    for t in predictor.order()..rows {
        let p = predictor.predict(&col.x, t);
        let ctx = magnitude_context((mean16 >> 4).min(i32::MAX as u64) as i32, CONTEXTS);
        let r = code_residual(io, &mut models[ctx], col.x[t].wrapping_sub(p))?;
        col.x[t] = p.wrapping_add(r);
        mean16 = mean16 - (mean16 >> 4) + r.unsigned_abs().min(1 << 40);
    }
    if common > 1 {
        col.x.iter_mut().for_each(|v| *v = v.wrapping_mul(common));
    }
    if col.mode == Mode::Grid {
        // Each value's correction from its grid point, in the context of the previous one
        // being none or some.
        let mut models = [IntModel::default(), IntModel::default()];
        col.fix.resize(rows, 0);
        let mut prev = 0usize;
        for d in col.fix.iter_mut() {
            *d = code_residual(io, &mut models[prev], *d)?;
            prev = usize::from(*d != 0);
        }
    }
    Ok(())
}

fn code_predictor<I: Io>(io: &mut I, p: Option<&Predictor>) -> Result<Predictor> {
    let lpc = io.raw(u32::from(matches!(p, Some(Predictor::Lpc { .. }))), 1) == 1;
    if !lpc {
        let order = io.raw(p.map_or(0, |p| p.order() as u32), 3) as usize;
        if order > 4 {
            return Err(malformed("fixed predictor order over 4"));
        }
        return Ok(Predictor::Fixed(order));
    }
    let (shift, coeffs) = match p {
        Some(Predictor::Lpc { shift, coeffs }) => (*shift, coeffs.clone()),
        _ => (0, Vec::new()),
    };
    let order = io.raw(coeffs.len().saturating_sub(1) as u32, 5) as usize + 1;
    let shift = io.raw(shift, 5);
    if shift > lpc::MAX_SHIFT {
        return Err(malformed("LPC shift"));
    }
    let mut m = IntModel::default();
    let mut out = Vec::with_capacity(order);
    for i in 0..order {
        let c = io.int(&mut m, coeffs.get(i).copied().unwrap_or(0));
        if c.unsigned_abs() >= 1 << (lpc::PRECISION - 1) {
            return Err(malformed("LPC coefficient past its precision"));
        }
        out.push(c);
    }
    Ok(Predictor::Lpc { shift, coeffs: out })
}

/// Decodes the chunks of one analog container.
#[derive(Debug, Clone)]
pub struct Decoder {
    header: Header,
    layout: Layout,
}

impl Decoder {
    pub fn new(header: Header) -> Result<Decoder> {
        if !matches!(
            header.codec,
            CodecId::AnalogLossless | CodecId::AnalogBounded
        ) {
            return Err(Error::Invalid(format!(
                "{} does not code analog channels",
                header.codec
            )));
        }
        let layout = Layout::parse(&header.params, header.points as usize)?;
        // What decoding may allocate: every value of the take (decode_all), bounded as the
        // service bounds what it reads ([`crate::limits::Limits::analog_samples`]).
        let values = u64::from(header.frames)
            .saturating_mul(layout.per_frame as u64)
            .saturating_mul(u64::from(header.points));
        let limit = crate::limits::Limits::default().analog_samples;
        if values > limit {
            return Err(Error::Limit {
                what: "analog values (frames × samples per frame × channels)",
                actual: values,
                limit,
            });
        }
        Ok(Decoder { header, layout })
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// Chunk `index`'s stored values, `rows × channels`, checked against its index entry.
    pub fn decode_chunk(&self, index: usize, payload: &[u8]) -> Result<Samples> {
        let meta = self
            .header
            .chunks
            .get(index)
            .ok_or_else(|| malformed(format!("no analog chunk {index}")))?;
        verify_chunk(meta, payload, index)?;
        let n = self.layout.channels.len();
        let rows = meta.frames as usize * self.layout.per_frame;
        let mut dec = RangeDecoder::new(payload);
        let mut out = match self.layout.storage {
            Storage::Float => Samples::Float(vec![0.0; rows * n]),
            s => Samples::Int {
                values: vec![0; rows * n],
                unsigned: s == Storage::Unsigned,
            },
        };
        for c in 0..n {
            let mut col = Column {
                mode: Mode::Exact,
                x: vec![0; rows],
                quantum: 0.0,
                fix: Vec::new(),
            };
            code_column(&mut dec, &self.layout, c, &mut col)?;
            if dec.overran() {
                return Err(malformed(format!("analog chunk {index} is cut short")));
            }
            match (col.values(&self.layout, c)?, &mut out) {
                (Stored::Float(v), Samples::Float(o)) => v
                    .into_iter()
                    .enumerate()
                    .for_each(|(r, x)| o[r * n + c] = x),
                (Stored::Int(v), Samples::Int { values: o, .. }) => v
                    .into_iter()
                    .enumerate()
                    .for_each(|(r, x)| o[r * n + c] = x),
                _ => return Err(malformed("analog chunk of the wrong storage")),
            }
        }
        Ok(out)
    }

    /// An [`Analog`] of decoded stored values (of whole chunks, or a range of them).
    pub fn analog(&self, samples: Samples) -> Result<Analog> {
        Analog::new(
            self.layout.per_frame,
            self.layout.gen_scale,
            self.layout.channels.clone(),
            samples,
        )
        .map_err(|e| malformed(e.to_string()))
    }

    /// Decode chunks `range` (payloads in order) and join them.
    pub fn decode_chunks<'a>(
        &self,
        first: usize,
        payloads: impl IntoIterator<Item = &'a [u8]>,
    ) -> Result<Samples> {
        let mut joined: Option<Samples> = None;
        for (i, p) in payloads.into_iter().enumerate() {
            let s = self.decode_chunk(first + i, p)?;
            joined = Some(match (joined, s) {
                (None, s) => s,
                (Some(Samples::Float(mut a)), Samples::Float(b)) => {
                    a.extend(b);
                    Samples::Float(a)
                }
                (
                    Some(Samples::Int {
                        mut values,
                        unsigned,
                    }),
                    Samples::Int { values: b, .. },
                ) => {
                    values.extend(b);
                    Samples::Int { values, unsigned }
                }
                _ => return Err(malformed("analog chunks of different storage")),
            });
        }
        Ok(joined.unwrap_or(match self.layout.storage {
            Storage::Float => Samples::Float(Vec::new()),
            s => Samples::Int {
                values: Vec::new(),
                unsigned: s == Storage::Unsigned,
            },
        }))
    }
}

/// Decode a whole analog container.
pub fn decode_all(c: &Container) -> Result<Analog> {
    let d = Decoder::new(c.header.clone())?;
    let s = d.decode_chunks(0, c.chunks.iter().map(Vec::as_slice))?;
    d.analog(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel(label: &str, scale: f32, offset: i32) -> Channel {
        Channel {
            label: label.into(),
            description: "test".into(),
            unit: "N".into(),
            scale,
            offset,
        }
    }

    /// Two channels at 10 samples per frame: a force-like smooth signal and noisy EMG.
    fn signal(frames: usize, float: bool) -> Analog {
        let per_frame = 10;
        let rows = frames * per_frame;
        let mut seed = 7u64;
        let mut noise = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) as f64 / (1u64 << 31) as f64) - 0.5
        };
        let mut v = Vec::with_capacity(rows * 2);
        for r in 0..rows {
            let t = r as f64 / 1000.0;
            let force = 8000.0 * (t * 3.0).sin().max(0.0) + 40.0 * noise();
            let emg = 300.0 * noise() * (1.0 + (t * 5.0).sin());
            v.push(force);
            v.push(emg);
        }
        let samples = if float {
            Samples::Float(v.iter().map(|&x| (x * 0.01) as f32).collect())
        } else {
            Samples::Int {
                values: v.iter().map(|&x| x.round() as i32).collect(),
                unsigned: false,
            }
        };
        Analog::new(
            per_frame,
            0.5,
            vec![channel("Fz1", 0.25, 3), channel("EMG1", 0.001, -2)],
            samples,
        )
        .unwrap()
    }

    #[test]
    fn lossless_round_trips_integers_and_floats() {
        for float in [false, true] {
            let a = signal(300, float);
            let e = encode(&a, 100.0, &[128, 128, 44], &[]).unwrap();
            assert_eq!(e.container.header.codec, CodecId::AnalogLossless);
            assert_eq!(e.max_error, [0.0, 0.0]);
            let bytes = e.container.to_bytes();
            let back = Container::parse(&bytes, &Default::default()).unwrap();
            assert_eq!(decode_all(&back).unwrap(), a);
            if !float {
                // 16-bit values, predicted: well under their 2 bytes each.
                assert!(bytes.len() < a.raw_bytes() * 3 / 4, "{} bytes", bytes.len());
            }
        }
    }

    #[test]
    fn analog_chunks_join_point_chunks_at_their_boundaries() {
        // 100-frame point chunks at 10 samples a frame: 1000 rows each, five make 4096+.
        let c = chunk_frames(&[100; 12], 10);
        assert_eq!(c, [500, 700]);
        assert_eq!(chunk_frames(&[100; 11], 10), [500, 600]);
        assert_eq!(chunk_frames(&[30], 1), [30]);
        assert_eq!(chunk_frames(&[5000, 5000], 1), [5000, 5000]);
    }

    #[test]
    fn a_range_is_the_rows_of_the_whole() {
        let a = signal(300, false);
        let e = encode(&a, 100.0, &[100, 100, 100], &[]).unwrap();
        let d = Decoder::new(e.container.header.clone()).unwrap();
        let mid = d
            .decode_chunks(1, [e.container.chunks[1].as_slice()])
            .unwrap();
        assert_eq!(d.analog(mid).unwrap(), a.slice_frames(100, 200));
    }

    #[test]
    fn bounded_keeps_every_value_within_its_channels_bound() {
        for float in [false, true] {
            let a = signal(200, float);
            let bounds = [Some(2.0), None];
            let lossless = encode(&a, 100.0, &[200], &[]).unwrap();
            let e = encode(&a, 100.0, &[200], &bounds).unwrap();
            assert_eq!(e.container.header.codec, CodecId::AnalogBounded);
            let back = decode_all(&e.container).unwrap();
            let mut worst: f64 = 0.0;
            for r in 0..a.rows() {
                worst = worst.max((a.value(r, 0) - back.value(r, 0)).abs());
                assert_eq!(a.value(r, 1), back.value(r, 1));
            }
            assert!(worst <= 2.0 && worst > 0.1, "{worst}");
            assert!((e.max_error[0] - worst).abs() < 1e-9);
            assert!(e.container.stored_bytes() < lossless.container.stored_bytes());
        }
    }

    #[test]
    fn damaged_chunks_give_errors_not_panics() {
        let a = signal(50, true);
        let e = encode(&a, 100.0, &[50], &[]).unwrap();
        let d = Decoder::new(e.container.header.clone()).unwrap();
        let good = &e.container.chunks[0];
        assert!(d.decode_chunk(0, &good[..good.len() / 2]).is_err());
        // With its checksum fixed, altered bytes must still decode safely.
        let mut h = e.container.header.clone();
        for i in 0..good.len().min(64) {
            let mut b = good.clone();
            b[i] ^= 0x3C;
            h.chunks[0].crc32c = crc32c::crc32c(&b);
            let d = Decoder::new(h.clone()).unwrap();
            let _ = d.decode_chunk(0, &b);
        }
        for cut in 0..e.container.header.params.len() {
            let _ = Layout::parse(&e.container.header.params[..cut], 2);
        }
        // A header that declares more values than a take may hold is refused before any
        // of them is allocated.
        let mut huge = e.container.header.clone();
        huge.frames = u32::MAX;
        assert!(matches!(Decoder::new(huge), Err(Error::Limit { .. })));
    }

    #[test]
    fn floats_on_a_grid_are_coded_as_its_indices() {
        let q = 10.0 / 32768.0;
        let v: Vec<f32> = (0..500)
            .map(|i| ((i as f64 * 0.05).sin() * 3000.0).round() * q)
            .map(|x| x as f32)
            .collect();
        assert_eq!(
            grids(&v)
                .first()
                .map(|g| (g.0, g.2.iter().filter(|d| **d != 0).count())),
            Some((q, 0))
        );
        let a = Analog::new(
            1,
            1.0,
            vec![channel("Pin1", 1.0, 0)],
            Samples::Float(v.clone()),
        )
        .unwrap();
        let e = encode(&a, 100.0, &[500], &[]).unwrap();
        assert_eq!(decode_all(&e.container).unwrap(), a);
        // As ints it costs what the ADC integers would, far under their float bits.
        assert!(
            e.container.stored_bytes() < 500,
            "{}",
            e.container.stored_bytes()
        );
        assert!(grids(&[0.1, 0.3, 1e-7])
            .iter()
            .all(|g| g.2.iter().any(|d| *d != 0) || g.0 < 1e-9));
        // A few values off the grid (a filtered tail) are kept as they are.
        let mut w = v.clone();
        w[497] = 1.234_567e-3;
        w[499] = f32::NAN;
        let g = grids(&w).into_iter().next().unwrap();
        let off: Vec<usize> = (0..500).filter(|&i| g.2[i] != 0).collect();
        assert_eq!((g.0, off), (q, vec![497, 499]));
        let a = Analog::new(
            1,
            1.0,
            vec![channel("Pin1", 1.0, 0)],
            Samples::Float(w.clone()),
        )
        .unwrap();
        let e = encode(&a, 100.0, &[500], &[]).unwrap();
        let back = decode_all(&e.container).unwrap();
        let (Samples::Float(b), Samples::Float(w)) = (&back.samples, &a.samples) else {
            unreachable!()
        };
        assert!(b.iter().zip(w).all(|(x, y)| x.to_bits() == y.to_bits()));
    }

    #[test]
    fn ordered_float_bits_round_trip_and_keep_order() {
        let v = [
            -3.5f32,
            -0.0,
            0.0,
            1e-30,
            2.0,
            f32::NAN,
            f32::INFINITY,
            -f32::MAX,
        ];
        for &x in &v {
            assert_eq!(unordered(ordered(x)).unwrap().to_bits(), x.to_bits());
        }
        assert!(ordered(-3.5) < ordered(-0.0) && ordered(0.0) < ordered(2.0));
    }
}
