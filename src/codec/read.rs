//! The read path: frames `a..b` of a take, all its points or some, from its header, the
//! shared basis the header names, and a source of its chunks. Every reader goes through
//! [`Reader::read`]: whole-take decoding after encoding, range requests (with a server's
//! cache of decoded chunks as the source), verification and export.

use std::ops::Range;
use std::sync::Arc;

use super::basis::{hex, Basis};
use super::container::{unpack_chunk, verify_chunk, Header};
use super::error::{malformed, Error, Result};
use super::skeleton::{Channels, Skeleton};
use super::{codec, ChunkDecoder};
use crate::motion::decimal::PrintedValues;

/// What a header may name beyond its own bytes — objects stored once and referenced by many
/// takes: a shared basis, and the skeleton of a codec that keeps channel values. A decoder
/// is built only when each one the header names is supplied with that hash.
#[derive(Debug, Clone, Default)]
pub struct Shared {
    pub basis: Option<Arc<Basis>>,
    pub rig: Option<Arc<Skeleton>>,
}

impl From<Option<Arc<Basis>>> for Shared {
    fn from(basis: Option<Arc<Basis>>) -> Shared {
        Shared { basis, rig: None }
    }
}

/// One chunk as a source holds it.
pub enum Chunk<'a> {
    /// Decoded already (a cache): `frames × points × 3`, NaN at gaps.
    Decoded(Arc<Vec<f32>>),
    /// The payload as stored.
    Stored(&'a [u8]),
}

/// Where a [`Reader`] gets the chunks a range needs.
pub trait ChunkSource {
    /// Chunk `index` of the take.
    fn chunk(&self, index: usize) -> Result<Chunk<'_>>;
    /// Whether chunks decoded from this source's payloads should be handed back to
    /// [`ChunkSource::keep`] (a cache); when not, whole chunks decode straight into the
    /// output.
    fn keeps(&self) -> bool {
        false
    }
    /// A chunk decoded from this source's payload.
    fn keep(&self, _index: usize, _decoded: Arc<Vec<f32>>) {}
}

/// Payloads in memory, of consecutive chunks from `first` on.
pub struct Stored<'a> {
    pub first: usize,
    pub payloads: Vec<&'a [u8]>,
}

impl<'a> Stored<'a> {
    pub fn new(first: usize, payloads: impl IntoIterator<Item = &'a [u8]>) -> Self {
        Stored {
            first,
            payloads: payloads.into_iter().collect(),
        }
    }
}

impl ChunkSource for Stored<'_> {
    fn chunk(&self, index: usize) -> Result<Chunk<'_>> {
        index
            .checked_sub(self.first)
            .and_then(|i| self.payloads.get(i))
            .map(|p| Chunk::Stored(p))
            .ok_or_else(|| Error::Fault(format!("chunk {index} was not supplied")))
    }
}

/// A take ready to read: its header and the decoder built from it (parsing a shared or
/// per-take basis costs more than decoding a second of frames, so servers keep a reader per
/// take).
pub struct Reader {
    header: Header,
    decoder: Box<dyn ChunkDecoder>,
}

