//! The container: a header that says what was coded and how, and a list of independently
//! decodable chunks. Byte layout in `docs/FORMAT.md`; keep the two in step.

use std::ops::Range;

use super::entropy::{get_varint, put_varint};
use super::error::{malformed, Error, Result};
use super::wire::Reader;
use super::CodecId;

pub const MAGIC: &[u8; 4] = b"MCST";
pub const VERSION: u16 = 1;
const FIXED_HEADER: usize = 36;
const CHUNK_ENTRY: usize = 16;

/// Bounds on what a decoder of untrusted bytes agrees to allocate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecodeLimits {
    pub max_frames: u64,
    pub max_points: u64,
    pub max_samples: u64,
    pub max_params_bytes: u64,
    pub max_chunk_bytes: u64,
}

impl Default for DecodeLimits {
    /// Shapes as [`crate::limits`] sets them for takes; the byte bounds are the container's.
    fn default() -> Self {
        DecodeLimits::from(&crate::limits::Limits::default())
    }
}

impl From<&crate::limits::Limits> for DecodeLimits {
    /// What a decoder of stored (or imported) bitstreams may allocate under the service's
    /// policy: the shapes it allows a take; the byte bounds are the container's own.
    fn from(take: &crate::limits::Limits) -> Self {
        DecodeLimits {
            max_frames: take.frames,
            max_points: take.points,
            max_samples: take.samples,
            max_params_bytes: 64 << 20,
            max_chunk_bytes: 256 << 20,
        }
    }
}

fn limit(what: &'static str, actual: u64, limit: u64) -> Result<()> {
    if actual > limit {
        Err(Error::Limit {
            what,
            actual,
            limit,
        })
    } else {
        Ok(())
    }
}

/// Where one chunk sits in the take and how to check it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChunkMeta {
    pub first_frame: u32,
    pub frames: u32,
    pub len: u32,
    pub crc32c: u32,
}

impl ChunkMeta {
    /// Bytes one chunk takes in a header's index.
    pub const INDEX_BYTES: usize = CHUNK_ENTRY;

    pub fn frame_range(&self) -> Range<usize> {
        self.first_frame as usize..(self.first_frame + self.frames) as usize
    }
}

/// What a rate search counts a coding as taking stored: `params` header bytes, and per chunk
/// its codec bytes, its index entry and the one-byte gap-mask length of a chunk without
/// gaps. The searches code gap-filled frames, and a mask where there is one costs every
/// candidate alike, so it is left out (counting it would change which setting mdtt settles
/// on, and the bytes it writes).
pub fn estimated_bytes(params: usize, chunks: &[super::ChunkOut]) -> usize {
    params
        + chunks
            .iter()
            .map(|c| c.bytes.len() + ChunkMeta::INDEX_BYTES + 1)
            .sum::<usize>()
}

/// Everything needed to decode any chunk, apart from the chunk's own bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    pub codec: CodecId,
    pub frames: u32,
    pub points: u32,
    pub fps: f64,
    pub metres_per_unit: f64,
    /// Codec parameters and per-take side data (e.g. MDTT's basis), codec-defined.
    pub params: Vec<u8>,
    /// Content hash of a shared basis the chunks were coded with, if any.
    pub basis: Option<[u8; 32]>,
    /// Content hash of the skeleton ([`super::Skeleton`]) a codec that keeps channel values
    /// decodes with, if the codec is one.
    pub rig: Option<[u8; 32]>,
    pub chunks: Vec<ChunkMeta>,
}

