//! `rot`: error-bounded coding of a skeleton's rotations, the bound measured where users see
//! it — on the positions FK gives for every joint and End Site.
//!
//! A joint with three rotation channels about three axes is coded as a unit quaternion: each
//! frame is predicted from the two before it at constant angular velocity (from the decoded
//! frames: closed loop, so quantisation errors never accumulate), and the residual rotation
//! is sent as a rotation vector quantised per component. Every other channel (the root's
//! translation, position channels, odd rotation channel sets) is predicted linearly and
//! quantised as a scalar. The encoder codes each joint's rotation *aimed* from its decoded
//! parent ([`aim`]: the spatial closed loop, so errors do not add up along a chain either),
//! and so a joint's step is the take's one parameter `α` divided by its longest bone
//! (version 1, which did not aim, divided by the reach below the joint); translations step
//! by `α` itself.
//! Rate control searches `α` for the largest that keeps the decoded FK positions within the
//! bound. Residuals go to the adaptive range coder with contexts from their running size.
//!
//! Decoded rotations come back as Euler angles in each joint's own channel order (continuous
//! from frame to frame within a chunk, and from version 3 on the source's branch: the
//! chunk's [`branches`](super::branches) say where it is not; from version 4 also
//! [`twists`](super::twists) near gimbal lock, applied before the joint's children are
//! aimed from it), rounded to 10⁻⁶ — what the
//! decoder gives is what a BVH file prints, so the bound verified on decoding holds on the
//! served file.

use std::sync::Arc;

use nalgebra::Vector3;

use super::branches::{self, turnings, Turning};
use super::entropy::io::{Dry, Io};
use super::entropy::rangecoder::{Decoder, Encoder};
use super::error::{malformed, Error, Result};
use super::measure::max_mean;
use super::rate::{ChunkSteps, Smallest};
use super::skeletal::{no_skeleton, read_whole, rig_of, ChannelDecoder, Posed};
pub(super) use super::skeleton::printed;
use super::skeleton::{Channels, Skeleton};
use super::twists;
use super::{
    default_chunk_frames, ChunkDecoder, ChunkOut, Codec, CodecId, CodecOutput, Input, Shared,
    Target,
};
use crate::motion::rotation::euler_order;

mod aim;
mod delta;
mod transform;

/// What the encoder writes ([`Version::V4`]); the decoder reads every [`Version`].
const VERSION: u8 = 4;
pub(super) const SIZE_CONTEXTS: usize = 20;

pub struct Rot;

/// How each part of a frame is coded.
#[derive(Debug, Clone, Copy)]
pub(super) enum Part {
    /// Three Euler channels (`idx`, in channel order about `order`'s axes) as a quaternion,
    /// with a step in radians.
    Quat {
        joint: usize,
        order: [usize; 3],
        idx: [usize; 3],
        step: f64,
    },
    /// One channel on its own, with a step in its units (degrees or file units).
    Scalar { idx: usize, step: f64, kind: usize },
}

/// The parts of a frame for a rig at a given `α`.
pub(super) struct Plan {
    pub(super) parts: Vec<Part>,
    pub(super) channels: usize,
    pub(super) version: Version,
    /// Whether the chunk's joints are [`twisted`](super::twists) near lock (version 4,
    /// chunk by chunk).
    pub(super) twists: bool,
}

impl Plan {
    fn new(rig: &Skeleton, version: Version, distance: &[f64], alpha: f64) -> Plan {
        let mut parts = Vec::new();
        let mut k = 0;
        for (j, joint) in rig.joints().iter().enumerate() {
            let first = k;
            k += joint.channels.len();
            let rot_step = alpha / distance[j];
            let order = euler_order(&joint.channels);
            let mut rot_idx = Vec::new();
            for (c, ch) in joint.channels.iter().enumerate() {
                match (ch.rotation_axis(), order) {
                    (Some(_), Some(_)) => rot_idx.push(first + c),
                    (Some(_), None) => parts.push(Part::Scalar {
                        idx: first + c,
                        step: rot_step.to_degrees(),
                        kind: 1,
                    }),
                    (None, _) => parts.push(Part::Scalar {
                        idx: first + c,
                        step: alpha,
                        kind: 0,
                    }),
                }
            }
            if let Some(order) = order {
                parts.push(Part::Quat {
                    joint: j,
                    order,
                    idx: [rot_idx[0], rot_idx[1], rot_idx[2]],
                    step: rot_step,
                });
            }
        }
        Plan {
            parts,
            channels: rig.channel_count(),
            version,
            twists: false,
        }
    }
}

