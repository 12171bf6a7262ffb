//! Root motion, up axis and unit: frame by frame, on positions ([`PointPose`]) or on a
//! skeleton's channels ([`SkeletonPose`]).
//!
//! Root motion follows the pelvis ([`Stance::pelvis`]), whatever joint carries the
//! translation channels: in place, its horizontal position is zero in every frame (its
//! height kept); extracted, that path runs on the floor as one more point or joint.
//!
//! Another up axis is the shortest turn from the take's ([`Axis::turn_to`]): Z-up to Y-up
//! takes `(x, y, z)` to `(x, z, −y)`. On a skeleton it turns the root (its translation and
//! its rotation); every other joint lies in its parent's frame and follows.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use super::{Axis, Options, Root, Stance, ROOT_MOTION, ROOT_MOTION_FORWARD, ROOT_MOTION_FORWARD_M};
use crate::motion::rotation::{euler_order, from_euler, to_euler};
use crate::motion::skeleton::{Channel, Fk, Joint};
use crate::motion::Error;

/// The up axis a transform of `options` works in: the take's, which must be known when
/// root motion is moved or the take is turned (else the 409 that says how to give it).
fn working_up(options: &Options, stance: &Stance) -> Result<Axis, Error> {
    match (options.root, options.up) {
        (Root::Keep, None) => Ok(stance.up.unwrap_or(Axis::Y)),
        (Root::Keep, Some(to)) => stance.up_for(&format!("turning it {to} up (glTF, up=)")),
        (root, _) => stance.up_for(&format!("root={root}")),
    }
}

/// `v` with its component along `up` set to `height` (a coordinate, signed as `up` is).
fn on_level(mut v: [f64; 3], up: Axis, height: f64) -> [f64; 3] {
    v[up.index()] = height * up.sign();
    v
}

/// Root motion, axes and unit on positions (`points × 3` a frame, NaN where missing).
#[derive(Debug, Clone)]
pub struct PointPose {
    points: usize,
    root: Root,
    /// The points whose centroid root motion follows.
    pelvis: Vec<usize>,
    up: Axis,
    floor: f64,
    turn: Option<Matrix3<f64>>,
    scale: f64,
    /// The pelvis's last horizontal place, held through frames where all its points are
    /// missing.
    held: Option<[f64; 3]>,
    /// Extract's heading, when the body tells which way it faces: the points are turned
    /// back by it about the pelvis, and it is given as a point ahead of the root motion.
    heading: Option<Facing>,
    /// [`ROOT_MOTION_FORWARD_M`] in the take's units.
    ahead: f64,
}

impl PointPose {
    /// The transform of `options` for `points` points of a take whose body is `stance`, in
    /// units of `metres_per_unit`. Unsupported (409): the body does not tell what the
    /// options need.
    pub fn new(
        options: &Options,
        points: usize,
        stance: &Stance,
        metres_per_unit: f64,
    ) -> Result<PointPose, Error> {
        let up = working_up(options, stance)?;
        let pelvis = match options.root {
            Root::Keep => Vec::new(),
            root => stance.pelvis_for(root)?.to_vec(),
        };
        if let Some(&p) = pelvis.iter().find(|&&p| p >= points) {
            return Err(Error::Contradiction(format!(
                "the pelvis is point {p} of a take of {points}"
            )));
        }
        if let Some(&p) = stance
            .sides
            .iter()
            .flat_map(|(l, r)| l.iter().chain(r))
            .find(|&&p| p >= points)
        {
            return Err(Error::Contradiction(format!(
                "a side is point {p} of a take of {points}"
            )));
        }
        let heading = match (options.root, stance.forward) {
            (Root::Extract, Some(f)) if !stance.sides.is_empty() => Some(Facing {
                forward: f.vector(),
                sides: stance.sides.clone(),
                last: None,
            }),
            _ => None,
        };
        Ok(PointPose {
            points,
            root: options.root,
            pelvis,
            up,
            floor: stance.floor,
            turn: options.up.and_then(|to| up.turn_to(to)),
            scale: options
                .metres_per_unit
                .map_or(1.0, |out| metres_per_unit / out),
            held: None,
            heading,
            ahead: ROOT_MOTION_FORWARD_M / metres_per_unit,
        })
    }

