//! `pga`: principal geodesic analysis of joint rotations with IK reconstruction (Tournier,
//! Wu, Courty, Arnaud, Reveret: *Motion Compression using Principal Geodesics Analysis*,
//! CGF 28(2), 2009).
//!
//! A take's inner-joint rotations are points of SO(3)ⁿ; the header stores their intrinsic
//! mean and the `k` leading principal geodesics ([`model`]), or only the mean when each
//! joint's own axes code the take smaller (measured: they usually do under a max bound,
//! since a principal direction spreads one coordinate's error over every joint it moves). Each chunk codes, through the
//! paper's multiscale lifting ([`lifting`], [`chunk`]), the root's position and
//! orientation, the pose's `k` geodesic coordinates and — when the take is decoded with IK —
//! the end points (End Sites and leaf joints) in the root's frame. The decoder poses each
//! frame from its coordinates, moved by Levenberg–Marquardt ([`ik`]) to reach the end points
//! while held near the coordinates (the paper holds them near the previous frame's instead
//! and sends no coordinates; measured on CMU, that drifts by 20–65 mm on average and up to
//! half a metre, which no bound a user asks for allows).
//!
//! Rate control ([`encode`]): `k` is the fewest directions whose truncation leaves room in
//! the bound; each chunk is then coded at the largest step ([`scale`]) at which the
//! decoder's own output ([`coder`], the one chunk coding both sides run) meets the bound on
//! the FK positions of every joint and End Site. Both models are tried without IK; the
//! smaller is tried again with IK, and the smaller of those kept. [`layout`] maps a skeleton's channels to root, inner joints and end
//! points; [`params`] is the header.
//! Channel values come back as Euler angles in each joint's own channel order, rounded as
//! a BVH file prints them, so the take is served as BVH like any codec that keeps rotations.

pub mod chunk;
pub mod coder;
pub mod encode;
pub mod frames;
pub mod ik;
pub mod layout;
pub mod lifting;
pub mod model;
pub mod params;
pub mod scale;

use std::sync::Arc;

use self::coder::Coder;
use self::encode::{Directions, Options, Take};
use self::layout::Layout;
use self::params::Params;
use super::entropy::rangecoder::Decoder;
use super::error::Result;
use super::skeletal::{no_skeleton, read_whole, rig_of, ChannelDecoder, Posed};
use super::skeleton::{Channels, Skeleton};
use super::{ChunkDecoder, Codec, CodecId, CodecOutput, Input, Shared, Target};
use crate::motion::Motion;

pub struct Pga;

impl Codec for Pga {
    fn id(&self) -> CodecId {
        CodecId::Pga
    }

    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput> {
        let (rig, skeleton) = input.skeleton_for(CodecId::Pga)?;
        Take::new(rig, skeleton, input)?.encode(
            target,
            &[Directions::Principal, Directions::Canonical],
            &[Options::PLAIN, Options::IK],
        )
    }

    fn versions(&self) -> &'static [u8] {
        &params::VERSIONS
    }

    fn decoder(
        &self,
        params: &[u8],
        _points: usize,
        shared: &Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        let rig = rig_of(shared, CodecId::Pga)?;
        let (params, layout) = Params::parse(params, &rig)?;
        Ok(Box::new(Posed(PgaDecoder {
            rig,
            coder: Coder::new(&layout, params),
        })))
    }

    fn codes_channels(&self) -> bool {
        true
    }

    fn unsuited(&self, motion: &Motion) -> Option<String> {
        let Some(sk) = &motion.skeleton else {
            return no_skeleton(motion);
        };
        let rig = match Skeleton::new(sk.joints.clone()) {
            Ok(r) => r,
            Err(e) => return Some(e.to_string()),
        };
        Layout::new(&rig, &sk.values, sk.frame_count()).err()
    }
}

struct PgaDecoder {
    rig: Arc<Skeleton>,
    coder: Coder,
}

impl ChannelDecoder for PgaDecoder {
    fn rig(&self) -> &Skeleton {
        &self.rig
    }

