//! Codecs: pure encoders and decoders over point matrices, the container they write, the
//! entropy stage they share, and rate control to a stated error bound. No I/O, no async,
//! no database: bytes and matrices in, bytes and matrices out.
//!
//! # Layout
//! - [`id`]: codec ids, latency classes, error bounds — the user's vocabulary.
//! - [`container`]: header + chunk index + per-chunk gap masks and checksums.
//! - [`entropy`]: adaptive binary range coder and integer models (and the zstd alternative).
//! - [`pipeline`]: encode a `Motion` with any codec to a bound and verify it.
//! - [`read`]: the one read path: any frame range of a take, from any source of chunks.
//! - [`stream`]: code a take frame by frame as it is recorded, with the codecs that can.
//! - [`raw`], [`quant`]: the baselines. [`mdtt`]: Hou et al. 2015 with a residual layer.
//! - [`lsdt`]: Hou et al. 2016's learned spatial transform, its training, `lsdt-clip` and
//!   `lsdt-frame`.
//! - [`bvh_lossless`]: a skeleton's channel values exactly as printed. [`rot`]: its
//!   rotations, error-bounded on the FK positions.
//! - [`pga`]: principal geodesics of rotations with IK (Tournier et al. 2009).
//! - [`branches`]: which equivalent Euler triple `rot` and `pga` give back (the source's).
//! - [`spca`]: segments, torso normalisation, PCA and key-framed splines (Liu & McMillan
//!   2006).
//! - [`features`]: a take's motion features (one descriptor per window) as stored.
//! - [`outputs`]: a C3D's model outputs (angles, forces, moments, powers), exactly.
//! - [`analog`]: analog channels (force plates, EMG) by linear prediction, lossless or
//!   bounded per channel.
//! - [`basis`]: shared bases — learned once per layout, content addressed, referenced.
//! - [`skeleton`]: skeletons — stored once, content addressed, named by the headers of the codecs
//!   that code channel values.
//! - [`dct`], [`residual`], [`gaps`], [`measure`], [`linalg`], [`rate`]: shared pieces of
//!   the above. [`segment`]: PPCA motion segmentation (Barbič et al. 2004), for `spca` and
//!   `mdtt`'s adaptive clips.

pub mod analog;
pub mod basis;
pub mod branches;
pub mod bvh_lossless;
pub mod container;
pub mod dct;
pub mod entropy;
pub mod error;
pub mod features;
pub mod gaps;
pub mod id;
pub mod linalg;
pub mod lsdt;
pub mod mdtt;
pub mod measure;
pub mod outputs;
pub mod pga;
pub mod pipeline;
pub mod quant;
pub mod rate;
pub mod raw;
pub mod read;
pub mod residual;
pub mod rot;
pub mod segment;
pub mod simd;
pub mod skeletal;
pub mod skeleton;
pub mod spca;
pub mod stream;
#[cfg(test)]
pub(crate) mod testing;
pub mod twists;
mod wire;

use crate::motion::{Animation, Motion};

pub use basis::{Basis, BasisKind};
pub use container::{Container, DecodeLimits, Header};
pub use error::{Error, Result};
pub use id::{ErrorBound, Latency};
pub use pipeline::{
    decode_all, decode_all_with, decoded_digest, digest_update, encode, EncodeOptions, Encoded,
    Encoder,
};
pub use read::{decode_chunk, decoder, ChunkSource, Reader, Shared, Stored};
pub use skeleton::{Channels, Skeleton};

/// What an encoder sees: gap-filled positions (`frames × points × 3`, the take's units) and
/// which samples are real, so that errors are judged on those only.
pub struct Input<'a> {
    pub data: &'a [f32],
    pub valid: Option<&'a [bool]>,
    pub frames: usize,
    pub points: usize,
    pub fps: f64,
    /// The shared basis to code with, for codecs that use one ([`Codec::basis_kind`]).
    pub shared: Option<&'a Basis>,
    /// The take's skeleton and channel values, for codecs that code them
    /// ([`Codec::codes_channels`]); its rig is the one the header names.
    pub skeleton: Option<(&'a Skeleton, &'a Animation)>,
    /// The points' names (empty when unknown): codecs that treat some points apart (`spca`'s
    /// torso and feet) find them by name.
    pub names: &'a [String],
    /// The torso points `[origin, left shoulder, right shoulder]` when the request named
    /// them ([`Hints`]); codecs that need them otherwise find them by name.
    pub torso: Option<[usize; 3]>,
}

