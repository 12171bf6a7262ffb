//! What the codecs that keep a skeleton's channel values (`rot`, `pga`, `bvh-lossless`)
//! share: each needs the take's rig, sits out point-only takes, and decodes a chunk into
//! channel values whose forward kinematics are the positions it serves.

use std::sync::Arc;

use super::error::{Error, Result};
use super::{Channels, ChunkDecoder, CodecId, Rig, Shared};
use crate::motion::Motion;

/// The rig a skeleton codec's reader was given; an error naming `codec` without one.
pub fn rig_of(shared: &Shared, codec: CodecId) -> Result<Arc<Rig>> {
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
pub trait ChannelDecoder: Send + Sync {
    /// The rig the values drive.
    fn rig(&self) -> &Rig;
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
