//! Encode a take with one codec to a bound and prove it; decode any frame range.

use std::sync::Arc;

use super::basis::Basis;
use super::container::{pack_chunks, Container, Header};
use super::error::{Error, Result};
use super::id::ErrorBound;
use super::read::{Reader, Shared, Stored};
use super::skeleton::Skeleton;
use super::CodecId;
use super::{codec, gaps, Codec, CodecOutput, Hints, Input, Target};
use crate::motion::metrics::{self, ErrorSeries, ErrorStats};
use crate::motion::Motion;

/// A take encoded and checked: the container, the errors measured on its decoded output,
/// and its stored size.
#[derive(Debug, Clone)]
pub struct Encoded {
    pub container: Container,
    pub stats: ErrorStats,
    pub stored_bytes: usize,
    /// [`decoded_digest`] of the decoded take the statistics were measured on: a reader
    /// that decodes to the same digest later reads exactly what was measured.
    pub decoded_digest: String,
    /// The skeleton the header names (codecs that code channel values): with the basis,
    /// what a reader of this container needs.
    pub rig: Option<Arc<Skeleton>>,
    /// The error second by second, measured on the same decode as `stats`.
    pub series: ErrorSeries,
}

/// BLAKE3 (hex) of decoded frames as little-endian f32, gaps included: what `verify`
/// compares a later decode against.
pub fn decoded_digest(frames: &[f32]) -> String {
    let mut h = blake3::Hasher::new();
    digest_update(&mut h, frames);
    h.finalize().to_hex().to_string()
}

/// Add decoded frames to a running [`decoded_digest`] (takes decoded chunk by chunk).
pub fn digest_update(h: &mut blake3::Hasher, frames: &[f32]) {
    let mut buf = [0u8; 4096];
    for block in frames.chunks(buf.len() / 4) {
        for (b, v) in buf.chunks_exact_mut(4).zip(block) {
            b.copy_from_slice(&v.to_le_bytes());
        }
        h.update(&buf[..block.len() * 4]);
    }
}

/// A codec's encoder called in place of its own search ([`EncodeOptions::encoder`]).
pub type Encoder<'a> = Box<dyn FnOnce(&Input<'_>, Target) -> Result<CodecOutput> + 'a>;

/// What an [`encode`] may be given beyond the take, its codec and its bound; each part
/// optional, `EncodeOptions::default()` none.
#[derive(Default)]
pub struct EncodeOptions<'a> {
    /// The shared basis that codecs of [`Codec::basis_kind`] code with (ignored by the
    /// others). The header records its hash.
    pub basis: Option<&'a Arc<Basis>>,
    /// What the request said about the take's points.
    pub hints: Hints,
    /// The codec's encoder called through this instead of the codec's own: for benchmarks
    /// and tests of a codec's settings (a clip length, an intra period) that per-take
    /// choice does not search. The result is checked and decodes like any other.
    pub encoder: Option<Encoder<'a>>,
}

impl<'a> EncodeOptions<'a> {
    /// With a shared basis (if any), nothing else.
    pub fn with_basis(basis: Option<&'a Arc<Basis>>) -> Self {
        EncodeOptions {
            basis,
            ..EncodeOptions::default()
        }
    }