/// The bitstream versions a decoder reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Version {
    /// A joint's step scales with its reach (the farthest joint or End Site below it: its
    /// errors add up along the chain); delta mode always extrapolates.
    V1,
    /// A joint's step scales with its longest bone (the encoder aims each joint from its
    /// decoded parent, [`aim`], so an error moves the joint's own children only); delta mode
    /// chooses each part's predictor.
    V2,
    /// Version 2, and each chunk ends with its Euler branch changes
    /// ([`branches`](super::branches)), so decoded triples are the source's.
    V3,
    /// Version 3, and each joint's Euler triples near gimbal lock are twisted to the
    /// file's angles ([`twists`](super::twists)), coded where the joint is decoded.
    V4,
}

impl Version {
    /// The versions a decoder reads.
    pub const ALL: [u8; 4] = [1, 2, 3, 4];
}

impl Version {
    fn parse(v: u8) -> Option<Version> {
        match v {
            1 => Some(Version::V1),
            2 => Some(Version::V2),
            3 => Some(Version::V3),
            4 => Some(Version::V4),
            _ => None,
        }
    }
}

/// Each joint's distance for `version`'s step rule, in the rest pose; at least 5 % of the
/// largest, so that joints that move nothing still keep their rotations to a sensible
/// precision (the BVH served is the animation, not only its FK).
fn distances(rig: &Skeleton, version: Version) -> Vec<f64> {
    let joints = rig.joints();
    let mut pos: Vec<Vector3<f64>> = Vec::with_capacity(joints.len());
    for j in joints {
        let base = j.parent.map_or(Vector3::zeros(), |p| pos[p]);
        pos.push(base + Vector3::from(j.offset));
    }
    let mut dist = vec![0f64; joints.len()];
    for (d, j) in joints.iter().enumerate() {
        let mut a = j.parent;
        while let Some(p) = a {
            dist[p] = dist[p].max((pos[d] - pos[p]).norm());
            a = match version {
                Version::V1 => joints[p].parent,
                Version::V2 | Version::V3 | Version::V4 => None,
            };
        }
    }
    let top = dist.iter().cloned().fold(0.0, f64::max);
    let floor = if top > 0.0 { 0.05 * top } else { 1.0 };
    dist.iter().map(|r| r.max(floor)).collect()
}

impl Codec for Rot {
    fn id(&self) -> CodecId {
        CodecId::Rot
    }

    fn encode(&self, input: &Input<'_>, target: Target) -> Result<CodecOutput> {
        let (rig, skeleton) = input.skeleton_for(CodecId::Rot)?;
        // Steps scale with the tighter bound; each chunk's search keeps the largest step
        // that meets both.
        let t = target.tightest();
        if !(t.is_finite() && t > 0.0) {
            return Err(Error::Invalid(format!(
                "rot needs a positive bound, got {t}"
            )));
        }
        let take = Take::new(rig, skeleton, input, t, default_chunk_frames(input.fps));
        take.encode(target)
    }

    fn versions(&self) -> &'static [u8] {
        &Version::ALL
    }

    fn decoder(
        &self,
        params: &[u8],
        _points: usize,
        shared: &Shared,
    ) -> Result<Box<dyn ChunkDecoder>> {
        let (version, base) = match params {
            [v, a @ ..] if a.len() == 8 => (
                Version::parse(*v).ok_or_else(|| malformed(format!("rot version {v}")))?,
                f64::from_le_bytes(a.try_into().expect("8 bytes")),
            ),
            _ => return Err(malformed("rot parameters")),
        };
        if !(base.is_finite() && base > 0.0) {
            return Err(malformed(format!("rot step {base}")));
        }
        let rig = rig_of(shared, CodecId::Rot)?;
        let steps = Steps::new(&rig, version, base);
        Ok(Box::new(Posed(RotDecoder { rig, steps })))
    }

    fn codes_channels(&self) -> bool {
        true
    }

    fn unsuited(&self, motion: &crate::motion::Motion) -> Option<String> {
        no_skeleton(motion)
    }
}