    fn channels(&self, bytes: &[u8], frames: usize) -> Result<Channels> {
        let mut dec = Decoder::new(bytes);
        let values = self.coder.code(&mut dec, 0, false, frames, None)?;
        read_whole(&dec, values, CodecId::Pga)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::testing::{
        damage_channels, encoded, first_chunk, measured, meets_bounds_and_shrinks, skeleton_shared,
    };
    use crate::codec::Error;
    use crate::codec::{encode, EncodeOptions, ErrorBound};
    use crate::motion::synthetic::dancer;

    #[test]
    fn decoded_euler_triples_are_the_sources() {
        crate::codec::testing::follows_the_sources_euler_branches(CodecId::Pga);
    }

    #[test]
    fn decoded_euler_triples_near_gimbal_lock_are_the_sources() {
        crate::codec::testing::keeps_the_sources_angles_near_gimbal_lock(CodecId::Pga);
    }

    #[test]
    fn meets_max_and_mean_bounds_on_fk_positions_and_shrinks_as_they_loosen() {
        meets_bounds_and_shrinks(&dancer(600, 120.0, 7), CodecId::Pga, [0.5, 2.0, 10.0]);
    }

    /// `m` coded by pga to `max_mm` with `options` only (settings its search does not try).
    fn coded_with(m: &Motion, max_mm: f64, options: Options) -> crate::codec::Encoded {
        let encoder = move |input: &Input<'_>, t| {
            let (rig, sk) = input.skeleton.unwrap();
            Take::new(rig, sk, input)?.encode(t, &[Directions::Principal], &[options])
        };
        let options = EncodeOptions::with_encoder(None, encoder);
        encode(m, CodecId::Pga, ErrorBound::max(max_mm), options).unwrap()
    }

    /// At a loose bound the paper's decoder (end points sent, coarser coordinates, IK) codes
    /// smaller than coordinates alone: the reason `auto` tries it ([`Options::IK`]).
    #[test]
    fn ik_codes_smaller_than_coordinates_alone_at_a_loose_bound() {
        let m = dancer(600, 120.0, 7);
        let size = |options: Options| {
            let enc = coded_with(&m, 12.5, options);
            let (max, _) = measured(&m, &enc);
            assert!(max <= 12.5, "{max}");
            enc.stored_bytes
        };
        let (ik, plain) = (size(Options::IK), size(Options::PLAIN));
        assert!(ik < plain, "IK {ik} bytes, coordinates alone {plain}");
    }

    /// The paper's decoder: poses by IK from the decoded end points, held near the decoded
    /// coordinates. The bound holds on what it gives.
    #[test]
    fn takes_decoded_by_ik_meet_the_bound() {
        let m = dancer(300, 60.0, 3);
        let options = Options {
            iterations: 3,
            ..Options::IK
        };
        let enc = coded_with(&m, 5.0, options);
        let (max, _) = measured(&m, &enc);
        assert!(max <= 5.0, "{max}");
        let params = &enc.container.header.params;
        assert_eq!(params[1], 3, "IK steps stored");
        // Channels and positions agree: the positions served are the BVH's FK.
        let shared = skeleton_shared(&m);
        let rig = shared.rig.clone().unwrap();
        let d = Pga.decoder(params, m.point_count(), &shared).unwrap();
        let (frames, bytes) = first_chunk(&enc, &m);
        let ch = d.decode_channels(&bytes, frames).unwrap();
        let mut fk = vec![0f32; frames * m.point_count() * 3];
        rig.positions(&ch.values, &mut fk);
        let mut pos = vec![0f32; fk.len()];
        d.decode_chunk(&bytes, frames, &mut pos).unwrap();
        assert_eq!(fk, pos);
        assert!(ch
            .values
            .iter()
            .all(|v| *v == crate::codec::skeleton::printed(*v)));
    }

