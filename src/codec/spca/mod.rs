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
//! - Without torso points (named in the request, else found by name) the poses are coded as
//!   they are: no normalisation.

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

    fn versions(&self) -> &'static [u8] {
        &[params::VERSION]
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::testing::{encoded, meets_bounds_and_shrinks};
    use crate::codec::{gaps, ErrorBound};
    use crate::motion::metrics::{accelerations, speeds};
    use crate::motion::synthetic::{dancer, two_behaviours, walker};

    #[test]
    fn meets_bounds_and_shrinks_with_and_without_a_torso() {
        meets_bounds_and_shrinks(&dancer(480, 120.0, 5), CodecId::Spca, [0.5, 2.0, 8.0]);
        // Points with no names to find a torso by: coded as they are.
        let w = walker(400, 9, 100.0, 4, 0.2);
        for bound in [ErrorBound::max(1.0), ErrorBound::mean(1.0)] {
            let enc = encoded(&w, CodecId::Spca, bound);
            let (max, mean) = crate::codec::testing::measured(&w, &enc);
            assert!(bound.holds(max, mean), "{bound}: max {max}, mean {mean}");
        }
    }

    #[test]
    fn a_change_of_behaviour_starts_a_new_segment_and_the_hand_over_is_smooth() {
        let m = two_behaviours();
        let filled = gaps::fill(m.positions(), m.point_count());
        let input = Input {
            data: &filled,
            valid: None,
            frames: m.frame_count(),
            points: m.point_count(),
            fps: m.fps,
            shared: None,
            skeleton: None,
            names: &m.point_names,
            torso: None,
        };
        let take = Take::new(&input, Options::SPCA).unwrap();
        let starts: Vec<usize> = take.segments().iter().skip(1).map(|r| r.start).collect();
        assert!(
            starts.iter().any(|&s| s.abs_diff(400) <= 60),
            "segments start at {starts:?}"
        );
        // Without the residual layer (a mean bound) the models alone make the frames. At
        // every cut the decoded motion moves no faster and turns no harder than the
        // original does anywhere.
        let enc = encoded(&m, CodecId::Spca, ErrorBound::mean(10.0));
        let cuts: Vec<usize> = enc.container.header.chunks[1..]
            .iter()
            .map(|c| c.first_frame as usize)
            .collect();
        assert!(!cuts.is_empty());
        let decoded = crate::codec::decode_all(&enc.container).unwrap();
        let n = m.point_count();
        let (v, a) = (speeds(m.positions(), n), accelerations(m.positions(), n));
        let (vmax, amax) = (max(&v), max(&a));
        let (dv, da) = (speeds(&decoded, n), accelerations(&decoded, n));
        for &b in &cuts {
            assert!(dv[b - 1] <= vmax, "speed {} at {b} > {vmax}", dv[b - 1]);
            for (f, a) in da.iter().enumerate().take(b + 1).skip(b.saturating_sub(2)) {
                assert!(*a <= amax, "acceleration {a} at {f} > {amax}");
            }
        }
    }

    fn max(v: &[f64]) -> f64 {
        v.iter().copied().fold(0.0, f64::max)
    }

    #[test]
    fn a_torso_named_in_the_request_normalises_a_take_with_unknown_names() {
        let w = walker(300, 6, 100.0, 8, 0.1);
        let bound = ErrorBound::max(2.0);
        let plain = encoded(&w, CodecId::Spca, bound);
        assert_eq!(
            plain.container.header.params[1], 3,
            "no torso found by name"
        );
        let names = &w.point_names;
        let hints = crate::codec::Hints {
            torso: Some([names[0].clone(), names[2].clone(), names[4].clone()]),
        };
        let enc = crate::codec::encode(
            &w,
            CodecId::Spca,
            bound,
            crate::codec::EncodeOptions {
                basis: None,
                hints: hints.clone(),
                ..Default::default()
            },
        )
        .unwrap();
        let p = Params::parse(&enc.container.header.params, w.point_count()).unwrap();
        assert_eq!(p.torso.map(|(_, t)| t), Some([0, 2, 4]));
        let (max, _) = crate::codec::testing::measured(&w, &enc);
        assert!(max <= 2.0, "{max}");
        let bad = crate::codec::Hints {
            torso: Some(["nope".into(), names[2].clone(), names[4].clone()]),
        };
        let err = crate::codec::encode(
            &w,
            CodecId::Spca,
            bound,
            crate::codec::EncodeOptions {
                basis: None,
                hints: bad.clone(),
                ..Default::default()
            },
        );
        assert!(matches!(err, Err(Error::Invalid(e)) if e.contains("nope")));
    }

    #[test]
    fn damaged_chunks_and_headers_give_errors_not_panics() {
        let m = two_behaviours();
        let enc = encoded(&m, CodecId::Spca, ErrorBound::max(1.0));
        let params = &enc.container.header.params;
        for i in 0..params.len() {
            let mut p = params.clone();
            p[i] ^= 0x5a;
            if let Ok(d) = Spca.decoder(&p, m.point_count(), &Shared::default()) {
                let (frames, bytes) = crate::codec::testing::first_chunk(&enc, &m);
                let mut out = vec![0f32; frames * m.point_count() * 3];
                let _ = d.decode_chunk(&bytes, frames, &mut out);
            }
        }
        for cut in [0, 1, 5, params.len() / 2] {
            assert!(Spca
                .decoder(&params[..cut], m.point_count(), &Shared::default())
                .is_err());
        }
        let d = Spca
            .decoder(params, m.point_count(), &Shared::default())
            .unwrap();
        let (frames, bytes) = crate::codec::testing::first_chunk(&enc, &m);
        let mut out = vec![0f32; frames * m.point_count() * 3];
        for i in 0..bytes.len().min(300) {
            let mut b = bytes.clone();
            b[i] ^= 0x5a;
            let _ = d.decode_chunk(&b, frames, &mut out);
        }
        for cut in [0, 1, bytes.len() / 2] {
            let _ = d.decode_chunk(&bytes[..cut], frames, &mut out);
        }
        assert!(Spca
            .decoder(params, SPCA_MAX_POINTS + 1, &Shared::default())
            .is_err());
    }
}