    /// The names of the points a frame has after the take's own: an extracted root motion,
    /// and the point ahead of it that gives its heading when the body tells one.
    pub fn extra_names(&self) -> &'static [&'static str] {
        match (self.root, &self.heading) {
            (Root::Extract, Some(_)) => &[ROOT_MOTION, ROOT_MOTION_FORWARD],
            (Root::Extract, None) => &[ROOT_MOTION],
            _ => &[],
        }
    }

    /// Points a frame has once transformed.
    pub fn points_out(&self) -> usize {
        self.points + self.extra_names().len()
    }

    /// Whether frames go through unchanged.
    pub fn is_identity(&self) -> bool {
        self.root == Root::Keep && self.turn.is_none() && self.scale == 1.0
    }

    /// The pelvis's place across `up` in frame `src` (up component zero): the centroid of
    /// its points present, or the last one known.
    fn pelvis_at(&mut self, src: &[f64]) -> Option<[f64; 3]> {
        let mut sum = [0.0; 3];
        let mut k = 0;
        for &p in &self.pelvis {
            let v = &src[p * 3..p * 3 + 3];
            if v.iter().all(|x| x.is_finite()) {
                for a in 0..3 {
                    sum[a] += v[a];
                }
                k += 1;
            }
        }
        if k > 0 {
            self.held = Some(on_level(sum.map(|s| s / k as f64), self.up, 0.0));
        }
        self.held
    }

    /// One frame, appended to `out` (`points_out() × 3` values).
    pub fn frame(&mut self, src: &[f64], out: &mut Vec<f64>) {
        let at = out.len();
        out.extend_from_slice(&src[..self.points * 3]);
        if self.root != Root::Keep {
            let path = self.pelvis_at(src);
            if let Some(h) = path {
                for p in out[at..].chunks_exact_mut(3) {
                    for a in self.up.across() {
                        p[a] -= h[a];
                    }
                }
            }
            if self.root == Root::Extract {
                let ground = path.map_or([f64::NAN; 3], |h| on_level(h, self.up, self.floor));
                out.extend_from_slice(&ground);
                if let Some(h) = &mut self.heading {
                    // The body turned back about the pelvis (now over the origin), and the
                    // heading as a point ahead of the root motion.
                    let u = self.up.vector();
                    let mut placed = |p: usize| {
                        let v = &src[p * 3..p * 3 + 3];
                        v.iter()
                            .all(|x| x.is_finite())
                            .then(|| Vector3::new(v[0], v[1], v[2]))
                    };
                    let angle = h.angle(&mut placed, &u);
                    let axis = nalgebra::Unit::new_unchecked(u);
                    let back = UnitQuaternion::from_axis_angle(&axis, -angle);
                    for p in out[at..at + self.points * 3].chunks_exact_mut(3) {
                        let v = back * Vector3::new(p[0], p[1], p[2]);
                        p.copy_from_slice(v.as_slice());
                    }
                    let ahead = UnitQuaternion::from_axis_angle(&axis, angle) * h.forward;
                    out.extend((0..3).map(|a| ground[a] + ahead[a] * self.ahead));
                }
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
pub struct SkeletonPose {
    joints: Vec<Joint>,
    source: Vec<Joint>,
    root: Root,
    up: Axis,
    floor: f64,
    /// The pelvis's joints (their centroid is its place, as a marker take's pelvis points
    /// are), and FK to find them each frame (root motion only).
    pelvis: Vec<usize>,
    fk: Fk,
    placed: Vec<f64>,
    /// The root's position channel of each axis (root motion only).
    root_position: [Option<usize>; 3],
    turn: Option<Turn>,
    /// Extract's heading, when the body tells which way it faces and the root has three
    /// Euler channels to take the turn back from.
    heading: Option<Heading>,
    scale: f64,
    /// Channels of the written skeleton that are positions (scaled).
    positions: Vec<bool>,
}

/// The turn of an extracted root motion about up: from the body's forward to the way its
/// hips and shoulders face in each frame. A skeleton's root motion joint carries it, and
/// its root has it taken back, so that every joint stays where it was.
#[derive(Debug, Clone)]
struct Heading {
    facing: Facing,
    /// The root's three Euler channels (offsets in its channels) and their order.
    at: [usize; 3],
    order: [usize; 3],
}

/// The way a body faces, frame after frame: the turn about up from its forward.
#[derive(Debug, Clone)]
struct Facing {
    forward: Vector3<f64>,
    sides: Vec<(Vec<usize>, Vec<usize>)>,
    /// The last frame's heading (radians), for continuity across ±180°.
    last: Option<f64>,
}

impl Facing {
    /// The heading (radians about `up`) of the frame whose points are placed by `placed`
    /// (`None`: missing there), or the last one when no side pair is placed.
    fn angle(
        &mut self,
        placed: &mut dyn FnMut(usize) -> Option<Vector3<f64>>,
        up: &Vector3<f64>,
    ) -> f64 {
        let mut at = |set: &[usize]| -> Option<Vector3<f64>> {
            let found: Vec<Vector3<f64>> = set.iter().filter_map(|&j| placed(j)).collect();
            (!found.is_empty()).then(|| found.iter().sum::<Vector3<f64>>() / found.len() as f64)
        };
        let mut across = Vector3::zeros();
        for (l, r) in &self.sides {
            let (Some(a), Some(b)) = (at(l), at(r)) else {
                continue;
            };
            let d = b - a;
            let flat = d - up * d.dot(up);
            if flat.norm() > 0.0 {
                across += flat.normalize();
            }
        }
        let facing = up.cross(&across);
        let last = self.last.unwrap_or(0.0);
        if facing.norm() == 0.0 {
            return last;
        }
        let mut h = up
            .dot(&self.forward.cross(&facing))
            .atan2(self.forward.dot(&facing));
        // The nearest turn to the last one: no jump of 360° when the body turns about.
        h += std::f64::consts::TAU * ((last - h) / std::f64::consts::TAU).round();
        self.last = Some(h);
        h
    }
}

/// How the root turns to other axes.
#[derive(Debug, Clone)]
struct Turn {
    /// The up axis turned to.
    to: Axis,
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

/// `joint`'s channels, spelled out for an error message.
fn channel_list(joint: &Joint) -> String {
    joint
        .channels
        .iter()
        .map(|c| c.name())
        .collect::<Vec<_>>()
        .join(" ")
}

impl SkeletonPose {
    /// The transform of `options` for `joints` of a take whose body is `stance` (its pelvis
    /// a joint index), in `metres_per_unit`. Other axes need a root with three Euler
    /// channels and three position channels (what BVH roots have), root motion a root with
    /// position channels across up (and along it, to extract); another root is refused,
    /// saying why, as is a body that does not tell what the options need.
    pub fn new(
        options: &Options,
        joints: &[Joint],
        stance: &Stance,
        metres_per_unit: f64,
    ) -> Result<SkeletonPose, Error> {
        let root = joints
            .first()
            .ok_or_else(|| Error::Contradiction("the skeleton has no joints".into()))?;
        let up = working_up(options, stance)?;
        let pos = |axis: usize| root.channels.iter().position(|c| c.axis() == (axis, false));
        let root_position = [pos(0), pos(1), pos(2)];
        if let Some(&p) = stance
            .sides
            .iter()
            .flat_map(|(l, r)| l.iter().chain(r))
            .find(|&&p| p >= joints.len())
        {
            return Err(Error::Contradiction(format!(
                "a side is joint {p} of a skeleton of {}",
                joints.len()
            )));
        }
        let pelvis = match options.root {
            Root::Keep => Vec::new(),
            r => {
                let p = stance.pelvis_for(r)?.to_vec();
                if let Some(&j) = p.iter().find(|&&j| j >= joints.len()) {
                    return Err(Error::Contradiction(format!(
                        "the pelvis is joint {j} of a skeleton of {}",
                        joints.len()
                    )));
                }
                let mut needed = up.across().to_vec();
                if r == Root::Extract {
                    needed.push(up.index());
                }
                if needed.iter().any(|&a| root_position[a].is_none()) {
                    return Err(Error::Unsupported(format!(
                        "root={r} moves the root joint's position channels, and {:?} has {}",
                        root.name,
                        channel_list(root)
                    )));
                }
                p
            }
        };
        let turn = match options.up.and_then(|to| up.turn_to(to)) {
            None => None,
            Some(m) => {
                let rot: Vec<usize> = (0..root.channels.len())
                    .filter(|&c| root.channels[c].rotation_axis().is_some())
                    .collect();
                match (euler_order(&root.channels), root_position) {
                    (Some(order), [Some(x), Some(y), Some(z)]) if rot.len() == 3 => Some(Turn {
                        to: options.up.expect("a turn has a target"),
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
                        return Err(Error::Unsupported(format!(
                            "up={} needs a root joint with three rotation and three position \
                             channels; {:?} has {}",
                            options.up.map_or("", Axis::name),
                            root.name,
                            channel_list(root)
                        )))
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
        let rotations: Vec<usize> = (0..root.channels.len())
            .filter(|&c| root.channels[c].rotation_axis().is_some())
            .collect();
        let heading = match (options.root, stance.forward, euler_order(&root.channels)) {
            (Root::Extract, Some(f), Some(order))
                if rotations.len() == 3 && !stance.sides.is_empty() =>
            {
                Some(Heading {
                    facing: Facing {
                        forward: f.vector(),
                        sides: stance.sides.clone(),
                        last: None,
                    },
                    at: [rotations[0], rotations[1], rotations[2]],
                    order,
                })
            }
            _ => None,
        };
        if options.root == Root::Extract {
            for j in &mut out {
                j.parent = Some(j.parent.map_or(0, |p| p + 1));
            }
            let mut channels = vec![Channel::Xposition, Channel::Yposition, Channel::Zposition];
            if heading.is_some() {
                // About the written up: the take's, or the one it is turned to.
                let written = options.up.unwrap_or(up);
                channels.push(
                    [Channel::Xrotation, Channel::Yrotation, Channel::Zrotation][written.index()],
                );
            }
            out.insert(
                0,
                Joint {
                    name: ROOT_MOTION.into(),
                    parent: None,
                    offset: [0.0; 3],
                    channels,
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
            floor: stance.floor,
            pelvis,
            fk: Fk::new(joints),
            placed: vec![0.0; joints.len() * 3],
            root_position,
            turn,
            heading,
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
        let mut ground = [0.0; 3];
        let mut yaw = None;
        let mut vals = src.to_vec();
        if self.root != Root::Keep {
            // The root's translation is in world coordinates: moving it by the pelvis's
            // horizontal place moves the whole body so that the pelvis stands over zero.
            self.fk.frame(&self.source, src, &mut self.placed);
            let mut path = [0.0; 3];
            for &j in &self.pelvis {
                for (a, v) in path.iter_mut().enumerate() {
                    *v += self.placed[j * 3 + a] / self.pelvis.len() as f64;
                }
            }
            path[self.up.index()] = 0.0;
            if self.root == Root::Extract {
                ground = on_level(path, self.up, self.floor);
                path = ground;
            }
            for (a, moved) in path.iter().enumerate() {
                if let Some(c) = self.root_position[a] {
                    vals[c] -= moved;
                }
            }
            if let Some(h) = &mut self.heading {
                // The root, now the root motion's child, in its frame: its place and its
                // rotation turned back by the heading.
                let u = self.up.vector();
                let placed = &self.placed;
                let angle = h.facing.angle(
                    &mut |j| {
                        Some(Vector3::new(
                            placed[j * 3],
                            placed[j * 3 + 1],
                            placed[j * 3 + 2],
                        ))
                    },
                    &u,
                );
                let back =
                    UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(u), -angle);
                let p = self
                    .root_position
                    .map(|c| c.expect("extract has all three"));
                let t = back * Vector3::new(vals[p[0]], vals[p[1]], vals[p[2]]);
                for a in 0..3 {
                    vals[p[a]] = t[a];
                }
                let e = [vals[h.at[0]], vals[h.at[1]], vals[h.at[2]]];
                let e = to_euler(&(back * from_euler(h.order, e)), h.order, Some(e));
                for (k, v) in h.at.iter().zip(e) {
                    vals[*k] = v;
                }
                yaw = Some(angle);
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
            ground = (turn.m * Vector3::from(ground)).into();
        }
        let at = out.len();
        if self.root == Root::Extract {
            out.extend_from_slice(&ground);
            if let Some(angle) = yaw {
                // About the written up axis, signed as it is.
                let written = self.turn.as_ref().map_or(self.up, |t| t.to);
                out.push(angle.to_degrees() * written.sign());
            }
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

    /// Y-up, the pelvis the root (joint 0), the floor at zero.
    fn stance() -> Stance {
        Stance {
            up: Some(Axis::Y),
            pelvis: vec![0],
            floor: 0.0,
            ..Stance::default()
        }
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
        let mut inplace =
            SkeletonPose::new(&opts(Root::InPlace), &s.joints, &stance(), 0.01).unwrap();
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
        let mut extract =
            SkeletonPose::new(&opts(Root::Extract), &s.joints, &stance(), 0.01).unwrap();
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
        let mut pp = PointPose::new(&opts(Root::Extract), n, &stance(), 0.01).unwrap();
        let mut out = Vec::new();
        pp.frame(&src[..n * 3], &mut out);
        assert_eq!(out.len(), (n + 1) * 3);
        assert_eq!(out[0], 0.0);
        assert_eq!(&out[n * 3..], &[src[0], 0.0, src[2]]);
        let no_pelvis = Stance {
            pelvis: Vec::new(),
            ..stance()
        };
        assert!(matches!(
            PointPose::new(&opts(Root::InPlace), n, &no_pelvis, 0.01),
            Err(Error::Unsupported(_))
        ));
        let no_up = Stance {
            up: None,
            ..stance()
        };
        assert!(PointPose::new(&opts(Root::InPlace), n, &no_up, 0.01).is_err());
        assert!(PointPose::new(&opts(Root::Keep), n, &no_up, 0.01).is_ok());
    }

    /// Another up axis and unit on the channels gives FK's positions turned and scaled.
    #[test]
    fn axes_and_units_on_channels_match_positions() {
        let s = skeleton();
        let src = s.forward_kinematics();
        let opts = Options {
            up: Some(Axis::Z),
            metres_per_unit: Some(0.001),
            ..Options::default()
        };
        let mut pose = SkeletonPose::new(&opts, &s.joints, &stance(), 0.01).unwrap();
        let vals = apply(&mut pose, &s);
        let pos = fk(pose.joints(), &vals);
        let mut pp = PointPose::new(&opts, src.len() / 3, &stance(), 0.01).unwrap();
        let mut want = Vec::new();
        pp.frame(&src, &mut want);
        for (i, (a, b)) in want.iter().zip(&pos).enumerate() {
            assert!((a - b).abs() < 1e-6, "value {i}: {a} vs {b}");
        }
        // Y-up (x, y, z) is Z-up (x, −z, y), in ten times as many units.
        assert!((want[1] + src[2] * 10.0).abs() < 1e-9 && (want[2] - src[1] * 10.0).abs() < 1e-9);
    }

    /// A rig whose root joint stays at the origin while its child, the pelvis, walks (as
    /// Bandai Namco's `joint_Root` and `Hips`): in place, the pelvis stands over zero in
    /// every frame and every joint keeps its place relative to it; extracted, the path runs
    /// on the floor and FK gives back the source.
    #[test]
    fn root_motion_follows_the_pelvis_not_the_root_joint() {
        let s = skeleton();
        let mut joints = vec![Joint {
            name: "joint_Root".into(),
            parent: None,
            offset: [0.0; 3],
            channels: vec![
                Channel::Xposition,
                Channel::Yposition,
                Channel::Zposition,
                Channel::Zrotation,
                Channel::Xrotation,
                Channel::Yrotation,
            ],
            end_site: false,
        }];
        joints.extend(s.joints.iter().cloned().map(|mut j| {
            j.parent = Some(j.parent.map_or(0, |p| p + 1));
            j
        }));
        let cc = s.channel_count();
        let values: Vec<f64> = (0..s.frame_count())
            .flat_map(|f| {
                [0.0; 6]
                    .into_iter()
                    .chain(s.values[f * cc..(f + 1) * cc].iter().copied())
            })
            .collect();
        let rig = Animation::new(joints, values).unwrap();
        let n = rig.joints.len();
        let src = rig.forward_kinematics();
        let walked = (src[(s.frame_count() - 1) * n * 3 + 3] - src[3]).abs();
        assert!(walked > 1.0, "the pelvis walks {walked}");
        let stance = Stance {
            up: Some(Axis::Y),
            pelvis: vec![1],
            floor: -90.0,
            ..Stance::default()
        };
        let opts = |root| Options {
            root,
            ..Options::default()
        };
        let mut inplace =
            SkeletonPose::new(&opts(Root::InPlace), &rig.joints, &stance, 0.01).unwrap();
        let vals = apply(&mut inplace, &rig);
        let pos = fk(inplace.joints(), &vals);
        for f in 0..rig.frame_count() {
            let (a, b) = (&src[f * n * 3..][..n * 3], &pos[f * n * 3..][..n * 3]);
            assert!(
                b[3].abs() < 1e-9 && b[5].abs() < 1e-9,
                "frame {f}: {:?}",
                &b[3..6]
            );
            assert!((a[4] - b[4]).abs() < 1e-9, "height kept");
            for j in 0..n {
                for k in 0..3 {
                    let rel = |v: &[f64]| v[j * 3 + k] - v[3 + k];
                    assert!((rel(a) - rel(b)).abs() < 1e-9);
                }
            }
        }
        let mut extract =
            SkeletonPose::new(&opts(Root::Extract), &rig.joints, &stance, 0.01).unwrap();
        let vals = apply(&mut extract, &rig);
        let pos = fk(extract.joints(), &vals);
        for f in 0..rig.frame_count() {
            let b = &pos[f * (n + 1) * 3..][..(n + 1) * 3];
            let a = &src[f * n * 3..][..n * 3];
            assert_eq!(
                [b[0], b[1], b[2]],
                [a[3], -90.0, a[5]],
                "the path on the floor"
            );
            for (x, y) in a.iter().zip(&b[3..]) {
                assert!((x - y).abs() < 1e-9);
            }
        }
        // Positions: the same, by the pelvis point.
        let mut pp = PointPose::new(&opts(Root::InPlace), n, &stance, 0.01).unwrap();
        let mut out = Vec::new();
        pp.frame(&src[(rig.frame_count() - 1) * n * 3..], &mut out);
        assert!(out[3].abs() < 1e-9 && out[5].abs() < 1e-9);
    }

    /// Extract with the heading apart and another up: the root motion turns about the
    /// written up, and every joint lands where the source's FK turned puts it, in every
    /// frame of a dancer turning about; its point form gives the same body back.
    #[test]
    fn the_heading_apart_turned_to_another_up() {
        let m = crate::motion::synthetic::dancer(240, 60.0, 8);
        let body = crate::motion::body::Body::of(&m, Default::default(), None).unwrap();
        let stance = Stance::of(&body, &m.point_names, m.unit.metres_per_unit);
        assert!(stance.forward.is_some() && !stance.sides.is_empty());
        let s = m.skeleton.as_ref().unwrap();
        let options = Options {
            root: Root::Extract,
            up: Some(Axis::Z.flipped()),
            ..Options::default()
        };
        let mut pose = SkeletonPose::new(&options, &s.joints, &stance, 0.01).unwrap();
        let root_motion = &pose.joints()[0];
        assert_eq!(root_motion.channels.len(), 4);
        assert_eq!(root_motion.channels[3].rotation_axis(), Some(2));
        let out = Animation::new(pose.joints().to_vec(), apply(&mut pose, s)).unwrap();
        let (a, b) = (s.forward_kinematics(), out.forward_kinematics());
        let n = s.joints.len();
        let turn = Axis::Y.turn_to(Axis::Z.flipped()).unwrap();
        let mut yaws = Vec::new();
        for f in 0..s.frame_count() {
            for j in 0..n {
                let i = (f * n + j) * 3;
                let want = turn * Vector3::new(a[i], a[i + 1], a[i + 2]);
                let k = (f * (n + 1) + j + 1) * 3;
                let got = Vector3::new(b[k], b[k + 1], b[k + 2]);
                assert!(
                    (want - got).norm() < 1e-6,
                    "frame {f} joint {j}: {want} vs {got}"
                );
            }
            yaws.push(out.frame_values(f)[3]);
        }
        let span = yaws.iter().cloned().fold(f64::MIN, f64::max)
            - yaws.iter().cloned().fold(f64::MAX, f64::min);
        assert!(span > 5.0, "the dancer turns: {span}°");
        // The points: the body turned back about its pelvis, the path and the heading ahead.
        let mut points = PointPose::new(&options, n, &stance, 0.01).unwrap();
        assert_eq!(points.extra_names(), [ROOT_MOTION, ROOT_MOTION_FORWARD]);
        let mut got = Vec::new();
        points.frame(&a[..n * 3], &mut got);
        assert_eq!(got.len(), (n + 2) * 3);
        let (path, ahead) = (&got[n * 3..n * 3 + 3], &got[n * 3 + 3..]);
        let d = Vector3::new(ahead[0] - path[0], ahead[1] - path[1], ahead[2] - path[2]);
        assert!(
            (d.norm() - ROOT_MOTION_FORWARD_M / 0.01).abs() < 1e-6,
            "{d}"
        );
        assert!(d[2].abs() < 1e-9, "on the floor of the written up: {d}");
    }
}