    /// With a shared basis (if any), and `encoder` called in place of the codec's own.
    pub fn with_encoder(
        basis: Option<&'a Arc<Basis>>,
        encoder: impl FnOnce(&Input<'_>, Target) -> Result<CodecOutput> + 'a,
    ) -> Self {
        EncodeOptions {
            basis,
            encoder: Some(Box::new(encoder)),
            ..EncodeOptions::default()
        }
    }
}

/// Encode `motion` with `codec_id` so that its decoded output meets `bound`: the one
/// entry point of encoding, whatever the codec and options.
///
/// The returned statistics come from decoding the container just built with the same code
/// a reader uses, so the bound is a measured fact, not a codec's claim.
pub fn encode(
    motion: &Motion,
    codec_id: CodecId,
    bound: ErrorBound,
    options: EncodeOptions<'_>,
) -> Result<Encoded> {
    let EncodeOptions {
        basis,
        hints,
        encoder,
    } = options;
    match encoder {
        Some(encoder) => encode_checked(motion, codec_id, bound, basis, &hints, encoder),
        None => {
            let c = codec(codec_id)?;
            encode_checked(motion, codec_id, bound, basis, &hints, |input, target| {
                c.encode(input, target)
            })
        }
    }
}

/// Encode through `encoder`, then decode the container as a reader will and check the bound.
fn encode_checked(
    motion: &Motion,
    codec_id: CodecId,
    bound: ErrorBound,
    shared: Option<&Arc<Basis>>,
    hints: &Hints,
    encoder: impl FnOnce(&Input<'_>, Target) -> Result<CodecOutput>,
) -> Result<Encoded> {
    let torso = hints.torso_points(&motion.point_names)?;
    let (frames, points) = (motion.frame_count(), motion.point_count());
    if frames == 0 || points == 0 {
        return Err(Error::Invalid(format!(
            "nothing to encode: {frames} frames of {points} points"
        )));
    }
    let c = codec(codec_id)?;
    let shared = usable_basis(c, shared, points)?;
    let rig = rig_for(c, motion)?;
    let positions = motion.positions();
    let valid = gaps::validity(positions);
    if valid.as_ref().is_some_and(|v| !v.iter().any(|x| *x)) {
        return Err(Error::Invalid("every sample of the take is missing".into()));
    }
    let filled = gaps::fill(positions, points);
    let to_mm = motion.unit.to_mm();
    let target = bound.target(to_mm);
    let input = Input {
        data: &filled,
        valid: valid.as_deref(),
        frames,
        points,
        fps: motion.fps,
        shared: shared.map(|b| b.as_ref()),
        skeleton: rig
            .as_ref()
            .zip(motion.skeleton.as_ref())
            .map(|(r, s)| (r.as_ref(), s)),
        names: &motion.point_names,
        torso,
    };
    let out = encoder(&input, target)?;

    let (metas, payloads, first) = pack_chunks(out.chunks, valid.as_deref(), points);
    if first != frames {
        return Err(Error::Invalid(format!(
            "codec {codec_id} produced chunks for {first} of {frames} frames"
        )));
    }
    let container = Container {
        header: Header {
            codec: codec_id,
            frames: frames as u32,
            points: points as u32,
            fps: motion.fps,
            metres_per_unit: motion.unit.metres_per_unit,
            params: out.params,
            basis: shared.map(|b| b.hash()),
            rig: rig.as_ref().map(|r| r.hash()),
            chunks: metas,
        },
        chunks: payloads,
    };
    let decoded = decode_all_with(
        &container,
        Shared {
            basis: shared.cloned(),
            rig: rig.clone(),
        },
    )?;
    let stats = metrics::compare(positions, &decoded, points, to_mm)
        .map_err(|e| Error::Fault(e.to_string()))?;
    if !bound.holds(stats.max_mm, stats.mean_mm) {
        return Err(Error::BoundMissed {
            codec: codec_id.to_string(),
            detail: format!(
                "asked {bound}, decoded max {:.4} mm, mean {:.4} mm",
                stats.max_mm, stats.mean_mm
            ),
        });
    }
    let stored_bytes = container.stored_bytes();
    let per_second = (motion.fps.round() as usize).max(1);
    let series = ErrorSeries::of(positions, &decoded, points, per_second, to_mm);
    Ok(Encoded {
        container,
        stats,
        stored_bytes,
        decoded_digest: decoded_digest(&decoded),
        rig,
        series,
    })
}

/// The point container of a take with no points (analog channels only): a `raw` container
/// of `frames` frames of no points, in chunks of [`super::default_chunk_frames`] frames, so
/// that the take reads like any other and its analog chunks have ranges to align with.
pub fn encode_no_points(frames: usize, fps: f64, metres_per_unit: f64) -> Result<Encoded> {
    if frames == 0 {
        return Err(Error::Invalid("nothing to encode: no frames".into()));
    }
    let per = super::default_chunk_frames(fps);
    let chunks = (0..frames)
        .step_by(per)
        .map(|f0| super::ChunkOut {
            frames: per.min(frames - f0),
            bytes: Vec::new(),
        })
        .collect();
    let (metas, payloads, _) = pack_chunks(chunks, None, 0);
    let container = Container {
        header: Header {
            codec: CodecId::Raw,
            frames: frames as u32,
            points: 0,
            fps,
            metres_per_unit,
            params: Vec::new(),
            basis: None,
            rig: None,
            chunks: metas,
        },
        chunks: payloads,
    };
    let decoded = decode_all_with(&container, Shared::default())?;
    Ok(Encoded {
        stored_bytes: container.stored_bytes(),
        container,
        stats: metrics::Accumulator::new(0).finish(1.0),
        decoded_digest: decoded_digest(&decoded),
        rig: None,
        series: ErrorSeries::of(&[], &[], 0, 1, 1.0),
    })
}

/// The basis codec `c` needs, checked against the take; `None` for codecs that use none.
pub(crate) fn usable_basis<'a>(
    c: &dyn Codec,
    shared: Option<&'a Arc<Basis>>,
    points: usize,
) -> Result<Option<&'a Arc<Basis>>> {
    let Some(kind) = c.basis_kind() else {
        return Ok(None);
    };
    let b = shared.ok_or_else(|| {
        Error::Basis(format!(
            "codec {} codes with a shared {kind} basis and none was given",
            c.id()
        ))
    })?;
    if b.kind() != kind {
        return Err(Error::Basis(format!(
            "codec {} needs a {kind} basis, {} is {}",
            c.id(),
            b.id(),
            b.kind()
        )));
    }
    if b.points() != points {
        return Err(Error::Basis(format!(
            "basis {} is for {} points, the take has {points}",
            b.id(),
            b.points()
        )));
    }
    Ok(Some(b))
}

/// The skeleton codec `c` codes with, if it codes channel values: the take must have one.
fn rig_for(c: &dyn Codec, motion: &Motion) -> Result<Option<Arc<Skeleton>>> {
    if !c.codes_channels() {
        return Ok(None);
    }
    let s = motion.skeleton.as_ref().ok_or_else(|| {
        Error::Invalid(format!(
            "codec {} codes a skeleton's channel values and this take is point data only",
            c.id()
        ))
    })?;
    Ok(Some(Arc::new(Skeleton::new(s.joints.clone())?)))
}

/// Decode every frame.
pub fn decode_all(container: &Container) -> Result<Vec<f32>> {
    decode_all_with(container, None)
}

/// Decode every frame of a take coded with what its header names (a basis, a rig).
pub fn decode_all_with(container: &Container, shared: impl Into<Shared>) -> Result<Vec<f32>> {
    let reader = Reader::new(container.header.clone(), shared)?;
    reader.read_all(&Stored::new(0, container.chunks.iter().map(Vec::as_slice)))
}
