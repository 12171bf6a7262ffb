//! Streaming encoders: a take coded while it is being recorded, frames in, finished chunks
//! out, each packed (gap mask, checksum, index entry) and checked on its decoded output as
//! batch encoding checks a whole take ([`super::pipeline`]).
//!
//! A codec that can code frames as they arrive says so through [`Codec::streaming`] and
//! implements [`Streaming`] (start a stream: its header params and a [`StreamCoder`]). Every
//! other step is here, the same for all of them: a service opens a [`StreamEncoder`] by codec
//! id, pushes frames, stores the [`StreamChunk`]s it hands back and [`StreamEncoder::confirm`]s
//! each once stored. A new streaming codec is one `impl Streaming` in its own module and one
//! `streaming()` in its `impl Codec`; nothing above the codec layer changes.

use std::sync::Arc;

use super::container::{pack_indexed, ChunkMeta, Header};
use super::error::{Error, Result};
use super::id::ErrorBound;
use super::CodecId;
use super::{codec, pipeline, read, Basis, ChunkDecoder, ChunkOut, Codec};
use crate::motion::metrics::{Accumulator, ErrorStats};

/// What a stream is opened with, checked by [`StreamEncoder::open`].
#[derive(Clone, Copy)]
pub struct StreamSpec<'a> {
    pub points: usize,
    pub fps: f64,
    /// The take's unit, in metres.
    pub metres_per_unit: f64,
    /// Every chunk is held to this bound's value as a max bound (with no search possible
    /// frame by frame; a mean bound is then met too).
    pub bound: ErrorBound,
    /// Frames per chunk: an intra period, a clip.
    pub chunk_frames: usize,
    /// The shared basis, for codecs that code with one ([`Codec::basis_kind`]).
    pub shared: Option<&'a Arc<Basis>>,
}

impl<'a> StreamSpec<'a> {
    /// The shared basis, for codecs that code with one ([`StreamEncoder::open`] has checked
    /// it is of their kind and shape).
    pub fn basis(&self) -> Result<&'a Arc<Basis>> {
        self.shared
            .ok_or_else(|| Error::Basis("this codec streams with a shared basis".into()))
    }

    /// The bound in the take's units, a hair inside as batch encoding aims: a stream codes
    /// every sample within the tighter of the two bounds, which meets a mean bound too
    /// (a frame-by-frame coder cannot aim at a mean it has not yet seen).
    pub fn target(&self) -> f64 {
        let t = self.bound.target(self.metres_per_unit * 1000.0);
        t.tightest()
    }
}

/// A codec's own part of a stream: codes frames, hands out codec chunks as they finish.
pub trait StreamCoder: Send {
    /// Code `frames` (whole frames of the stream's points; NaN marks a missing sample),
    /// which follow every frame pushed before. With `flush`, end the current chunk after
    /// them (if frames are pending). Returns the chunks finished, in order.
    fn push(&mut self, frames: &[f32], flush: bool) -> Result<Vec<ChunkOut>>;
}

