//! Root motion, up axis and unit: frame by frame, on positions ([`PointPose`]) or on a
//! skeleton's channels ([`SkeletonPose`]).
//!
//! Another up axis is a quarter turn about X (right-handed, X kept): Z-up to Y-up takes
//! `(x, y, z)` to `(x, z, −y)`. On a skeleton it turns the root (its translation and its
//! rotation); every other joint lies in its parent's frame and follows.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use super::{Options, Root, Up, ROOT_MOTION};
use crate::motion::rotation::{euler_order, from_euler, to_euler};
use crate::motion::skeleton::{translation, Channel, Joint};

/// The turn from `from`-up coordinates to `to`-up ones; `None` when they are the same.
pub fn axes(from: Up, to: Up) -> Option<Matrix3<f64>> {
    match (from, to) {
        (Up::Z, Up::Y) => Some(Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0)),
        (Up::Y, Up::Z) => Some(Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0)),
        _ => None,
    }
}

/// The horizontal axes when `up` is up.
fn horizontal(up: Up) -> [usize; 2] {
    match up {
        Up::Y => [0, 2],
        Up::Z => [0, 1],
    }
}

/// Root motion, axes and unit on positions (`points × 3` a frame, NaN where missing).
#[derive(Debug, Clone)]
pub struct PointPose {
    points: usize,
    root: Root,
    /// The point root motion follows (a skeleton take's root joint).
    root_point: usize,
    up: Up,
    turn: Option<Matrix3<f64>>,
    scale: f64,
}

impl PointPose {
    /// The transform of `options` for `points` points of a take `up`-up in units of
    /// `metres_per_unit`, whose root is point `root_point` (`None`: a marker take, which has
    /// no root, and root motion is refused).
    pub fn new(
        options: &Options,
        points: usize,
        root_point: Option<usize>,
        up: Up,
        metres_per_unit: f64,
    ) -> Result<PointPose, String> {
        let root_point = match (options.root, root_point) {
            (Root::Keep, _) => 0,
            (_, Some(p)) if p < points => p,
            _ => {
                return Err(format!(
                    "root={} needs a skeleton take: a marker take has no root joint",
                    options.root
                ))
            }
        };
        Ok(PointPose {
            points,
            root: options.root,
            root_point,
            up,
            turn: options.up.and_then(|to| axes(up, to)),
            scale: options
                .metres_per_unit
                .map_or(1.0, |out| metres_per_unit / out),
        })
    }

    /// Points a frame has once transformed: one more with an extracted root motion.
    pub fn points_out(&self) -> usize {
        self.points + usize::from(self.root == Root::Extract)
    }

    /// Whether frames go through unchanged.
    pub fn is_identity(&self) -> bool {
        self.root == Root::Keep && self.turn.is_none() && self.scale == 1.0
    }

    /// One frame, appended to `out` (`points_out() × 3` values).
    pub fn frame(&self, src: &[f64], out: &mut Vec<f64>) {
        let at = out.len();
        out.extend_from_slice(&src[..self.points * 3]);
        if self.root != Root::Keep {
            let r = self.root_point * 3;
            let root = [src[r], src[r + 1], src[r + 2]];
            let mut moved = [0.0; 3];
            if root.iter().all(|v| v.is_finite()) {
                for a in horizontal(self.up) {
                    moved[a] = root[a];
                }
            } else {
                moved = [f64::NAN; 3];
            }
            if moved[0].is_finite() {
                for p in out[at..].chunks_exact_mut(3) {
                    for a in horizontal(self.up) {
                        p[a] -= moved[a];
                    }
                }
            }
            if self.root == Root::Extract {
                out.extend_from_slice(&moved);
            }
        }
        for p in out[at..].chunks_exact_mut(3) {
            let mut v = Vector3::new(p[0], p[1], p[2]);
            if let Some(m) = &self.turn {
                v = m * v;
            }
            v *= self.scale;
            p.copy_from_slice(v.as_slice());
        }
    }
}

/// Root motion, axes and unit on a skeleton's channel values: its joints as they are
/// written ([`SkeletonPose::joints`]) and each frame's values for them.
#[derive(Debug, Clone)]
pub struct SkeletonPose {
    joints: Vec<Joint>,
    source: Vec<Joint>,
    root: Root,
    up: Up,
    turn: Option<Turn>,
    scale: f64,
    /// Channels of the written skeleton that are positions (scaled).
    positions: Vec<bool>,
}

/// How the root turns to other axes.
#[derive(Debug, Clone)]
struct Turn {
    m: Matrix3<f64>,
    q: UnitQuaternion<f64>,
    /// The root's three Euler channels (offsets in its channels) and their order.
    at: [usize; 3],
    order: [usize; 3],
    /// The root's position channel of each axis.
    position: [usize; 3],
    /// The root's last written angles, for continuity.
    last: Option<[f64; 3]>,
}

