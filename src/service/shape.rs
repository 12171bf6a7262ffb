//! The transforms a range answer asks for ([`Options`]: frame rate, root motion, up axis,
//! unit), applied to each decoded block on its way to the writer. The math is in
//! [`crate::motion::transform`]; this holds the state one answer carries between blocks
//! and decides which transform a take can take.

use super::prepared::Prepared;
use super::retarget::{Feet, Target};
use super::{Error, Result};
use crate::motion::rate;
use crate::motion::retarget::Retarget;
use crate::motion::skeleton::Joint;
use crate::motion::transform::channels::Channels;
use crate::motion::transform::pose::{PointPose, SkeletonPose};
use crate::motion::transform::resample::{output_frames, Positions, Resampler};
use crate::motion::transform::Options;

/// The transforms of one answer, and the state they keep between blocks.
pub enum Shaper {
    /// Positions: all the take's points are decoded (root motion follows the root even
    /// when it is not asked for), transformed, then the asked-for ones kept.
    Points {
        options: Options,
        resampler: Option<Resampler<Positions>>,
        pose: Box<PointPose>,
        points: usize,
        /// Indices into the transformed frame's points.
        selected: Vec<usize>,
    },
    /// A skeleton's channel values: resampled, put on another skeleton (`skeleton=`),
    /// then posed.
    Channels {
        fps: Option<f64>,
        resampler: Option<Resampler<Channels>>,
        retarget: Option<Box<Retarget>>,
        pose: Box<SkeletonPose>,
        /// For a position format: the shaped skeleton's joints placed by forward
        /// kinematics, the asked-for ones kept ([`Shaper::as_positions`]).
        placed: Option<Box<Placed>>,
    },
}

/// A shaped skeleton's frames as positions of its joints.
pub struct Placed {
    joints: Vec<Joint>,
    fk: crate::motion::skeleton::Fk,
    /// Indices of the joints written, in order.
    selected: Vec<usize>,
}

/// A transform the take's body cannot make (409, naming what to give), a stored body that
/// contradicts its take (corrupt), or a transform that makes no sense (400).
fn refused(e: crate::motion::Error) -> Error {
    match e {
        crate::motion::Error::Unsupported(m) => Error::Unsatisfiable(m),
        crate::motion::Error::Contradiction(m) => Error::Corrupt(m),
        other => Error::InvalidRequest(other.to_string()),
    }
}

/// The options every answer shares, checked ([`Options::check`]): a 400 saying why not.
pub fn check(options: &Options) -> Result<()> {
    options.check().map_err(Error::InvalidRequest)
}

/// The source frames an answer of range `start..end` decodes (from `start`) and the frames
/// it has after `options`. Resampled, its frames are those whose time lies in the range,
/// `seconds` long from frame `start` (`t0 ≤ t < t1`: a second of a 24 fps take at 30 fps
/// is 30 frames); those past the range's last source frame are interpolated from the
/// frames after it, which are decoded too where the take has them and `extend` allows.
pub fn span(
    prepared: &Prepared,
    options: &Options,
    extend: bool,
    (start, end): (usize, usize),
    seconds: f64,
) -> (usize, usize) {
    match options.fps {
        Some(fps) if fps != prepared.fps => {
            let plain = output_frames(end - start, prepared.fps, fps);
            if !extend {
                return (end, plain);
            }
            // Output frames before the range's end (its time reckoned at either rate).
            let t = seconds * fps;
            let slack = rate::slack(seconds, prepared.fps) * fps / rate::nominal(prepared.fps);
            let within = (t - slack).ceil().max(1.0) as usize;
            if within <= plain {
                return (end, within);
            }
            // The last ones lie past the range's last source frame: decode the frames
            // after it that interpolating them needs (the cubic's two), where the take has
            // them.
            let decoded = (end + 2).min(prepared.frames.max(end));
            let can = output_frames(decoded - start, prepared.fps, fps);
            (decoded, within.min(can))
        }
        _ => (end, end - start),
    }
}