/// How a chunk is coded (each chunk the smaller of the two).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
enum Mode {
    /// Closed-loop prediction frame by frame ([`delta`]).
    Delta = 0,
    /// DCT coefficients of each part's series per chunk ([`transform`]).
    Transform = 1,
}

/// Step sizes: a chunk's `α` is `base · 2^((k − 224)/8)` for the index `k` (one byte) the
/// chunk starts with, so that each chunk is coded at the largest step its own motion allows.
struct Steps {
    version: Version,
    /// Each joint's rotation step is `α` over this ([`distances`]).
    distance: Vec<f64>,
    base: f64,
    /// The joints whose Euler branches a chunk of version 3 carries.
    turnings: Vec<Turning>,
}

impl Steps {
    fn new(rig: &Skeleton, version: Version, base: f64) -> Steps {
        Steps {
            version,
            distance: distances(rig, version),
            base,
            turnings: turnings(rig),
        }
    }

    fn plan(&self, rig: &Skeleton, k: u32) -> Plan {
        let alpha = self.base * 2f64.powf((f64::from(k) - 224.0) / 8.0);
        Plan::new(rig, self.version, &self.distance, alpha)
    }
}

/// What the encoder codes a chunk from: its channel values, their DCT coefficients, and
/// what aiming needs (when the chunk is aimed).
pub(super) struct Given<'a> {
    values: &'a [f64],
    /// `values` with the frames either side (for the twists' judgement).
    around: twists::Around<'a>,
    coeffs: &'a transform::Coeffs,
    aim: Option<aim::Aim<'a>>,
}

/// One chunk, after its step index, mode and (version 4) whether it twists (`k` and
/// `how` when encoding).
#[allow(clippy::too_many_arguments)]
fn code<I: Io>(
    how: How,
    io: &mut I,
    rig: &Skeleton,
    steps: &Steps,
    k: u32,
    frames: usize,
    given: Option<&Given>,
    out: &mut Vec<f64>,
) -> Result<()> {
    let k = io.raw(k, 8);
    let mut plan = steps.plan(rig, k);
    let mode = match io.raw(how.mode as u32, 1) {
        0 => Mode::Delta,
        _ => Mode::Transform,
    };
    if steps.version == Version::V4 {
        plan.twists = io.raw(u32::from(how.twists), 1) == 1;
    }
    let base = out.len();
    match mode {
        Mode::Delta => delta::code_chunk(io, &plan, frames, given, out)?,
        Mode::Transform => transform::code_chunk(io, &plan, frames, given, out)?,
    }
    if matches!(steps.version, Version::V3 | Version::V4) {
        let source = given.map(|g| g.values);
        branches::code(io, &steps.turnings, plan.channels, source, &mut out[base..])?;
    }
    Ok(())
}

/// How the encoder codes a chunk: the mode and whether joints are twisted near lock
/// (written in the chunk), and whether rotations are aimed from the decoded parents (the
/// encoder's choice; the decoder need not know).
#[derive(Debug, Clone, Copy)]
struct How {
    mode: Mode,
    twists: bool,
    aim: bool,
}

/// A take being encoded: its rig, channel values, the input positions the bound is judged
/// on, and its chunks with their (step-independent) analysis.
struct Take<'a> {
    rig: &'a Skeleton,
    values: &'a [f64],
    input: &'a Input<'a>,
    steps: Steps,
    /// The rig for aiming joints from their decoded parents ([`aim`]).
    bones: aim::Bones,
    /// Each chunk's first frame, frame count and DCT coefficients.
    chunks: Vec<(usize, usize, transform::Coeffs)>,
}