impl Reader {
    /// `shared` holds what the header names (a basis, a rig), if it names any; their hashes
    /// must match.
    pub fn new(header: Header, shared: impl Into<Shared>) -> Result<Reader> {
        let decoder = decoder(&header, &shared.into())?;
        Ok(Reader { header, decoder })
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The chunks frames `range` lie in, once the range is checked against the take: what a
    /// caller fetches before [`Reader::read`].
    pub fn chunks_for(&self, range: Range<usize>) -> Result<Range<usize>> {
        check_range(&self.header, &range)?;
        Ok(self.header.chunks_for(range.start, range.end))
    }

    /// Decode one chunk (its payload as stored): all its frames, NaN at gaps.
    pub fn decode_chunk(&self, index: usize, payload: &[u8]) -> Result<Vec<f32>> {
        decode_chunk(&self.header, self.decoder.as_ref(), index, payload)
    }

    /// Frames `range` of the take, of every point or of the point indices `points`
    /// (`(end − start) × points × 3`, NaN at gaps). Only the chunks the range lies in are
    /// asked of `source`.
    pub fn read(
        &self,
        range: Range<usize>,
        points: Option<&[usize]>,
        source: &dyn ChunkSource,
    ) -> Result<Vec<f32>> {
        let wanted = self.chunks_for(range.clone())?;
        let all = self.header.points as usize;
        if let Some(bad) = points.and_then(|p| p.iter().find(|&&p| p >= all)) {
            return Err(Error::Invalid(format!(
                "point {bad} of a take of {all} points"
            )));
        }
        let selected = points.map_or(all, <[usize]>::len);
        let (w, out_w) = (all * 3, selected * 3);
        let (start, end) = (range.start, range.end);
        let mut out = vec![0f32; (end - start) * out_w];
        for i in wanted {
            let r = self.header.chunks[i].frame_range();
            let (lo, hi) = (r.start.max(start), r.end.min(end));
            let dest = &mut out[(lo - start) * out_w..(hi - start) * out_w];
            let decoded = match source.chunk(i)? {
                Chunk::Decoded(d) => d,
                Chunk::Stored(payload) => {
                    if points.is_none() && !source.keeps() {
                        // Kept nowhere: decode the rows wanted straight into the output.
                        let rows = lo - r.start..hi - r.start;
                        let decoder = self.decoder.as_ref();
                        decode_rows_into(&self.header, decoder, i, payload, rows, dest)?;
                        continue;
                    }
                    let d = Arc::new(self.decode_chunk(i, payload)?);
                    if source.keeps() {
                        source.keep(i, d.clone());
                    }
                    d
                }
            };
            if decoded.len() != r.len() * w {
                return Err(Error::Fault(format!(
                    "chunk {i} holds {} values, its {} frames need {}",
                    decoded.len(),
                    r.len(),
                    r.len() * w
                )));
            }
            let rows = &decoded[(lo - r.start) * w..(hi - r.start) * w];
            match points {
                None => dest.copy_from_slice(rows),
                Some(points) => {
                    for (frame, to) in rows.chunks_exact(w).zip(dest.chunks_exact_mut(out_w)) {
                        for (&p, to) in points.iter().zip(to.chunks_exact_mut(3)) {
                            to.copy_from_slice(&frame[p * 3..p * 3 + 3]);
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    /// Every frame of the take.
    pub fn read_all(&self, source: &dyn ChunkSource) -> Result<Vec<f32>> {
        self.read(0..self.header.frames as usize, None, source)
    }

    /// The channel values of frames `range`, for a take coded with a codec that keeps them
    /// ([`super::Codec::codes_channels`]); `channels` values per frame. Decoded from the
    /// stored payloads (a cache of decoded positions cannot give channels back).
    pub fn read_channels(
        &self,
        range: Range<usize>,
        channels: usize,
        source: &dyn ChunkSource,
    ) -> Result<Channels> {
        let wanted = self.chunks_for(range.clone())?;
        let (start, end) = (range.start, range.end);
        let mut out = Channels {
            values: Vec::with_capacity((end - start) * channels),
            printed: None,
        };
        for i in wanted {
            let Chunk::Stored(payload) = source.chunk(i)? else {
                return Err(Error::Fault(format!(
                    "chunk {i}: channel values need the stored payload"
                )));
            };
            let meta = self.header.chunks[i];
            verify_chunk(&meta, payload, i)?;
            let r = meta.frame_range();
            let (_, codec_bytes) = unpack_chunk(payload, r.len() * self.header.points as usize)?;
            let got = self.decoder.decode_channels(codec_bytes, r.len())?;
            if got.values.len() != r.len() * channels
                || got
                    .printed
                    .as_ref()
                    .is_some_and(|p| p.values.len() != got.values.len())
            {
                return Err(malformed(format!(
                    "chunk {i} holds {} channel values, its {} frames need {}",
                    got.values.len(),
                    r.len(),
                    r.len() * channels
                )));
            }
            let (lo, hi) = (
                (r.start.max(start) - r.start) * channels,
                (r.end.min(end) - r.start) * channels,
            );
            out.values.extend_from_slice(&got.values[lo..hi]);
            match (got.printed, &mut out.printed) {
                (Some(p), Some(acc)) => acc.append(p, lo..hi),
                (Some(p), none @ None) if out.values.len() == hi - lo => {
                    let mut first = PrintedValues::default();
                    first.append(p, lo..hi);
                    *none = Some(first);
                }
                (None, None) => {}
                _ => {
                    return Err(malformed(format!(
                        "chunk {i}: printed values in some chunks only"
                    )))
                }
            }
        }
        Ok(out)
    }
}

/// The chunk decoder for a header, given what it names (a basis, a rig): each hash must be
/// the header's, so a take is never decoded with the wrong basis or skeleton.
pub fn decoder(header: &Header, shared: &Shared) -> Result<Box<dyn ChunkDecoder>> {
    let c = codec(header.codec)?;
    let rig = named("skeleton", header.rig, shared.rig.clone(), |r| {
        (r.hash(), r.id())
    })?;
    if c.codes_channels() && rig.is_none() {
        return Err(malformed(format!(
            "codec {} decodes with a skeleton and the header names none",
            header.codec
        )));
    }
    let basis = named("basis", header.basis, shared.basis.clone(), |b| {
        (b.hash(), b.id())
    })?;
    if c.basis_kind().is_some() && basis.is_none() {
        return Err(malformed(format!(
            "codec {} needs a shared basis and the header names none",
            header.codec
        )));
    }
    c.decoder(
        &header.params,
        header.points as usize,
        &Shared { basis, rig },
    )
}

/// The stored object (`what`: a basis, a skeleton) a header names by hash, if it names one:
/// the one supplied, if its hash (`hash_of` gives hash and id) is the header's.
fn named<T>(
    what: &str,
    want: Option<[u8; 32]>,
    got: Option<Arc<T>>,
    hash_of: impl Fn(&T) -> ([u8; 32], String),
) -> Result<Option<Arc<T>>> {
    let Some(want) = want else {
        return Ok(None);
    };
    let got = got.ok_or_else(|| {
        Error::Basis(format!(
            "the take was coded with {what} {} and it was not supplied",
            hex(&want)
        ))
    })?;
    let (hash, id) = hash_of(&got);
    if hash != want {
        return Err(Error::Basis(format!(
            "the take was coded with {what} {}, got {id}",
            hex(&want)
        )));
    }
    Ok(Some(got))
}

/// Decode chunk `index` (its payload as stored): all its frames, NaN where the take has
/// gaps. The unit a server caches.
pub fn decode_chunk(
    header: &Header,
    decoder: &dyn ChunkDecoder,
    index: usize,
    payload: &[u8],
) -> Result<Vec<f32>> {
    let meta = header
        .chunks
        .get(index)
        .ok_or_else(|| Error::Fault(format!("no chunk {index}")))?;
    let mut out = vec![0f32; meta.frames as usize * header.width()];
    decode_chunk_into(header, decoder, index, payload, &mut out)?;
    Ok(out)
}

/// [`decode_chunk`] into `out` (exactly the chunk's frames).
fn decode_chunk_into(
    header: &Header,
    decoder: &dyn ChunkDecoder,
    index: usize,
    payload: &[u8],
    out: &mut [f32],
) -> Result<()> {
    let frames = header
        .chunks
        .get(index)
        .map_or(0, |meta| meta.frames as usize);
    decode_rows_into(header, decoder, index, payload, 0..frames, out)
}

/// Frames `rows` of chunk `index` (counted from the chunk's first) into `out`, NaN at gaps.
fn decode_rows_into(
    header: &Header,
    decoder: &dyn ChunkDecoder,
    index: usize,
    payload: &[u8],
    rows: Range<usize>,
    out: &mut [f32],
) -> Result<()> {
    let meta = header
        .chunks
        .get(index)
        .ok_or_else(|| Error::Fault(format!("no chunk {index}")))?;
    verify_chunk(meta, payload, index)?;
    let n = meta.frames as usize;
    let points = header.points as usize;
    if rows.start > rows.end || rows.end > n || out.len() != rows.len() * points * 3 {
        return Err(Error::Fault(format!(
            "rows {rows:?} of chunk {index} ({n} frames) into {} values",
            out.len()
        )));
    }
    let (mask, codec_bytes) = unpack_chunk(payload, n * points)?;
    if rows == (0..n) {
        decoder.decode_chunk(codec_bytes, n, out)?;
    } else {
        decoder.decode_rows(codec_bytes, n, rows.clone(), out)?;
    }
    if let Some(mask) = mask {
        for (s, ok) in out.chunks_exact_mut(3).zip(&mask[rows.start * points..]) {
            if !ok {
                s.fill(f32::NAN);
            }
        }
    }
    if any_infinite(out) {
        return Err(malformed("decoded values are not finite"));
    }
    Ok(())
}

/// Whether any value is ±∞ (a corrupt stream). Blocks are folded without an early exit so
/// that the compiler vectorises the scan: on fast decoders a per-value branch cost several
/// per cent of the decode.
fn any_infinite(v: &[f32]) -> bool {
    v.chunks(256)
        .any(|c| c.iter().fold(false, |any, x| any | x.is_infinite()))
}

/// A range lies within the take, start at most end (an empty range reads nothing).
fn check_range(header: &Header, range: &Range<usize>) -> Result<()> {
    if range.start > range.end || range.end > header.frames as usize {
        return Err(Error::Invalid(format!(
            "frames {}..{} outside 0..{}",
            range.start, range.end, header.frames
        )));
    }
    Ok(())
}
