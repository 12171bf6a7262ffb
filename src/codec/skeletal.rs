//! What the codecs that keep a skeleton's channel values (`rot`, `pga`, `bvh-lossless`)
//! share: each needs the take's rig, sits out point-only takes, and decodes a chunk into
//! channel values whose forward kinematics are the positions it serves.

use std::sync::Arc;

use super::entropy::rangecoder::Decoder;
use super::error::{malformed, Error, Result};
use super::{Channels, ChunkDecoder, CodecId, Shared, Skeleton};
use crate::motion::Motion;

/// The rig a skeleton codec's reader was given; an error naming `codec` without one.
pub fn rig_of(shared: &Shared, codec: CodecId) -> Result<Arc<Skeleton>> {
    shared
        .rig
        .clone()
        .ok_or_else(|| Error::Basis(format!("{codec} decodes with the take's skeleton")))
}

/// Why a skeleton codec cannot code `motion`: it has no skeleton.
pub fn no_skeleton(motion: &Motion) -> Option<String> {
    motion
        .skeleton
        .is_none()
        .then(|| "the take has no skeleton (point data only)".into())
}

/// A skeleton codec's chunk decoder: it gives channel values.
/// What a lossy channel decoder read from a chunk: `values` (rounded as printed on the way
/// out, so none are kept here), or an error when the range decoder `dec` ran past the chunk's
/// end (a truncated chunk).
pub fn read_whole(dec: &Decoder<'_>, values: Vec<f64>, codec: CodecId) -> Result<Channels> {
    if dec.overran() {
        return Err(malformed(format!("{codec} chunk is truncated")));
    }
    Ok(Channels {
        values,
        printed: None,
    })
}

pub trait ChannelDecoder: Send + Sync {
    /// The rig the values drive.
    fn rig(&self) -> &Skeleton;
    /// `frames` frames of channel values from one chunk's bytes.
    fn channels(&self, bytes: &[u8], frames: usize) -> Result<Channels>;
}

/// A [`ChannelDecoder`] as a [`ChunkDecoder`]: positions are the channels' FK.
pub struct Posed<D>(pub D);

impl<D: ChannelDecoder> ChunkDecoder for Posed<D> {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        let ch = self.0.channels(bytes, frames)?;
        self.0.rig().positions(&ch.values, out);
        Ok(())
    }

    fn decode_channels(&self, bytes: &[u8], frames: usize) -> Result<Channels> {
        self.0.channels(bytes, frames)
    }
}