/// What a request may say about a take's points that codecs cannot always find for
/// themselves. Parsed at the boundary; checked against the take by [`Hints::torso_points`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Hints {
    /// The torso points by name: origin (e.g. `C7`, `Hips`), left and right shoulder.
    pub torso: Option<[String; 3]>,
}

impl Hints {
    /// The torso as point indices of a take with these point names; `Invalid` naming a
    /// point the take does not have.
    pub fn torso_points(&self, names: &[String]) -> Result<Option<[usize; 3]>> {
        let Some(t) = &self.torso else {
            return Ok(None);
        };
        let mut out = [0; 3];
        for (o, name) in out.iter_mut().zip(t) {
            *o = names.iter().position(|n| n == name).ok_or_else(|| {
                Error::Invalid(format!("torso point {name:?} is not a point of the take"))
            })?;
        }
        if out[0] == out[1] || out[0] == out[2] || out[1] == out[2] {
            return Err(Error::Invalid(
                "the three torso points must be different points".into(),
            ));
        }
        Ok(Some(out))
    }
}

impl<'a> Input<'a> {
    pub fn width(&self) -> usize {
        self.points * 3
    }

    /// The take's rig and skeleton, for a codec that codes channel values; `Invalid`, naming
    /// `codec`, for a take of points only.
    pub fn skeleton_for(&self, codec: CodecId) -> Result<(&'a Skeleton, &'a Animation)> {
        self.skeleton
            .ok_or_else(|| Error::Invalid(format!("{codec} needs a skeleton take")))
    }
}

/// A bound in the take's own units (the pipeline converts from millimetres): every sample
/// within `max`, and the mean within `mean` when one is asked for.
///
/// Codecs meet both with one rule: the residual layer (or the step) holds the max, and the
/// search aims at the mean when there is one — a setting is kept only if it [`holds`]
/// both, so a mean bound never lets a sample past the max.
///
/// [`holds`]: Target::holds
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    pub max: f64,
    pub mean: Option<f64>,
}

impl Target {
    /// Every sample within `t`.
    pub const fn max(t: f64) -> Self {
        Target { max: t, mean: None }
    }

    pub fn holds(self, max: f64, mean: f64) -> bool {
        max <= self.max && self.mean.is_none_or(|m| mean <= m)
    }

    /// The tighter of the two bounds: the scale a codec's steps start from (a max bound
    /// at this is a mean bound too).
    pub fn tightest(self) -> f64 {
        self.mean.map_or(self.max, |m| m.min(self.max))
    }

    /// Both bounds times `f` (a share of the bound given to one stage of a codec).
    pub fn scaled(self, f: f64) -> Target {
        Target {
            max: self.max * f,
            mean: self.mean.map(|m| m * f),
        }
    }
}

impl std::fmt::Display for Target {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "max {:.6}", self.max)?;
        if let Some(m) = self.mean {
            write!(f, " and mean {m:.6}")?;
        }
        write!(f, " (take units)")
    }
}

/// An encoder's output: parameters and side data for the header, and consecutive chunks.
pub struct CodecOutput {
    pub params: Vec<u8>,
    pub chunks: Vec<ChunkOut>,
}

pub struct ChunkOut {
    pub frames: usize,
    pub bytes: Vec<u8>,
}

/// One codec. Implementations are stateless; per-take state lives in the header params.
pub trait Codec: Send + Sync {
    fn id(&self) -> CodecId;
    /// Encode to meet `target` with as few bytes as the codec can.
    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput>;
    /// Parse the header params once; the decoder then decodes any chunk. `shared` is the
    /// basis the header names (the pipeline checks its hash), for codecs that use one.
    fn decoder(
        &self,
        params: &[u8],
        points: usize,
        shared: &Shared,
    ) -> Result<Box<dyn ChunkDecoder>>;
    /// Every parameter version [`Codec::decoder`] reads: each is a promise that takes stored
    /// so decode forever, and `tests/frozen` holds a bitstream of each.
    fn versions(&self) -> &'static [u8];
    /// The version stored `params` are (their first byte, for most codecs).
    fn version_of(&self, params: &[u8]) -> Option<u8> {
        params.first().copied()
    }
    /// The kind of shared basis this codec codes with, if it uses one: it then competes only
    /// for takes whose layout has such a basis.
    fn basis_kind(&self) -> Option<BasisKind> {
        None
    }
    /// Whether it codes a skeleton's channel values (rotations kept: the take can be served
    /// as BVH) rather than point positions. Such a codec needs a skeleton take, names the
    /// take's [`Skeleton`] in its header, decodes with it, and implements
    /// [`ChunkDecoder::decode_channels`]; the bound still holds on the FK positions.
    fn codes_channels(&self) -> bool {
        false
    }
    /// Why this codec should not compete for this take, if it should not (per-take choice
    /// skips it and records the reason). Every codec can still be asked for by name.
    fn unsuited(&self, _motion: &Motion) -> Option<String> {
        None
    }
    /// How this codec codes a live stream, frame by frame, if it can ([`stream`]).
    fn streaming(&self) -> Option<&dyn stream::Streaming> {
        None
    }
}