/// How a codec that can stream starts a stream.
pub trait Streaming: Sync {
    /// The header params of a stream of `spec` and the coder that writes its chunks.
    /// `target` is the bound as a max in the take's units ([`StreamSpec::target`]).
    fn open(&self, spec: &StreamSpec<'_>, target: f64) -> Result<(Vec<u8>, Box<dyn StreamCoder>)>;

    /// For a codec that codes with a shared basis: the basis a stream of `points` points
    /// codes with when none has been trained for its layout (a stream cannot wait for
    /// training), and how it was made (its provenance). `None`: such a stream is refused.
    fn untrained_basis(&self, _points: usize) -> Option<(Basis, &'static str)> {
        None
    }
}

/// The codec live streams use when a client names none.
pub const DEFAULT_CODEC: CodecId = CodecId::LsdtFrame;

/// [`Streaming::untrained_basis`] of the codec `codec_id`, if it streams and has one.
pub fn untrained_basis(codec_id: CodecId, points: usize) -> Option<(Basis, &'static str)> {
    codec(codec_id).ok()?.streaming()?.untrained_basis(points)
}

/// The codecs that can code a live stream, in id order.
pub fn streaming_codecs() -> Vec<CodecId> {
    super::available()
        .into_iter()
        .filter(|&c| codec(c).is_ok_and(|c| c.streaming().is_some()))
        .collect()
}

/// One finished chunk, checked, ready to store: its index entry (the frame it starts at in
/// the take), its payload as stored, and what it decodes to.
#[derive(Clone)]
pub struct StreamChunk {
    pub meta: ChunkMeta,
    pub payload: Vec<u8>,
    /// The chunk decoded (NaN where a sample is missing), as a reader will decode it.
    pub decoded: Vec<f32>,
    /// The take's error sums up to and with this chunk.
    running: Accumulator,
    /// Its position among the stream's chunks.
    pub index: usize,
}

impl StreamChunk {
    /// The take's error sums up to and with this chunk: stored with it, for a server that
    /// takes the stream over ([`StreamEncoder::resume`]).
    pub fn running(&self) -> &Accumulator {
        &self.running
    }
}

/// A stream's take so far: frames, chunks, stored bytes and measured errors.
#[derive(Debug, Clone)]
pub struct Totals {
    pub frames: usize,
    pub chunks: usize,
    /// Header (with its index) plus payloads: what the take costs once closed.
    pub stored_bytes: usize,
    pub stats: ErrorStats,
}

/// A take coded frame by frame with one codec. Chunks are handed out by
/// [`StreamEncoder::push`] and become part of the take when [`StreamEncoder::confirm`]ed
/// (after the caller has stored them), so a chunk that could not be stored never enters
/// the take's index, totals or digest.
pub struct StreamEncoder {
    /// The take's header without its chunk index (what a live take stores).
    header: Header,
    header_len: usize,
    coder: Box<dyn StreamCoder>,
    decoder: Arc<dyn ChunkDecoder>,
    bound: ErrorBound,
    mm_per_unit: f64,
    points: usize,
    /// Frames pushed that no chunk handed out holds yet, as sent.
    pending: Vec<f32>,
    /// Chunks handed out so far, and the frame the next one starts at.
    handed_out: usize,
    next_frame: usize,
    index: Vec<ChunkMeta>,
    payload_bytes: usize,
    /// Error sums over the confirmed chunks, and over every chunk handed out.
    stats: Accumulator,
    handed_stats: Accumulator,
    digest: blake3::Hasher,
}

impl StreamEncoder {
    /// Start a stream of `spec` with `codec_id`; `Unsupported` if that codec cannot stream.
    pub fn open(codec_id: CodecId, spec: &StreamSpec<'_>) -> Result<StreamEncoder> {
        let c: &dyn Codec = codec(codec_id)?;
        let streaming = c.streaming().ok_or_else(|| {
            let names: Vec<String> = streaming_codecs().iter().map(|c| c.to_string()).collect();
            Error::Unsupported(format!(
                "{codec_id} codes whole takes only; streams are coded with {}",
                names.join(" or ")
            ))
        })?;
        if spec.points == 0 || spec.chunk_frames == 0 {
            return Err(Error::Invalid(format!(
                "a stream needs points and frames per chunk, got {} and {}",
                spec.points, spec.chunk_frames
            )));
        }
        let shared = pipeline::usable_basis(c, spec.shared, spec.points)?;
        let spec = StreamSpec { shared, ..*spec };
        let (params, coder) = streaming.open(&spec, spec.target())?;
        let header = Header {
            codec: codec_id,
            frames: 0,
            points: spec.points as u32,
            fps: spec.fps,
            metres_per_unit: spec.metres_per_unit,
            params,
            basis: shared.map(|b| b.hash()),
            rig: None,
            chunks: Vec::new(),
        };
        let decoder = Arc::from(read::decoder(&header, &shared.cloned().into())?);
        Ok(StreamEncoder {
            header_len: header.to_bytes().len(),
            header,
            coder,
            decoder,
            bound: spec.bound,
            mm_per_unit: spec.metres_per_unit * 1000.0,
            points: spec.points,
            pending: Vec::new(),
            handed_out: 0,
            next_frame: 0,
            index: Vec::new(),
            payload_bytes: 0,
            stats: Accumulator::new(spec.points),
            handed_stats: Accumulator::new(spec.points),
            digest: blake3::Hasher::new(),
        })
    }