impl<'a> Take<'a> {
    fn new(
        rig: &'a Skeleton,
        skeleton: &'a crate::motion::Animation,
        input: &'a Input<'a>,
        base: f64,
        per: usize,
    ) -> Take<'a> {
        let frames = skeleton.frame_count();
        let values = &skeleton.values[..];
        let steps = Steps::new(rig, Version::V4, base);
        let layout = steps.plan(rig, 224);
        let cc = layout.channels;
        let chunks = (0..frames)
            .step_by(per)
            .map(|f0| {
                let n = per.min(frames - f0);
                let c = transform::analyse(&layout, &values[f0 * cc..(f0 + n) * cc], n);
                (f0, n, c)
            })
            .collect();
        Take {
            rig,
            values,
            input,
            steps,
            bones: aim::Bones::new(rig),
            chunks,
        }
    }

    /// Chunk `i` at step index `k` through `io`: its decoded channel values.
    fn chunk<I: Io>(&self, how: How, i: usize, k: u32, io: &mut I) -> Result<Vec<f64>> {
        let (f0, n, coeffs) = &self.chunks[i];
        let cc = self.rig.channel_count();
        let values = &self.values[f0 * cc..(f0 + n) * cc];
        let points = self.rig.joints().len();
        let aim = how.aim.then(|| aim::Aim {
            bones: &self.bones,
            positions: &self.input.data[f0 * points * 3..(f0 + n) * points * 3],
            points,
        });
        let mut out = Vec::with_capacity(values.len());
        code(
            how,
            io,
            self.rig,
            &self.steps,
            k,
            *n,
            Some(&Given {
                values,
                around: twists::Around::new(self.values, cc, *f0, *n),
                coeffs,
                aim,
            }),
            &mut out,
        )?;
        Ok(out)
    }

    /// Whether chunk `i` at step index `k` meets `target` on its FK positions.
    fn meets(&self, how: How, i: usize, k: u32, target: Target) -> Result<bool> {
        let decoded = self.chunk(how, i, k, &mut Dry)?;
        let (f0, n, _) = self.chunks[i];
        let w = self.rig.joints().len() * 3;
        let mut positions = vec![0f32; n * w];
        self.rig.positions(&decoded, &mut positions);
        let valid = self.input.valid.map(|v| &v[f0 * w / 3..(f0 + n) * w / 3]);
        let (max, mean) = max_mean(&self.input.data[f0 * w..(f0 + n) * w], &positions, valid);
        Ok(target.holds(max, mean))
    }

    /// The bitstream: every chunk in the mode that codes it smaller, each at the largest
    /// step that meets `target`. Chunks are aimed ([`aim`]) unless aiming cannot meet the
    /// bound (a rig whose position channels move children away from where their parent's
    /// rotation puts them): then the file's rotations are coded as they are. Joints are
    /// twisted near lock ([`twists`](super::twists)) unless that cannot meet the bound (a
    /// twist moves a rotation a little, and its children with it).
    fn encode(&self, target: Target) -> Result<CodecOutput> {
        let mut chunks = Vec::with_capacity(self.chunks.len());
        // The step search per mode, aiming and twisting: each chunk's starts where the last
        // one's ended.
        let mut steps = [[[ChunkSteps::default(); 2]; 2]; 2];
        for i in 0..self.chunks.len() {
            let mut best = Smallest::new();
            for mode in [Mode::Delta, Mode::Transform] {
                for (aim, twists) in [(true, true), (true, false), (false, true), (false, false)] {
                    let how = How { mode, twists, aim };
                    let steps = &mut steps[mode as usize][usize::from(aim)][usize::from(twists)];
                    let Some(k) = steps.largest(|k| self.meets(how, i, k, target))? else {
                        continue;
                    };
                    let mut enc = Encoder::new();
                    self.chunk(how, i, k, &mut enc)?;
                    let bytes = enc.finish();
                    best.offer(bytes.len(), bytes);
                    break;
                }
            }
            let bytes = best.into_best().ok_or_else(|| Error::BoundMissed {
                codec: "rot".into(),
                detail: format!("chunk {i} misses the bound even at the finest step"),
            })?;
            chunks.push(ChunkOut {
                frames: self.chunks[i].1,
                bytes,
            });
        }
        let mut params = vec![VERSION];
        params.extend_from_slice(&self.steps.base.to_le_bytes());
        Ok(CodecOutput { params, chunks })
    }
}

