//! `spca` — Liu & McMillan, *Segment-based human motion compression*, SCA 2006.
//!
//! 1. Normalise ([`torso`]): each frame is moved and turned about the vertical axis so the
//!    three torso points sit alike in every frame; the torso points themselves are coded by
//!    key frames alone, at a tighter tolerance.
//! 2. Segment ([`crate::codec::segment`], PPCA after Barbič et al. 2004): a cut wherever the
//!    coming frames stop fitting a Gaussian model of the frames so far.
//! 3. Per segment ([`model`]): PCA keeping the fewest components that leave every point
//!    within the PCA tolerance (foot points within a third of it).
//! 4. Per component trajectory ([`spline`]): 4 evenly spaced key frames, midpoints inserted
//!    wherever the cubic through them strays past the threshold; key values quantised and
//!    range coded.
//! 5. Decode ([`coder`]): splines → coefficients → poses → world; over the last frames of a
//!    segment the next segment's model takes over by a smooth blend, as the paper does, so
//!    there is no jump at the cut.
//!
//! Each segment is a chunk. The models live in the header ([`params`]), so a chunk holds its
//! own keys plus the next model's keys over the blend, and decodes from its own bytes.
//!
//! Departures from the paper, and why:
//! - Every tolerance is a fixed share of one scale that rate control searches ([`encode`]):
//!   the paper's tolerances are in its data's millimetres, ours follow the user's bound.
//! - Under a max bound a residual layer ([`crate::codec::residual`]) corrects the samples
//!   the model leaves too far, so the bound holds on every sample (the paper bounds no
//!   sample).
//! - The cubic is a Hermite spline with mean-secant tangents (local: a frame depends on four
//!   keys); the paper says only "cubic spline".
//! - Segments longer than [`encode::MAX_SEGMENT`] frames are split, so no chunk is huge.
//! - Without torso points (found by name) the poses are coded as they are: no normalisation.

pub mod coder;
pub mod encode;
pub mod model;
pub mod params;
pub mod spline;
pub mod torso;

use self::coder::Coder;
use self::encode::{Options, Take};
use self::params::Params;
use super::entropy::Decoder;
use super::error::{malformed, Error, Result};
use super::{residual, ChunkDecoder, Codec, CodecId, CodecOutput, Input, Shared, Target};
use crate::limits::SPCA_MAX_POINTS;
use crate::motion::Motion;

pub struct Spca;

impl Codec for Spca {
    fn id(&self) -> CodecId {
        CodecId::Spca
    }

    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput> {
        encode_with(input, target, Options::SPCA)
    }

    fn decoder(
        &self,
        params: &[u8],
        points: usize,
        _shared: &Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        check_points(points)?;
        let params = Params::parse(params, points)?;
        Ok(Box::new(SpcaDecoder {
            coder: Coder::new(params, points),
        }))
    }

    fn unsuited(&self, motion: &Motion) -> Option<String> {
        check_points(motion.point_count())
            .err()
            .map(|e| e.to_string())
    }
}

/// Encode with some parts of the method left out (the paper's Table 3 comparison).
pub fn encode_with(input: &Input<'_>, target: Target, options: Options) -> Result<CodecOutput> {
    check_points(input.points)?;
    Take::new(input, options)?.encode(target)
}

/// Models are `3J × 3J` eigendecompositions (and as large in the header); past
/// [`SPCA_MAX_POINTS`] points the codec sits out.
fn check_points(points: usize) -> Result<()> {
    if points > SPCA_MAX_POINTS {
        return Err(Error::Invalid(format!(
            "spca codes takes of at most {SPCA_MAX_POINTS} points, this one has {points}"
        )));
    }
    Ok(())
}

struct SpcaDecoder {
    coder: Coder,
}

impl ChunkDecoder for SpcaDecoder {
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()> {
        let mut dec = Decoder::new(bytes);
        let keys = self.coder.code(&mut dec, frames, None)?;
        if dec.overran() {
            return Err(malformed("spca chunk ends early"));
        }
        self.coder.reconstruct(&keys, frames, out);
        let t = self.coder.params.residual_t;
        if t > 0.0 {
            residual::decode(&mut dec, out, self.coder.points, t);
        }
        if dec.overran() {
            return Err(malformed("spca chunk ends early"));
        }
        Ok(())
    }
}
