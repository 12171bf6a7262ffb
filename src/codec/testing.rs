//! Checks that codecs share in their unit tests.

use std::sync::Arc;

use super::pipeline::Encoded;
use super::{encode, ChunkDecoder, CodecId, ErrorBound, Rig, Shared};
use crate::motion::Motion;

/// What a reader of a skeleton take `m` needs: its rig.
pub fn skeleton_shared(m: &Motion) -> Shared {
    Shared {
        basis: None,
        rig: Some(Arc::new(
            Rig::new(m.skeleton.clone().unwrap().joints).unwrap(),
        )),
    }
}

/// The first chunk of `enc` (a take of `m`): its frames and codec bytes.
pub fn first_chunk(enc: &Encoded, m: &Motion) -> (usize, Vec<u8>) {
    let frames = enc.container.header.chunks[0].frames as usize;
    let (_, bytes) =
        super::container::unpack_chunk(&enc.container.chunks[0], frames * m.point_count()).unwrap();
    (frames, bytes.to_vec())
}

/// Decode `bytes` with a byte flipped (each of the first 300 in turn) and cut short: each
/// gives channels or an error, never a panic.
pub fn damage_channels(d: &dyn ChunkDecoder, bytes: &[u8], frames: usize) {
    for i in 0..bytes.len().min(300) {
        let mut b = bytes.to_vec();
        b[i] ^= 0x5a;
        let _ = d.decode_channels(&b, frames);
    }
    for cut in [0, 1, bytes.len() / 2] {
        let _ = d.decode_channels(&bytes[..cut], frames);
    }
}

/// `codec` meets each max bound of `bounds` (mm) on `m`'s FK positions, close under it
/// rather than far below, with fewer bytes as bounds loosen; and a mean bound of 2 mm.
pub fn meets_bounds_and_shrinks(m: &Motion, codec: CodecId, bounds: [f64; 3]) {
    let mut last = usize::MAX;
    for mm in bounds {
        let enc = encode(m, codec, ErrorBound::max(mm)).unwrap();
        assert!(enc.stats.max_mm <= mm, "{} > {mm}", enc.stats.max_mm);
        // The search lands close under the bound, not far below it.
        assert!(enc.stats.max_mm > 0.5 * mm, "{} ≪ {mm}", enc.stats.max_mm);
        assert!(enc.stored_bytes < last);
        last = enc.stored_bytes;
    }
    let enc = encode(m, codec, ErrorBound::mean(2.0)).unwrap();
    assert!(enc.stats.mean_mm <= 2.0);
}