/// The nearest integer, saturating (a residual past ±2^62 steps is no motion).
pub(super) fn quantise(x: f64) -> i64 {
    x.round().clamp(-(2f64.powi(62)), 2f64.powi(62)) as i64
}

struct RotDecoder {
    rig: Arc<Skeleton>,
    steps: Steps,
}

impl ChannelDecoder for RotDecoder {
    fn rig(&self) -> &Skeleton {
        &self.rig
    }

    fn channels(&self, bytes: &[u8], frames: usize) -> Result<Channels> {
        let mut dec = Decoder::new(bytes);
        let mut values = Vec::new();
        // What the chunk says it is, read from it.
        let how = How {
            mode: Mode::Delta,
            twists: false,
            aim: false,
        };
        code(
            how,
            &mut dec,
            &self.rig,
            &self.steps,
            0,
            frames,
            None,
            &mut values,
        )?;
        read_whole(&dec, values, CodecId::Rot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::testing::{
        damage_channels, encoded, first_chunk, measured, meets_bounds_and_shrinks, skeleton_shared,
    };
    use crate::codec::ErrorBound;
    use crate::motion::format::Format;
    use crate::motion::formats::{read_as, ReadOptions};
    use crate::motion::synthetic::dancer;

    #[test]
    fn decoded_euler_triples_are_the_sources() {
        crate::codec::testing::follows_the_sources_euler_branches(CodecId::Rot);
    }

    #[test]
    fn decoded_euler_triples_near_gimbal_lock_are_the_sources() {
        crate::codec::testing::keeps_the_sources_angles_near_gimbal_lock(CodecId::Rot);
    }

    #[test]
    fn meets_max_and_mean_bounds_on_fk_positions_and_shrinks_as_they_loosen() {
        meets_bounds_and_shrinks(&dancer(600, 120.0, 7), CodecId::Rot, [0.1, 1.0, 10.0]);
    }

    #[test]
    fn joints_without_three_rotation_axes_and_deep_chains_still_meet_the_bound() {
        let text = crate::motion::synthetic::chain_bvh(12);
        // Twelve frames of a twelve-joint Z-only chain bending back and forth.
        let head = &text[..text.find("MOTION").unwrap()];
        let mut t = format!("{head}MOTION\nFrames: 40\nFrame Time: 0.01\n");
        for f in 0..40 {
            t += "0 0 0";
            for j in 1..12 {
                t += &format!(" {:.4}", 20.0 * ((f + j) as f64 * 0.2).sin());
            }
            t.push('\n');
        }
        let m = read_as(Format::Bvh, t.as_bytes(), &ReadOptions::default())
            .unwrap()
            .motion;
        let enc = encoded(&m, CodecId::Rot, ErrorBound::max(0.5));
        let (max, _) = measured(&m, &enc);
        assert!(max <= 0.5, "{max}");
    }

    #[test]
    fn damaged_chunks_fail_cleanly() {
        let m = dancer(200, 60.0, 3);
        let enc = encoded(&m, CodecId::Rot, ErrorBound::max(1.0));
        let shared = skeleton_shared(&m);
        let d = Rot
            .decoder(&enc.container.header.params, m.point_count(), &shared)
            .unwrap();
        assert!(Rot.decoder(&[VERSION], 1, &shared).is_err());
        assert!(Rot
            .decoder(&[VERSION, 0, 0, 0, 0, 0, 0, 240, 255], 1, &shared)
            .is_err());
        let (frames, bytes) = first_chunk(&enc, &m);
        damage_channels(d.as_ref(), &bytes, frames);
    }
}