    /// Go on with a stream another server started and stopped coding (it died): a coder
    /// opened afresh, whose first chunk is intra (every chunk decodes alone), joined to the
    /// take as stored. `stored` is the take's live header; `stats` the error sums stored
    /// with its last chunk. Then [`absorb`](Self::absorb) each stored chunk, in order.
    pub fn resume(
        codec_id: CodecId,
        spec: &StreamSpec<'_>,
        stored: &Header,
        stats: Accumulator,
    ) -> Result<StreamEncoder> {
        let mut e = StreamEncoder::open(codec_id, spec)?;
        if e.header != *stored {
            return Err(Error::Invalid(format!(
                "stream of {codec_id} cannot go on: its stored header differs from one opened \
                 with the same settings (another version wrote it?)"
            )));
        }
        if stats.points() != spec.points {
            return Err(Error::Invalid(format!(
                "stream error sums over {} points, the stream has {}",
                stats.points(),
                spec.points
            )));
        }
        e.stats = stats.clone();
        e.handed_stats = stats;
        Ok(e)
    }

    /// Join a chunk already stored to a [`resume`](Self::resume)d stream, in order: its
    /// index entry, size and decoded frames (for the take's digest).
    pub fn absorb(&mut self, meta: ChunkMeta, payload: &[u8]) -> Result<()> {
        if meta.first_frame as usize != self.next_frame || meta.frames == 0 {
            return Err(Error::Invalid(format!(
                "stored stream chunk {} starts at frame {}, the take has {}",
                self.index.len(),
                meta.first_frame,
                self.next_frame
            )));
        }
        let alone = Header {
            frames: meta.frames,
            chunks: vec![ChunkMeta {
                first_frame: 0,
                ..meta
            }],
            ..self.header.clone()
        };
        let decoded = read::decode_chunk(&alone, self.decoder.as_ref(), 0, payload)?;
        pipeline::digest_update(&mut self.digest, &decoded);
        self.payload_bytes += payload.len();
        self.next_frame += meta.frames as usize;
        self.handed_out += 1;
        self.index.push(meta);
        Ok(())
    }

    /// The take's header as stored while it is live: no chunk index, no frames.
    pub fn live_header(&self) -> &Header {
        &self.header
    }

    /// The take's header with the confirmed chunks as its index: what it is once closed.
    pub fn closed_header(&self) -> Header {
        Header {
            frames: self.committed_frames() as u32,
            chunks: self.index.clone(),
            ..self.header.clone()
        }
    }

    /// Values per frame: the stream's points × 3.
    pub fn width(&self) -> usize {
        self.points * 3
    }

    /// Code `frames` (whole frames, NaN for a missing sample); with `flush`, end the current
    /// chunk after them. Returns the chunks finished, packed and checked against the bound;
    /// store each and [`confirm`](Self::confirm) it, in order.
    pub fn push(&mut self, frames: &[f32], flush: bool) -> Result<Vec<StreamChunk>> {
        let w = self.width();
        if !frames.len().is_multiple_of(w) {
            return Err(Error::Invalid(format!(
                "{} values are not whole frames of {} points",
                frames.len(),
                self.points
            )));
        }
        let out = self.coder.push(frames, flush)?;
        self.pending.extend_from_slice(frames);
        out.into_iter().map(|c| self.finish_chunk(c)).collect()
    }

    /// Pack a codec chunk with the frames it codes, decode it alone and hold it to the bound.
    fn finish_chunk(&mut self, chunk: ChunkOut) -> Result<StreamChunk> {
        let w = self.width();
        let n = chunk.frames;
        if n == 0 || n * w > self.pending.len() {
            return Err(Error::Invalid(format!(
                "codec {} finished a chunk of {n} frames with {} pending",
                self.header.codec,
                self.pending.len() / w
            )));
        }
        let original: Vec<f32> = self.pending.drain(..n * w).collect();
        let (meta, payload) =
            pack_indexed(self.next_frame, &chunk, Some(&super::gaps::mask(&original)));
        // The chunk decodes on its own: check it with a header that holds only it.
        let alone = Header {
            frames: n as u32,
            chunks: vec![ChunkMeta {
                first_frame: 0,
                ..meta
            }],
            ..self.header.clone()
        };
        let decoded = read::decode_chunk(&alone, self.decoder.as_ref(), 0, &payload)?;
        let mut a = Accumulator::new(self.points);
        a.add(&original, &decoded);
        let max_mm = a.finish(self.mm_per_unit).max_mm;
        let index = self.handed_out;
        if max_mm > self.bound.tightest_mm() {
            return Err(Error::BoundMissed {
                codec: self.header.codec.to_string(),
                detail: format!(
                    "stream chunk {index} decodes {max_mm:.4} mm from its input, over {}",
                    self.bound
                ),
            });
        }
        self.handed_out += 1;
        self.next_frame += n;
        self.handed_stats.add(&original, &decoded);
        Ok(StreamChunk {
            meta,
            payload,
            decoded,
            running: self.handed_stats.clone(),
            index,
        })
    }