impl SkeletonPose {
    /// The transform of `options` for `joints` of a take `up`-up in `metres_per_unit`.
    /// Other axes need a root with three Euler channels and three position channels (what
    /// BVH roots have); another root is refused, saying why.
    pub fn new(
        options: &Options,
        joints: &[Joint],
        up: Up,
        metres_per_unit: f64,
    ) -> Result<SkeletonPose, String> {
        let root = joints
            .first()
            .ok_or_else(|| "the skeleton has no joints".to_string())?;
        let turn = match options.up.and_then(|to| axes(up, to)) {
            None => None,
            Some(m) => {
                let rot: Vec<usize> = (0..root.channels.len())
                    .filter(|&c| root.channels[c].rotation_axis().is_some())
                    .collect();
                let pos =
                    |axis: usize| root.channels.iter().position(|c| c.axis() == (axis, false));
                match (euler_order(&root.channels), pos(0), pos(1), pos(2)) {
                    (Some(order), Some(x), Some(y), Some(z)) if rot.len() == 3 => Some(Turn {
                        m,
                        q: UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
                            m,
                        )),
                        at: [rot[0], rot[1], rot[2]],
                        order,
                        position: [x, y, z],
                        last: None,
                    }),
                    _ => {
                        return Err(format!(
                            "up={} needs a root joint with three rotation and three position \
                             channels; {:?} has {}",
                            options.up.map_or("", Up::name),
                            root.name,
                            root.channels
                                .iter()
                                .map(|c| c.name())
                                .collect::<Vec<_>>()
                                .join(" ")
                        ))
                    }
                }
            }
        };
        let scale = options
            .metres_per_unit
            .map_or(1.0, |out| metres_per_unit / out);
        let mut out: Vec<Joint> = joints.to_vec();
        for j in &mut out {
            j.offset = j.offset.map(|v| v * scale);
        }
        if options.root != Root::Keep {
            // The offset's horizontal part is root motion too (a root without position
            // channels on an axis stands at its offset there).
            for a in horizontal(up) {
                out[0].offset[a] = 0.0;
            }
        }
        if options.root == Root::Extract {
            for j in &mut out {
                j.parent = Some(j.parent.map_or(0, |p| p + 1));
            }
            out.insert(
                0,
                Joint {
                    name: ROOT_MOTION.into(),
                    parent: None,
                    offset: [0.0; 3],
                    channels: vec![Channel::Xposition, Channel::Yposition, Channel::Zposition],
                    end_site: false,
                },
            );
        }
        let positions = out
            .iter()
            .flat_map(|j| j.channels.iter().map(|c| c.rotation_axis().is_none()))
            .collect();
        Ok(SkeletonPose {
            joints: out,
            source: joints.to_vec(),
            root: options.root,
            up,
            turn,
            scale,
            positions,
        })
    }

    /// The skeleton as written.
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    /// Channels a source frame has.
    pub fn channels_in(&self) -> usize {
        self.source.iter().map(|j| j.channels.len()).sum()
    }

    /// Channels a written frame has.
    pub fn channels_out(&self) -> usize {
        self.positions.len()
    }

    /// One frame of the source's channel values, appended to `out` as the written
    /// skeleton's (`channels_out()` values).
    pub fn frame(&mut self, src: &[f64], out: &mut Vec<f64>) {
        let root = &self.source[0];
        let n = root.channels.len();
        let mut moved = [0.0; 3];
        let mut vals = src.to_vec();
        if self.root != Root::Keep {
            let t = translation(root, &src[..n]);
            for a in horizontal(self.up) {
                moved[a] = t[a];
            }
            for (c, ch) in root.channels.iter().enumerate() {
                let (axis, rot) = ch.axis();
                if !rot && horizontal(self.up).contains(&axis) {
                    vals[c] = 0.0;
                }
            }
        }
        if let Some(turn) = &mut self.turn {
            let p = &turn.position;
            let t = turn.m * Vector3::new(vals[p[0]], vals[p[1]], vals[p[2]]);
            for a in 0..3 {
                vals[p[a]] = t[a];
            }
            let e = [vals[turn.at[0]], vals[turn.at[1]], vals[turn.at[2]]];
            let q = turn.q * from_euler(turn.order, e);
            let e = to_euler(&q, turn.order, turn.last.or(Some(e)));
            turn.last = Some(e);
            for (k, v) in turn.at.iter().zip(e) {
                vals[*k] = v;
            }
            moved = (turn.m * Vector3::from(moved)).into();
        }
        let at = out.len();
        if self.root == Root::Extract {
            out.extend_from_slice(&moved);
        }
        out.extend_from_slice(&vals);
        for (v, &is_pos) in out[at..].iter_mut().zip(&self.positions) {
            if is_pos {
                *v *= self.scale;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::skeleton::Animation;
    use crate::motion::synthetic::dancer_bvh;

    fn skeleton() -> Animation {
        crate::motion::formats::read(dancer_bvh(40, 120.0, 3, 6).as_bytes(), &Default::default())
            .unwrap()
            .motion
            .skeleton
            .unwrap()
    }

    fn fk(joints: &[Joint], values: &[f64]) -> Vec<f64> {
        Animation::new(joints.to_vec(), values.to_vec())
            .unwrap()
            .forward_kinematics()
    }

    fn apply(pose: &mut SkeletonPose, s: &Animation) -> Vec<f64> {
        let mut out = Vec::new();
        for f in 0..s.frame_count() {
            pose.frame(s.frame_values(f), &mut out);
        }
        out
    }

    /// In place: the root's horizontal path is zero, its height and every joint relative
    /// to it unchanged. Extract: the same, with the path on a joint above, so that FK gives
    /// the source's positions.
    #[test]
    fn root_motion_in_place_and_extracted() {
        let s = skeleton();
        let n = s.joints.len();
        let src = s.forward_kinematics();
        let opts = |root| Options {
            root,
            ..Options::default()
        };
        let mut inplace = SkeletonPose::new(&opts(Root::InPlace), &s.joints, Up::Y, 0.01).unwrap();
        let vals = apply(&mut inplace, &s);
        let pos = fk(inplace.joints(), &vals);
        for f in 0..s.frame_count() {
            let (a, b) = (&src[f * n * 3..][..n * 3], &pos[f * n * 3..][..n * 3]);
            assert!(
                b[0].abs() < 1e-9 && b[2].abs() < 1e-9,
                "frame {f}: {:?}",
                &b[..3]
            );
            assert!((a[1] - b[1]).abs() < 1e-9);
            for j in 1..n {
                for k in 0..3 {
                    let rel = |v: &[f64]| v[j * 3 + k] - v[k];
                    assert!((rel(a) - rel(b)).abs() < 1e-9);
                }
            }
        }
        let mut extract = SkeletonPose::new(&opts(Root::Extract), &s.joints, Up::Y, 0.01).unwrap();
        assert_eq!(extract.joints()[0].name, ROOT_MOTION);
        let vals = apply(&mut extract, &s);
        let pos = fk(extract.joints(), &vals);
        for f in 0..s.frame_count() {
            let b = &pos[f * (n + 1) * 3..][..(n + 1) * 3];
            assert_eq!(b[1], 0.0);
            for (x, y) in src[f * n * 3..][..n * 3].iter().zip(&b[3..]) {
                assert!((x - y).abs() < 1e-9);
            }
        }
        // Points: the same, with the path as one more point.
        let pp = PointPose::new(&opts(Root::Extract), n, Some(0), Up::Y, 0.01).unwrap();
        let mut out = Vec::new();
        pp.frame(&src[..n * 3], &mut out);
        assert_eq!(out.len(), (n + 1) * 3);
        assert_eq!(out[0], 0.0);
        assert_eq!(&out[n * 3..], &[src[0], 0.0, src[2]]);
        assert!(PointPose::new(&opts(Root::InPlace), n, None, Up::Y, 0.01).is_err());
    }

    /// Another up axis and unit on the channels gives FK's positions turned and scaled.
    #[test]
    fn axes_and_units_on_channels_match_positions() {
        let s = skeleton();
        let src = s.forward_kinematics();
        let opts = Options {
            up: Some(Up::Z),
            metres_per_unit: Some(0.001),
            ..Options::default()
        };
        let mut pose = SkeletonPose::new(&opts, &s.joints, Up::Y, 0.01).unwrap();
        let vals = apply(&mut pose, &s);
        let pos = fk(pose.joints(), &vals);
        let pp = PointPose::new(&opts, src.len() / 3, None, Up::Y, 0.01).unwrap();
        let mut want = Vec::new();
        pp.frame(&src, &mut want);
        for (i, (a, b)) in want.iter().zip(&pos).enumerate() {
            assert!((a - b).abs() < 1e-6, "value {i}: {a} vs {b}");
        }
        // Y-up (x, y, z) is Z-up (x, −z, y), in ten times as many units.
        assert!((want[1] + src[2] * 10.0).abs() < 1e-9 && (want[2] - src[1] * 10.0).abs() < 1e-9);
    }
}