fn resampler<I: crate::motion::transform::resample::Interpolant>(
    interp: I,
    prepared: &Prepared,
    options: &Options,
    frames: usize,
) -> Option<Resampler<I>> {
    match options.fps {
        Some(fps) if fps != prepared.fps => Some(Resampler::new(interp, frames, prepared.fps, fps)),
        _ => None,
    }
}

impl Shaper {
    /// This shaper making at most `frames` output frames (the range's, of more source
    /// frames decoded: [`span`]).
    pub fn limited(mut self, frames: usize) -> Shaper {
        match &mut self {
            Shaper::Points { resampler, .. } => {
                if let Some(r) = resampler {
                    r.limit(frames);
                }
            }
            Shaper::Channels { resampler, .. } => {
                if let Some(r) = resampler {
                    r.limit(frames);
                }
            }
        }
        self
    }

    /// The shaper of positions of `frames` source frames, keeping the points `selected`
    /// (all when `None`; with `root=extract`, `root_motion` is kept as well).
    pub fn points(
        prepared: &Prepared,
        options: &Options,
        frames: usize,
        selected: Option<Vec<usize>>,
    ) -> Result<Shaper> {
        check(options)?;
        let points = prepared.point_names.len();
        let pose = PointPose::new(options, points, &prepared.stance, prepared.metres_per_unit)
            .map_err(refused)?;
        let mut selected = selected.unwrap_or_else(|| (0..points).collect());
        selected.extend(points..pose.points_out());
        Ok(Shaper::Points {
            options: *options,
            resampler: resampler(Positions { points }, prepared, options, frames),
            pose: Box::new(pose),
            points,
            selected,
        })
    }

    /// The names of the points a shaped frame holds.
    pub fn point_names(&self, prepared: &Prepared) -> Vec<String> {
        match self {
            Shaper::Points {
                selected,
                points,
                pose,
                ..
            } => selected
                .iter()
                .map(|&i| match i.checked_sub(*points) {
                    Some(extra) => pose.extra_names()[extra].to_string(),
                    None => prepared.point_names[i].clone(),
                })
                .collect(),
            Shaper::Channels { .. } => Vec::new(),
        }
    }

    /// The shaper of a skeleton's channels (`joints`) of `frames` source frames, put on
    /// `onto` when asked (its feet as `feet` asks).
    pub fn channels(
        prepared: &Prepared,
        joints: &[Joint],
        options: &Options,
        frames: usize,
        onto: Option<&Target>,
        feet: Feet,
    ) -> Result<Shaper> {
        check(options)?;
        let (retarget, pose) = match onto {
            None => (
                None,
                SkeletonPose::new(options, joints, &prepared.stance, prepared.metres_per_unit),
            ),
            Some(target) => {
                let fps = options.fps.unwrap_or(prepared.fps);
                let (r, stance) = super::retarget::retargeter(prepared, joints, target, feet, fps)?;
                let pose = SkeletonPose::new(options, r.joints(), &stance, target.metres_per_unit);
                (Some(Box::new(r)), pose)
            }
        };
        Ok(Shaper::Channels {
            fps: options.fps,
            resampler: resampler(Channels::new(joints), prepared, options, frames),
            retarget,
            pose: Box::new(pose.map_err(refused)?),
            placed: None,
        })
    }

    /// This skeleton shaper writing positions of its joints (`selected` by index among
    /// [`Shaper::joints`], all when `None`) instead of channel values: a position format of
    /// a take put on another skeleton.
    pub fn as_positions(mut self, selected: Option<Vec<usize>>) -> Shaper {
        if let Shaper::Channels { pose, placed, .. } = &mut self {
            let joints = pose.joints().to_vec();
            *placed = Some(Box::new(Placed {
                selected: selected.unwrap_or_else(|| (0..joints.len()).collect()),
                fk: crate::motion::skeleton::Fk::new(&joints),
                joints,
            }));
        }
        self
    }