    /// The take's totals if `chunk` (the next to confirm) were part of it: what to store
    /// with it.
    pub fn totals_with(&self, chunk: &StreamChunk) -> Totals {
        Totals {
            frames: self.committed_frames() + chunk.meta.frames as usize,
            chunks: self.index.len() + 1,
            stored_bytes: self.stored_bytes(self.index.len() + 1)
                + self.payload_bytes
                + chunk.payload.len(),
            stats: chunk.running.finish(self.mm_per_unit),
        }
    }

    /// Chunks confirmed so far.
    pub fn chunks(&self) -> usize {
        self.index.len()
    }

    /// The take as confirmed so far.
    pub fn committed(&self) -> Totals {
        Totals {
            frames: self.committed_frames(),
            chunks: self.index.len(),
            stored_bytes: self.stored_bytes(self.index.len()) + self.payload_bytes,
            stats: self.stats.finish(self.mm_per_unit),
        }
    }

    /// Header and index bytes of a take of `chunks` chunks.
    fn stored_bytes(&self, chunks: usize) -> usize {
        self.header_len + chunks * ChunkMeta::INDEX_BYTES
    }

    fn committed_frames(&self) -> usize {
        self.index
            .last()
            .map_or(0, |c| c.first_frame as usize + c.frames as usize)
    }

    /// Make a stored chunk part of the take. Chunks are confirmed in the order handed out.
    pub fn confirm(&mut self, chunk: StreamChunk) -> Result<()> {
        if chunk.index != self.index.len() {
            return Err(Error::Invalid(format!(
                "stream chunk {} confirmed after {} chunks",
                chunk.index,
                self.index.len()
            )));
        }
        self.stats = chunk.running;
        pipeline::digest_update(&mut self.digest, &chunk.decoded);
        self.payload_bytes += chunk.payload.len();
        self.index.push(chunk.meta);
        Ok(())
    }

    /// [`pipeline::decoded_digest`] of the confirmed chunks' decoded frames.
    pub fn decoded_digest(&self) -> String {
        self.digest.finalize().to_hex().to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::lsdt::spatial::dct_basis;
    use crate::motion::synthetic::walker;

    fn spec(basis: &Arc<Basis>) -> StreamSpec<'_> {
        StreamSpec {
            points: 4,
            fps: 60.0,
            metres_per_unit: 0.001,
            bound: ErrorBound::max(1.0),
            chunk_frames: 30,
            shared: Some(basis),
        }
    }

    #[test]
    fn only_streaming_codecs_open_and_chunks_join_the_take_when_confirmed() {
        let basis = Arc::new(dct_basis(4));
        assert_eq!(
            streaming_codecs(),
            vec![CodecId::LsdtClip, CodecId::LsdtFrame]
        );
        assert!(matches!(
            StreamEncoder::open(CodecId::Quant, &spec(&basis)),
            Err(Error::Unsupported(_))
        ));
        let m = walker(100, 4, 60.0, 3, 0.05);
        let mut e = StreamEncoder::open(CodecId::LsdtFrame, &spec(&basis)).unwrap();
        assert!(
            e.push(&m.positions()[..5], false).is_err(),
            "not whole frames"
        );
        let chunks = e.push(m.positions(), false).unwrap();
        assert_eq!(chunks.len(), 3, "three whole chunks of 30 frames");
        assert_eq!(
            e.committed().frames,
            0,
            "nothing is part of the take until confirmed"
        );
        let mut chunks = chunks.into_iter();
        let first = chunks.next().unwrap();
        let second = chunks.next().unwrap();
        assert!(e.confirm(second).is_err(), "confirmed out of order");
        let t = e.totals_with(&first);
        e.confirm(first).unwrap();
        let c = e.committed();
        assert_eq!(
            (c.frames, c.chunks, c.stored_bytes),
            (t.frames, 1, t.stored_bytes)
        );
        assert!(c.stats.max_mm <= 1.0);
        let tail = e.push(&[], true).unwrap();
        assert_eq!(tail.len(), 1);
        assert_eq!(
            tail[0].meta.first_frame, 90,
            "frames are numbered as handed out"
        );
        assert_eq!(e.closed_header().chunks.len(), 1);
    }
}
