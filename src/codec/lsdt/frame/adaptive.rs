//! The adaptive entropy stage of `lsdt-frame` (parameters version 1): every coefficient as
//! binary decisions of the adaptive range coder, models reset at each intra frame. Nothing
//! needs to be known in advance, so a live stream codes each frame as it arrives.

use std::sync::Arc;

use super::{check_chunk, FrameParams, Loop, Quantiser};
use crate::codec::basis::Basis;
use crate::codec::entropy::{self, magnitude_context, Encoder, IntModel};
use crate::codec::error::{malformed, Result};
use crate::codec::lsdt::spatial::Spatial;
use crate::codec::{ChunkDecoder, ChunkOut};

/// Coefficient context: intra or predicted, the basis row on a log scale (learned rows are
/// ordered by energy, DCT-started ones too), and the size of the same coefficient in the
/// previous frame (motion is coherent).
fn context(intra: bool, r: usize, prev: i32) -> usize {
    let lg = ((usize::BITS - r.leading_zeros()) as usize).min(5);
    (usize::from(intra) * 6 + lg) * 3 + magnitude_context(prev, 3)
}
const CONTEXTS: usize = 36;

/// The coefficient models and the previous frame's coefficients, within one chunk.
struct Coefs {
    models: Vec<IntModel>,
    prev_q: Vec<i32>,
    j: usize,
}

impl Coefs {
    fn new(points: usize) -> Coefs {
        Coefs {
            models: vec![IntModel::default(); CONTEXTS],
            prev_q: vec![0; points * 3],
            j: points,
        }
    }

    /// A chunk starts afresh at its intra frame.
    fn start(&mut self, intra: bool) {
        if intra {
            self.models.fill(IntModel::default());
            self.prev_q.fill(0);
        }
    }

    fn encode(&mut self, enc: &mut Encoder, intra: bool, q: &[i32]) {
        self.start(intra);
        // Rows by coordinate, so the row index needs no division per coefficient.
        for d in 0..3 {
            for r in 0..self.j {
                let i = d * self.j + r;
                self.models[context(intra, r, self.prev_q[i])].encode(enc, q[i]);
            }
        }
        self.prev_q.copy_from_slice(q);
    }

    fn decode(&mut self, dec: &mut entropy::Decoder<'_>, intra: bool) -> &[i32] {
        self.start(intra);
        for d in 0..3 {
            for r in 0..self.j {
                let i = d * self.j + r;
                self.prev_q[i] = self.models[context(intra, r, self.prev_q[i])].decode(dec);
            }
        }
        &self.prev_q
    }
}

/// Codes frames one at a time; each chunk is handed out when its last frame is in.
pub struct FrameEncoder {
    quantiser: Quantiser,
    coefs: Coefs,
    enc: Encoder,
    chunk_frames: usize,
}

impl FrameEncoder {
    pub fn new(p: FrameParams, basis: &Basis) -> Result<FrameEncoder> {
        let spatial = Arc::new(Spatial::new(basis)?);
        let points = spatial.points();
        Ok(FrameEncoder {
            quantiser: Quantiser::new(p, spatial),
            coefs: Coefs::new(points),
            enc: Encoder::new(),
            chunk_frames: 0,
        })
    }

    /// Code one frame (`points × 3`; NaN or `valid[p] == false` marks a missing sample,
    /// which is coded as its prediction). Returns the reconstruction a decoder will produce,
    /// and the chunk if this frame completed one.
    pub fn push(&mut self, frame: &[f32], valid: Option<&[bool]>) -> (&[f32], Option<ChunkOut>) {
        let intra = self.quantiser.quantise(frame, valid);
        self.coefs.encode(&mut self.enc, intra, &self.quantiser.q);
        if let Some(r) = &mut self.quantiser.state.residual {
            r.code(&mut self.enc);
        }
        self.quantiser.advance();
        self.chunk_frames += 1;
        let chunk = self.quantiser.state.intra().then(|| self.take_chunk());
        (&self.quantiser.recon, chunk)
    }

    /// The last, partial chunk, if frames are pending.
    pub fn finish(mut self) -> Option<ChunkOut> {
        self.flush()
    }

    /// End the current chunk early (if frames are pending): the next frame starts a new
    /// chunk with an intra frame. Live streams flush to make frames fetchable sooner.
    pub fn flush(&mut self) -> Option<ChunkOut> {
        (self.chunk_frames > 0).then(|| self.take_chunk())
    }

    /// Frames pushed since the last chunk was handed out.
    pub fn pending(&self) -> usize {
        self.chunk_frames
    }

    fn take_chunk(&mut self) -> ChunkOut {
        let enc = std::mem::take(&mut self.enc);
        let frames = std::mem::take(&mut self.chunk_frames);
        self.quantiser.reset();
        ChunkOut {
            frames,
            bytes: enc.finish(),
        }
    }
}

pub(super) struct Decoder {
    p: FrameParams,
    spatial: Spatial,
}

impl Decoder {
    pub(super) fn new(p: FrameParams, spatial: Spatial) -> Decoder {
        Decoder { p, spatial }
    }
}

impl ChunkDecoder for Decoder {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        check_chunk(&self.p, frames)?;
        let points = self.spatial.points();
        let w = points * 3;
        let step = self.p.step as f32;
        let mut st = Loop::new(self.p, points);
        let mut coefs = Coefs::new(points);
        let mut dec = entropy::Decoder::new(bytes);
        let mut scratch = self.spatial.scratch();
        for frame in out.chunks_exact_mut(w).take(frames) {
            let intra = st.intra();
            st.predict(frame);
            let q = coefs.decode(&mut dec, intra);
            self.spatial.inverse_add(q, step, &mut scratch, frame);
            if let Some(r) = &mut st.residual {
                r.decode_frame(&mut dec, frame);
            }
            st.advance(frame);
        }
        if dec.overran() {
            return Err(malformed("lsdt-frame chunk ends early"));
        }
        Ok(())
    }
}