/// Every codec that is implemented, in id order: what per-take choice considers.
pub fn available() -> Vec<CodecId> {
    CodecId::ALL
        .into_iter()
        .filter(|&c| codec(c).is_ok())
        .collect()
}

pub trait ChunkDecoder: Send + Sync {
    /// Decode one chunk of `frames` frames into `out` (`frames × points × 3`).
    fn decode_chunk(&self, bytes: &[u8], frames: usize, out: &mut [f32]) -> Result<()>;
    /// Decode frames `rows` of a chunk of `frames` frames into `out` (`rows.len()` frames),
    /// for a range read that wants part of a chunk and keeps none of it. Decoders that
    /// synthesise frames from chunk-wide coefficients override this to synthesise only the
    /// rows asked for; by default the whole chunk is decoded and the rows copied out.
    fn decode_rows(
        &self,
        bytes: &[u8],
        frames: usize,
        rows: std::ops::Range<usize>,
        out: &mut [f32],
    ) -> Result<()> {
        if rows == (0..frames) {
            return self.decode_chunk(bytes, frames, out);
        }
        let w = out.len() / rows.len().max(1);
        let mut all = vec![0f32; frames * w];
        self.decode_chunk(bytes, frames, &mut all)?;
        out.copy_from_slice(&all[rows.start * w..rows.end * w]);
        Ok(())
    }
    /// Decode one chunk's channel values, for codecs that code them
    /// ([`Codec::codes_channels`]).
    fn decode_channels(&self, _bytes: &[u8], _frames: usize) -> Result<Channels> {
        Err(Error::Unsupported(
            "this codec keeps positions, not channel values".into(),
        ))
    }
}

// The registry: every codec, one line each ([`id::registry`] makes `CodecId`, its names and
// latencies, and [`codec`], the implementation for an id, from it).
id::registry! {
    // variant = byte (written in bitstreams: never reuse one), name, latency => implementation
    points: {
        Raw = 1, "raw", Frame => raw::Raw;
        Quant = 2, "quant", Frame => quant::Quant;
        Mdtt = 3, "mdtt", Sequence => mdtt::Mdtt;
        LsdtClip = 4, "lsdt-clip", Clip => lsdt::clip::LsdtClip;
        LsdtFrame = 5, "lsdt-frame", Frame => lsdt::frame::LsdtFrame;
        Spca = 6, "spca", Sequence => spca::Spca;
        Pga = 7, "pga", Sequence => pga::Pga;
        /// MDTT's database mode: `K` spatial bases shared by a library.
        MdttShared = 8, "mdtt-shared", Sequence => mdtt::database::MdttShared;
        /// A skeleton's channel values exactly as the file printed them.
        BvhLossless = 9, "bvh-lossless", Frame => bvh_lossless::BvhLossless;
        /// A skeleton's rotations, error-bounded on the FK positions.
        Rot = 10, "rot", Frame => rot::Rot;
    }
    analog: {
        /// Analog channels, exactly as stored ([`analog`]).
        AnalogLossless = 11, "analog-lossless", Frame;
        /// Analog channels, each within its bound in its own unit.
        AnalogBounded = 12, "analog-bounded", Frame;
    }
}

/// The longest clip the clip codecs (`mdtt`, `mdtt-shared`, `lsdt-clip`) code. Their decoders
/// tabulate a clip-long DCT (up to 4096 × 4096 values), so a header may ask for no longer
/// clip: a hostile one once asked `lsdt-clip` for a 65,536² table (17 GB).
pub const MAX_CLIP: usize = 4096;

/// Frames per chunk for codecs free to choose: about one second, so a range request reads
/// at most a second more than it needs.
pub fn default_chunk_frames(fps: f64) -> usize {
    (fps.round() as usize).clamp(16, 1024)
}
