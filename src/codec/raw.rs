//! `raw`: lossless. Each chunk is its f32 samples rearranged so zstd sees redundancy — one
//! trajectory after another, each as differences of consecutive bit patterns, split into
//! byte planes — then zstd. The baseline every ratio is compared with ("how much does a
//! plain lossless archive save").

use super::error::{malformed, Result};
use super::{
    default_chunk_frames, ChunkDecoder, ChunkOut, Codec, CodecId, CodecOutput, Input, Target,
};

const ZSTD_LEVEL: i32 = 9;

pub struct Raw;

impl Codec for Raw {
    fn id(&self) -> CodecId {
        CodecId::Raw
    }

    fn encode(&self, input: &Input<'_>, _target: Target) -> Result<CodecOutput> {
        let w = input.width();
        let per = default_chunk_frames(input.fps);
        let chunks = (0..input.frames)
            .step_by(per)
            .map(|f0| {
                let n = per.min(input.frames - f0);
                ChunkOut {
                    frames: n,
                    bytes: pack(&input.data[f0 * w..(f0 + n) * w], n, w),
                }
            })
            .collect();
        Ok(CodecOutput {
            params: Vec::new(),
            chunks,
        })
    }

    /// One layout, which has no parameters.
    fn versions(&self) -> &'static [u8] {
        &[1]
    }

    fn version_of(&self, params: &[u8]) -> Option<u8> {
        params.is_empty().then_some(1)
    }

    fn decoder(
        &self,
        params: &[u8],
        _points: usize,
        _shared: &super::Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        if !params.is_empty() {
            return Err(malformed("raw takes no parameters"));
        }
        Ok(Box::new(RawDecoder))
    }
}

fn pack(data: &[f32], frames: usize, w: usize) -> Vec<u8> {
    let n = data.len();
    let mut planes = vec![0u8; n * 4];
    for c in 0..w {
        let mut prev = 0u32;
        for f in 0..frames {
            let bits = data[f * w + c].to_bits();
            let d = bits.wrapping_sub(prev);
            prev = bits;
            let i = c * frames + f;
            for (b, byte) in d.to_le_bytes().into_iter().enumerate() {
                planes[b * n + i] = byte;
            }
        }
    }
    zstd::bulk::compress(&planes, ZSTD_LEVEL).expect("in-memory zstd compression does not fail")
}

struct RawDecoder;

impl ChunkDecoder for RawDecoder {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        let n = out.len();
        // A take of no points (analog channels only) has empty chunks.
        if n == 0 {
            return if bytes.is_empty() {
                Ok(())
            } else {
                Err(malformed("raw chunk of no points holds bytes"))
            };
        }
        let w = n / frames.max(1);
        let planes = zstd::bulk::decompress(bytes, n * 4)
            .map_err(|e| malformed(format!("raw chunk: {e}")))?;
        if planes.len() != n * 4 {
            return Err(malformed("raw chunk has the wrong size"));
        }
        for c in 0..w {
            let mut prev = 0u32;
            for f in 0..frames {
                let i = c * frames + f;
                let d = u32::from_le_bytes([
                    planes[i],
                    planes[n + i],
                    planes[2 * n + i],
                    planes[3 * n + i],
                ]);
                prev = prev.wrapping_add(d);
                out[f * w + c] = f32::from_bits(prev);
            }
        }
        Ok(())
    }
}