    /// Where no model and step meet the bound, `pga` says so with the typed error that
    /// per-take choice records and skips: here a bone whose length wavers by a millionth,
    /// which `pga` holds rigid, against a bound finer than that.
    #[test]
    fn a_bound_pga_cannot_meet_is_reported_missed() {
        let m = with_position_channel(dancer(60, 60.0, 2), |f| 10.0 + 5e-6 * (f % 2) as f64);
        assert!(Pga.unsuited(&m).is_none());
        match encode(
            &m,
            CodecId::Pga,
            ErrorBound::max(1e-6),
            crate::codec::EncodeOptions::default(),
        ) {
            Err(Error::BoundMissed { codec, detail }) => {
                assert_eq!(codec, "pga");
                assert!(detail.contains("finest step"), "{detail}");
            }
            other => panic!("{:?}", other.map(|e| e.stats.max_mm)),
        }
        assert!(encode(
            &m,
            CodecId::Pga,
            ErrorBound::max(1.0),
            crate::codec::EncodeOptions::default()
        )
        .is_ok());
    }

    /// `m` with an X position channel on joint 1 holding `value(frame)`, its positions by FK.
    fn with_position_channel(m: Motion, value: impl Fn(usize) -> f64) -> Motion {
        let frames = m.frame_count();
        let mut sk = m.skeleton.clone().unwrap();
        sk.joints[1]
            .channels
            .insert(0, crate::motion::skeleton::Channel::Xposition);
        let cc: usize = sk.joints.iter().map(|j| j.channels.len()).sum();
        let first = sk.joints[0].channels.len();
        let old = std::mem::take(&mut sk.values);
        for f in 0..frames {
            let row = &old[f * (cc - 1)..(f + 1) * (cc - 1)];
            sk.values.extend_from_slice(&row[..first]);
            sk.values.push(value(f));
            sk.values.extend_from_slice(&row[first..]);
        }
        let rig = Skeleton::new(sk.joints.clone()).unwrap();
        let mut positions = vec![0f32; m.positions().len()];
        rig.positions(&sk.values, &mut positions);
        Motion::new(m.fps, m.unit, m.point_names.clone(), positions, Some(sk)).unwrap()
    }

    #[test]
    fn point_takes_and_stretching_bones_are_unsuited_with_the_reason() {
        let points = crate::motion::synthetic::walker(50, 4, 60.0, 1, 0.0);
        assert!(Pga.unsuited(&points).unwrap().contains("no skeleton"));
        assert!(Pga.unsuited(&dancer(50, 60.0, 1)).is_none());
        let m = with_position_channel(dancer(20, 60.0, 2), |f| f as f64);
        let why = Pga.unsuited(&m).unwrap();
        assert!(why.contains("moves"), "{why}");
    }

    #[test]
    fn damaged_parameters_and_chunks_fail_cleanly() {
        let m = dancer(200, 60.0, 3);
        let enc = encoded(&m, CodecId::Pga, ErrorBound::max(2.0));
        let shared = skeleton_shared(&m);
        let params = &enc.container.header.params;
        let d = Pga.decoder(params, m.point_count(), &shared).unwrap();
        assert!(Pga
            .decoder(params, m.point_count(), &Shared::default())
            .is_err());
        for cut in 0..params.len() {
            assert!(
                Pga.decoder(&params[..cut], 1, &shared).is_err(),
                "cut {cut}"
            );
        }
        for (at, value) in [(0, 9), (1, 200), (2, 40)] {
            let mut p = params.clone();
            p[at] = value;
            assert!(Pga.decoder(&p, 1, &shared).is_err(), "byte {at} = {value}");
        }
        for i in 0..params.len() {
            let mut p = params.clone();
            p[i] ^= 0x5a;
            if let Ok(d) = Pga.decoder(&p, 1, &shared) {
                let _ = d.decode_channels(&[0, 1, 2, 3], 10);
            }
        }
        let (frames, bytes) = first_chunk(&enc, &m);
        damage_channels(d.as_ref(), &bytes, frames);
    }
}
