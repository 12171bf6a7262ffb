//! The transforms on a whole take in memory (`mocapstore convert`): the same resampler and
//! poses the read path streams blocks through, run over every frame at once.

use super::channels::Channels;
use super::pose::{PointPose, SkeletonPose};
use super::resample::{Positions, Resampler};
use super::{Options, Stance};
use crate::motion::body::Body;
use crate::motion::skeleton::Animation;
use crate::motion::units::{Unit, UnitSource};
use crate::motion::Error;
use crate::motion::Motion;

/// `m`, whose body is `body`, with `options` applied. A skeleton take is transformed
/// through its channels (its positions are then its joints' FK); any other through its
/// positions. Root motion follows the body's pelvis; axes turn from its up.
pub fn apply(m: &Motion, body: &Body, options: &Options) -> Result<Motion, Error> {
    options.check().map_err(Error::Invalid)?;
    if options.is_identity() {
        return Ok(m.clone());
    }
    let stance = Stance::of(body, &m.point_names, m.unit.metres_per_unit);
    let fps = options.fps.unwrap_or(m.fps);
    let unit = match options.metres_per_unit {
        Some(mpu) => Unit::new(mpu, UnitSource::Explicit)?,
        None => m.unit.clone(),
    };
    let frames = m.frame_count();
    let resample = options.fps.filter(|&f| f != m.fps);
    if let Some(s) = &m.skeleton {
        let mut pose = SkeletonPose::new(options, &s.joints, &stance, m.unit.metres_per_unit)?;
        let values = match resample {
            Some(to) => {
                let mut r = Resampler::new(Channels::new(&s.joints), frames, m.fps, to);
                let mut out = Vec::new();
                r.push(&s.values, &mut out);
                out
            }
            None => s.values.clone(),
        };
        let mut shaped = Vec::with_capacity(values.len());
        for f in values.chunks_exact(pose.channels_in().max(1)) {
            pose.frame(f, &mut shaped);
        }
        let skeleton = Animation::new(pose.joints().to_vec(), shaped)?;
        let names = skeleton.joints.iter().map(|j| j.name.clone()).collect();
        let positions = skeleton
            .forward_kinematics()
            .into_iter()
            .map(|v| v as f32)
            .collect();
        return Motion::new(fps, unit, names, positions, Some(skeleton));
    }
    let points = m.point_count();
    let mut pose = PointPose::new(options, points, &stance, m.unit.metres_per_unit)?;
    let src: Vec<f64> = m.positions().iter().map(|&v| f64::from(v)).collect();
    let (frames_in, count) = match resample {
        Some(to) => {
            let mut r = Resampler::new(Positions { points }, frames, m.fps, to);
            let mut out = Vec::new();
            let made = r.push_count(&src, frames, &mut out);
            (out, made)
        }
        None => (src, frames),
    };
    if points == 0 {
        // Frames of no points (a C3D of analog channels only) are still frames.
        return Motion::without_points(fps, unit, count);
    }
    let mut shaped = Vec::with_capacity(frames_in.len());
    for f in frames_in.chunks_exact(points * 3) {
        pose.frame(f, &mut shaped);
    }
    let mut names = m.point_names.clone();
    names.extend(pose.extra_names().iter().map(|n| n.to_string()));
    let positions = shaped.into_iter().map(|v| v as f32).collect();
    Motion::new(fps, unit, names, positions, None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::synthetic::dancer_bvh;
    use crate::motion::transform::Root;

    /// A whole take transformed is what FK of its transformed channels gives: root in place,
    /// 60 fps, in metres; its positions are its joints'.
    #[test]
    fn a_skeleton_take_transformed_whole() {
        // Frame time 0.008333 s: 120.0048 fps, taken as 120 (every other frame at 60).
        let m = crate::motion::formats::read(
            dancer_bvh(61, 120.0, 2, 6).as_bytes(),
            &Default::default(),
        )
        .unwrap()
        .motion;
        let o = Options {
            fps: Some(60.0),
            root: Root::InPlace,
            metres_per_unit: Some(1.0),
            up: None,
        };
        let body = Body::of(&m, Default::default(), None).unwrap();
        let t = apply(&m, &body, &o).unwrap();
        assert_eq!(t.frame_count(), 31);
        assert_eq!(t.fps, 60.0);
        assert_eq!(t.unit.metres_per_unit, 1.0);
        for f in 0..t.frame_count() {
            let root = t.sample(f, 0).unwrap();
            assert!(root[0].abs() < 1e-6 && root[2].abs() < 1e-6, "{root:?}");
            // Every other source frame, relative to the root, in metres.
            let (a, b) = (m.frame(2 * f), t.frame(f));
            let k = m.unit.metres_per_unit as f32;
            for p in 1..m.point_count() {
                for c in 0..3 {
                    let rel = (a[p * 3 + c] - a[c]) * k;
                    assert!((rel - (b[p * 3 + c] - b[c])).abs() < 1e-4, "{p} {c}");
                }
            }
        }
    }
}