impl Header {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b =
            Vec::with_capacity(FIXED_HEADER + self.params.len() + 40 + 16 * self.chunks.len());
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.push(self.codec as u8);
        b.push(u8::from(self.basis.is_some()) | (u8::from(self.rig.is_some()) << 1));
        b.extend_from_slice(&self.frames.to_le_bytes());
        b.extend_from_slice(&self.points.to_le_bytes());
        b.extend_from_slice(&self.fps.to_le_bytes());
        b.extend_from_slice(&self.metres_per_unit.to_le_bytes());
        b.extend_from_slice(&(self.params.len() as u32).to_le_bytes());
        b.extend_from_slice(&self.params);
        if let Some(h) = &self.basis {
            b.extend_from_slice(h);
        }
        if let Some(h) = &self.rig {
            b.extend_from_slice(h);
        }
        b.extend_from_slice(&(self.chunks.len() as u32).to_le_bytes());
        for c in &self.chunks {
            for v in [c.first_frame, c.frames, c.len, c.crc32c] {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        let crc = crc32c::crc32c(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        b
    }

    /// Parse a header from the start of `bytes`; returns it and its length in bytes.
    pub fn parse(bytes: &[u8], limits: &DecodeLimits) -> Result<(Header, usize)> {
        let mut r = Reader::named(bytes, "header");
        r.opening(MAGIC, VERSION, "bitstream")?;
        let codec_byte = r.u8()?;
        let codec = CodecId::from_byte(codec_byte)
            .ok_or_else(|| Error::Unsupported(format!("codec id {codec_byte}")))?;
        let flags = r.u8()?;
        if flags > 3 {
            return Err(Error::Unsupported(format!("header flags {flags:#x}")));
        }
        let frames = r.u32()?;
        let points = r.u32()?;
        limit("frame count", frames.into(), limits.max_frames)?;
        limit("point count", points.into(), limits.max_points)?;
        limit(
            "sample count",
            u64::from(frames) * u64::from(points),
            limits.max_samples,
        )?;
        let fps = r.f64()?;
        let metres_per_unit = r.f64()?;
        if !(fps.is_finite() && fps > 0.0 && metres_per_unit.is_finite() && metres_per_unit > 0.0) {
            return Err(malformed("frame rate or unit is not a positive number"));
        }
        let params_len = r.u32()?;
        limit(
            "codec parameter bytes",
            params_len.into(),
            limits.max_params_bytes,
        )?;
        let params = r.take(params_len as usize)?.to_vec();
        let mut hash = |bit: u8| -> Result<Option<[u8; 32]>> {
            Ok(if flags & bit != 0 {
                Some(r.take(32)?.try_into().expect("32 bytes"))
            } else {
                None
            })
        };
        let basis = hash(1)?;
        let rig = hash(2)?;
        let count = r.u32()? as usize;
        if count > frames.max(1) as usize {
            return Err(malformed(format!("{count} chunks for {frames} frames")));
        }
        let entries = r.take(
            count
                .checked_mul(CHUNK_ENTRY)
                .ok_or_else(|| malformed("chunk count"))?,
        )?;
        let mut chunks = Vec::with_capacity(count);
        let mut next = 0u64;
        for e in entries.chunks_exact(CHUNK_ENTRY) {
            let w = |i: usize| u32::from_le_bytes(e[i * 4..i * 4 + 4].try_into().expect("4"));
            let c = ChunkMeta {
                first_frame: w(0),
                frames: w(1),
                len: w(2),
                crc32c: w(3),
            };
            if u64::from(c.first_frame) != next || c.frames == 0 {
                return Err(malformed("chunk index does not tile the frames in order"));
            }
            limit("chunk bytes", c.len.into(), limits.max_chunk_bytes)?;
            next += u64::from(c.frames);
            chunks.push(c);
        }
        if next != u64::from(frames) {
            return Err(malformed(format!("chunks cover {next} of {frames} frames")));
        }
        let body_end = r.position();
        let crc = r.u32()?;
        if crc32c::crc32c(&bytes[..body_end]) != crc {
            return Err(Error::Checksum("header".into()));
        }
        Ok((
            Header {
                codec,
                frames,
                points,
                fps,
                metres_per_unit,
                params,
                basis,
                rig,
                chunks,
            },
            r.position(),
        ))
    }

    pub fn width(&self) -> usize {
        self.points as usize * 3
    }

    /// Indices of the chunks that overlap frames `start..end`.
    pub fn chunks_for(&self, start: usize, end: usize) -> Range<usize> {
        let first = self
            .chunks
            .partition_point(|c| (c.first_frame + c.frames) as usize <= start);
        let last = self
            .chunks
            .partition_point(|c| (c.first_frame as usize) < end);
        first..last.max(first)
    }
}

/// A whole encoded take: header plus chunk payloads, as stored in one file.
#[derive(Debug, Clone, PartialEq)]
pub struct Container {
    pub header: Header,
    pub chunks: Vec<Vec<u8>>,
}

impl Container {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = self.header.to_bytes();
        for c in &self.chunks {
            b.extend_from_slice(c);
        }
        b
    }

    pub fn parse(bytes: &[u8], limits: &DecodeLimits) -> Result<Container> {
        let (header, mut pos) = Header::parse(bytes, limits)?;
        let mut chunks = Vec::with_capacity(header.chunks.len());
        for (i, meta) in header.chunks.iter().enumerate() {
            let end = pos
                .checked_add(meta.len as usize)
                .filter(|&e| e <= bytes.len())
                .ok_or_else(|| malformed(format!("chunk {i} runs past the end")))?;
            let payload = &bytes[pos..end];
            verify_chunk(meta, payload, i)?;
            chunks.push(payload.to_vec());
            pos = end;
        }
        if pos != bytes.len() {
            return Err(malformed(format!("{} trailing bytes", bytes.len() - pos)));
        }
        Ok(Container { header, chunks })
    }

    /// Stored size: header plus payloads (what compression ratios divide by).
    pub fn stored_bytes(&self) -> usize {
        self.header.to_bytes().len() + self.chunks.iter().map(Vec::len).sum::<usize>()
    }
}

/// Check a chunk's length and checksum against its index entry.
pub fn verify_chunk(meta: &ChunkMeta, payload: &[u8], index: usize) -> Result<()> {
    if payload.len() != meta.len as usize {
        return Err(malformed(format!(
            "chunk {index} is {} bytes, index says {}",
            payload.len(),
            meta.len
        )));
    }
    if crc32c::crc32c(payload) != meta.crc32c {
        return Err(Error::Checksum(format!("chunk {index}")));
    }
    Ok(())
}

/// A chunk payload: the gap mask of its samples, then the codec's bytes.
///
/// The mask is a run-length list (varints) of alternating present/missing runs over the
/// chunk's samples (frame-major), starting with present; an empty list means no gaps.
pub fn pack_chunk(valid: Option<&[bool]>, codec_bytes: &[u8]) -> Vec<u8> {
    let mut mask = Vec::new();
    if let Some(v) = valid.filter(|v| v.iter().any(|x| !x)) {
        let mut current = true;
        let mut run = 0u64;
        for &x in v {
            if x == current {
                run += 1;
            } else {
                put_varint(&mut mask, run);
                current = x;
                run = 1;
            }
        }
        put_varint(&mut mask, run);
    }
    let mut out = Vec::with_capacity(mask.len() + codec_bytes.len() + 4);
    put_varint(&mut out, mask.len() as u64);
    out.extend_from_slice(&mask);
    out.extend_from_slice(codec_bytes);
    out
}

/// Pack consecutive codec chunks into stored payloads (gap mask + codec bytes) and their
/// index entries; `valid` is the take's per-sample validity (`frames × points`), if it has
/// gaps. Returns the entries, the payloads and the frames they cover.
pub fn pack_chunks(
    chunks: Vec<super::ChunkOut>,
    valid: Option<&[bool]>,
    points: usize,
) -> (Vec<ChunkMeta>, Vec<Vec<u8>>, usize) {
    let mut metas = Vec::with_capacity(chunks.len());
    let mut payloads = Vec::with_capacity(chunks.len());
    let mut first = 0usize;
    for ch in chunks {
        let mask = valid.map(|v| &v[first * points..(first + ch.frames) * points]);
        let (meta, payload) = pack_indexed(first, &ch, mask);
        metas.push(meta);
        payloads.push(payload);
        first += ch.frames;
    }
    (metas, payloads, first)
}

/// One codec chunk starting at frame `first`, packed with its gap mask, and its index entry.
pub fn pack_indexed(
    first: usize,
    chunk: &super::ChunkOut,
    valid: Option<&[bool]>,
) -> (ChunkMeta, Vec<u8>) {
    let payload = pack_chunk(valid, &chunk.bytes);
    let meta = ChunkMeta {
        first_frame: first as u32,
        frames: chunk.frames as u32,
        len: payload.len() as u32,
        crc32c: crc32c::crc32c(&payload),
    };
    (meta, payload)
}

/// Split a chunk payload into its gap mask (`None` when all present) and codec bytes.
pub fn unpack_chunk(payload: &[u8], samples: usize) -> Result<(Option<Vec<bool>>, &[u8])> {
    let mut pos = 0;
    let mask_len = get_varint(payload, &mut pos).ok_or_else(|| malformed("gap mask length"))?;
    let end = usize::try_from(mask_len)
        .ok()
        .and_then(|l| pos.checked_add(l))
        .filter(|&e| e <= payload.len())
        .ok_or_else(|| malformed("gap mask runs past the chunk"))?;
    let codec_bytes = &payload[end..];
    if mask_len == 0 {
        return Ok((None, codec_bytes));
    }
    let mask_bytes = &payload[pos..end];
    let mut valid = Vec::with_capacity(samples);
    let mut p = 0;
    let mut current = true;
    while p < mask_bytes.len() {
        let run = get_varint(mask_bytes, &mut p).ok_or_else(|| malformed("gap mask run"))?;
        if run > (samples - valid.len()) as u64 {
            return Err(malformed("gap mask longer than the chunk"));
        }
        valid.extend(std::iter::repeat_n(current, run as usize));
        current = !current;
    }
    if valid.len() != samples {
        return Err(malformed("gap mask shorter than the chunk"));
    }
    Ok((Some(valid), codec_bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Container {
        let chunks = vec![vec![1u8, 2, 3], vec![4u8; 10]];
        let metas = vec![
            ChunkMeta {
                first_frame: 0,
                frames: 5,
                len: 3,
                crc32c: crc32c::crc32c(&chunks[0]),
            },
            ChunkMeta {
                first_frame: 5,
                frames: 2,
                len: 10,
                crc32c: crc32c::crc32c(&chunks[1]),
            },
        ];
        Container {
            header: Header {
                codec: CodecId::Quant,
                frames: 7,
                points: 2,
                fps: 120.0,
                metres_per_unit: 0.001,
                params: vec![9, 9],
                basis: Some([7; 32]),
                rig: Some([8; 32]),
                chunks: metas,
            },
            chunks,
        }
    }

    #[test]
    fn round_trips_and_finds_chunks() {
        let c = sample();
        let bytes = c.to_bytes();
        assert_eq!(
            Container::parse(&bytes, &DecodeLimits::default()).unwrap(),
            c
        );
        assert_eq!(c.header.chunks_for(0, 1), 0..1);
        assert_eq!(c.header.chunks_for(4, 6), 0..2);
        assert_eq!(c.header.chunks_for(5, 7), 1..2);
        assert_eq!(c.header.chunks_for(7, 7), 2..2);
    }

    #[test]
    fn every_truncation_and_bit_flip_is_a_typed_error() {
        let bytes = sample().to_bytes();
        for cut in 0..bytes.len() {
            assert!(Container::parse(&bytes[..cut], &DecodeLimits::default()).is_err());
        }
        for i in 0..bytes.len() {
            for bit in 0..8 {
                let mut b = bytes.clone();
                b[i] ^= 1 << bit;
                assert!(
                    Container::parse(&b, &DecodeLimits::default()).is_err(),
                    "flip {i}.{bit}"
                );
            }
        }
    }

    #[test]
    fn limits_reject_before_allocating() {
        let bytes = sample().to_bytes();
        let tight = DecodeLimits {
            max_frames: 6,
            ..DecodeLimits::default()
        };
        assert!(matches!(
            Container::parse(&bytes, &tight),
            Err(Error::Limit { .. })
        ));
    }

    #[test]
    fn gap_masks_round_trip() {
        let valid = vec![true, true, false, false, true, false];
        let p = pack_chunk(Some(&valid), b"xyz");
        let (v, rest) = unpack_chunk(&p, 6).unwrap();
        assert_eq!(v.unwrap(), valid);
        assert_eq!(rest, b"xyz");
        let p = pack_chunk(Some(&[true; 4]), b"q");
        assert_eq!(unpack_chunk(&p, 4).unwrap(), (None, &b"q"[..]));
        assert!(unpack_chunk(&pack_chunk(Some(&valid), b""), 5).is_err());
    }
}