    /// Shaped channel values (whole frames) as the positions [`Shaper::as_positions`]
    /// asked for, and how many frames; `None` for a shaper that writes channels.
    pub fn placed(&mut self, values: &[f64]) -> Option<(Vec<f32>, usize)> {
        let Shaper::Channels {
            placed: Some(p), ..
        } = self
        else {
            return None;
        };
        let cc: usize = p.joints.iter().map(|j| j.channels.len()).sum();
        let frames = values.len() / cc.max(1);
        let mut at = vec![0.0; p.joints.len() * 3];
        let mut out = Vec::with_capacity(frames * p.selected.len() * 3);
        for f in values.chunks_exact(cc.max(1)) {
            p.fk.frame(&p.joints, f, &mut at);
            for &j in &p.selected {
                out.extend(at[j * 3..j * 3 + 3].iter().map(|&v| v as f32));
            }
        }
        Some((out, frames))
    }

    /// The rate of shaped frames.
    pub fn fps(&self, prepared: &Prepared) -> f64 {
        match self {
            Shaper::Points { options, .. } => options.fps,
            Shaper::Channels { fps, .. } => *fps,
        }
        .unwrap_or(prepared.fps)
    }

    /// The skeleton a shaped frame's channels are of (`None` for positions).
    pub fn joints(&self) -> Option<&[Joint]> {
        match self {
            Shaper::Channels { pose, .. } => Some(pose.joints()),
            Shaper::Points { .. } => None,
        }
    }

    /// Channels a source frame has (a skeleton's shaper).
    pub fn channels_in(&self) -> usize {
        match self {
            Shaper::Channels {
                retarget: Some(r), ..
            } => r.channels_in(),
            Shaper::Channels { pose, .. } => pose.channels_in(),
            Shaper::Points { .. } => 0,
        }
    }

    /// Values a shaped frame holds.
    pub fn width(&self) -> usize {
        match self {
            Shaper::Points { selected, .. } => selected.len() * 3,
            Shaper::Channels { pose, .. } => pose.channels_out(),
        }
    }

    /// Decoded positions of `count` whole source frames (every point of the take) to shaped
    /// ones, as many frames as are ready, and how many (a take of no points has frames too).
    pub fn positions(&mut self, decoded: &[f32], count: usize) -> (Vec<f32>, usize) {
        let Shaper::Points {
            resampler,
            pose,
            points,
            selected,
            ..
        } = self
        else {
            unreachable!("a positions block is shaped by a points shaper")
        };
        let w = *points * 3;
        let src: Vec<f64> = decoded.iter().map(|&v| f64::from(v)).collect();
        let (frames, count) = match resampler {
            Some(r) => {
                let mut out = Vec::with_capacity(r.most_out_of(count) * w);
                let made = r.push_count(&src, count, &mut out);
                (out, made)
            }
            None => (src, count),
        };
        let wo = pose.points_out() * 3;
        let mut shaped = Vec::with_capacity(wo);
        let mut out = Vec::with_capacity(selected.len() * 3 * count);
        for f in (0..count).map(|i| &frames[i * w..(i + 1) * w]) {
            shaped.clear();
            pose.frame(f, &mut shaped);
            for &p in selected.iter() {
                out.extend(shaped[p * 3..p * 3 + 3].iter().map(|&v| v as f32));
            }
        }
        (out, count)
    }

    /// Decoded channel values of whole source frames to shaped ones, as many frames as
    /// are ready.
    pub fn channel_values(&mut self, decoded: &[f64]) -> Vec<f64> {
        let Shaper::Channels {
            resampler,
            retarget,
            pose,
            ..
        } = self
        else {
            unreachable!("a channels block is shaped by a channels shaper")
        };
        let resampled;
        let frames = match resampler {
            Some(r) => {
                let mut out = Vec::new();
                r.push(decoded, &mut out);
                resampled = out;
                &resampled[..]
            }
            None => decoded,
        };
        let mut out = Vec::new();
        match retarget {
            None => {
                let w = pose.channels_in().max(1);
                out.reserve(frames.len() / w * pose.channels_out());
                for f in frames.chunks_exact(w) {
                    pose.frame(f, &mut out);
                }
            }
            Some(r) => {
                let w = r.channels_in().max(1);
                out.reserve(frames.len() / w * pose.channels_out());
                let mut on = Vec::with_capacity(r.channels_out());
                for f in frames.chunks_exact(w) {
                    on.clear();
                    r.frame(f, &mut on);
                    pose.frame(&on, &mut out);
                }
            }
        }
        out
    }
}
