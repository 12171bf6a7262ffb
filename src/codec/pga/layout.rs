//! How a skeleton's channels map onto what `pga` codes: the root's position and rotation,
//! the rotations of the inner joints (every other joint that turns), and the end points IK
//! aims (End Sites and leaf joints); and back.
//!
//! PGA keeps bones rigid, so position channels below the root must hold one value for the
//! whole take (exporters such as Bandai's and Blender's write the offset again on every
//! joint); those values become part of the bones. The root is the joint that moves: the
//! rig's own, or one below joints that hold still throughout (Bandai's `joint_Root`). A
//! joint that turns about fewer or other than three axes, or a moving position channel
//! below the root, makes the take unsuited.

use nalgebra::{UnitQuaternion, Vector3};

use super::ik::{Chain, Link};
use crate::codec::skeleton::Skeleton;
use crate::motion::rotation::{euler_order, from_euler, to_euler};

/// A joint whose rotation is three Euler channels.
#[derive(Debug, Clone, Copy)]
struct Turning {
    order: [usize; 3],
    /// Its rotation channels' indices in a frame, in channel order.
    idx: [usize; 3],
}

/// The mapping for one rig and take.
#[derive(Debug, Clone)]
pub struct Layout {
    channels: usize,
    /// The joint PGA codes from (link 0 of the chain); the joints above it hold still.
    root: usize,
    /// The root's position channels (x, y, z; `None` where the offset holds).
    root_position: [Option<usize>; 3],
    root_offset: Vector3<f64>,
    root_rotation: Option<Turning>,
    /// The inner joints, in rig order: the [`Geodesics`](super::model::Geodesics) joints.
    inner: Vec<Turning>,
    /// Every channel above the root and the position channels below it, with the value
    /// each holds.
    constants: Vec<(usize, f64)>,
    chain: Chain,
}

impl Layout {
    /// The layout of `rig` for a take of `frames` frames of `values`; the reason when PGA
    /// cannot code it.
    ///
    /// The root PGA codes from is the joint that moves: the rig's root, or the one joint
    /// below it whose position channels move when everything above it holds still (Bandai
    /// Namco's files hang `Hips` under a `joint_Root` that never moves).
    pub fn new(rig: &Skeleton, values: &[f64], frames: usize) -> Result<Layout, String> {
        let joints = rig.joints();
        let cc = rig.channel_count();
        if frames == 0 {
            return Err("the take has no frames".into());
        }
        if values.len() != frames * cc {
            return Err(format!(
                "{} channel values for {frames} frames of {cc}",
                values.len()
            ));
        }
        // Exporters print "constant" offsets with noise in the last digits (Bandai's vary
        // by 10⁻¹²): a channel within a millionth of its first value holds still, and the
        // bound is verified on the decoded take anyway.
        let moves = |i: usize| {
            let v0 = values[i];
            (1..frames).any(|f| (values[f * cc + i] - v0).abs() > 1e-6 * (1.0 + v0.abs()))
        };
        let mut first = 0;
        let mut movers = Vec::new();
        let mut firsts = Vec::with_capacity(joints.len());
        for (j, joint) in joints.iter().enumerate() {
            firsts.push(first);
            if j > 0
                && joint
                    .channels
                    .iter()
                    .enumerate()
                    .any(|(c, ch)| !ch.axis().1 && moves(first + c))
            {
                movers.push(j);
            }
            first += joint.channels.len();
        }
        // The channel that moves first in joint `j`'s, by name.
        let moving = |j: usize, rotations: bool| {
            joints[j]
                .channels
                .iter()
                .enumerate()
                .find(|(c, ch)| (rotations || !ch.axis().1) && moves(firsts[j] + c))
                .map_or("position", |(_, ch)| ch.name())
        };
        let root = match movers[..] {
            [] => 0,
            [r] if everything_below(rig, r) => {
                if let Some(a) =
                    (0..r).find(|&a| (firsts[a]..firsts[a] + joints[a].channels.len()).any(&moves))
                {
                    return Err(format!(
                        "joint {} moves and so does {}'s {} channel above it; pga codes one \
                         moving root",
                        joints[r].name,
                        joints[a].name,
                        moving(a, true)
                    ));
                }
                r
            }
            _ => {
                let j = movers[movers.len().min(2) - 1];
                return Err(format!(
                    "joint {}'s {} channel moves, and pga keeps bones rigid",
                    joints[j].name,
                    moving(j, false)
                ));
            }
        };
        let constants: Vec<(usize, f64)> = constant_channels(rig, root)
            .into_iter()
            .map(|i| (i, values[i]))
            .collect();
        Layout::with_constants(rig, root, &constants)
    }

    /// The layout of `rig` from joint `root` whose other channels that do not turn a joint
    /// below it, and every channel above it, hold `constants` (channel index and value, in
    /// channel order: what [`Layout::constants`] gives and the stored parameters keep); the
    /// reason when PGA cannot code the rig or the list does not name exactly those channels.
    pub fn with_constants(
        rig: &Skeleton,
        root: usize,
        constants: &[(usize, f64)],
    ) -> Result<Layout, String> {
        let joints = rig.joints();
        let cc = rig.channel_count();
        if joints.is_empty() || joints[0].parent.is_some() {
            return Err("the skeleton has no root".into());
        }
        if !everything_below(rig, root) {
            return Err(format!(
                "joint {root} is not a root with everything else below it"
            ));
        }
        let wanted = constant_channels(rig, root);
        if constants.len() != wanted.len()
            || constants
                .iter()
                .zip(&wanted)
                .any(|(&(i, v), &w)| i != w || !v.is_finite())
        {
            return Err("the constant channels do not match the skeleton's".into());
        }
        let mut value = vec![None; cc];
        for &(i, v) in constants {
            value[i] = Some(v);
        }
        let mut first: usize = joints[..root].iter().map(|j| j.channels.len()).sum();
        let mut root_position = [None; 3];
        let mut root_rotation = None;
        let mut inner = Vec::new();
        let mut links = Vec::with_capacity(joints.len() - root);
        for (j, joint) in joints.iter().enumerate().skip(root) {
            let mut translation = Vector3::from(joint.offset);
            let mut rot_idx = Vec::new();
            for (c, ch) in joint.channels.iter().enumerate() {
                let i = first + c;
                let (axis, rotation) = ch.axis();
                if rotation {
                    rot_idx.push(i);
                } else if j == root {
                    root_position[axis] = Some(i);
                } else if let Some(v) = value[i] {
                    translation[axis] = v;
                }
            }
            let turning = match (rot_idx.len(), euler_order(&joint.channels)) {
                (0, _) => None,
                (3, Some(order)) => Some(Turning {
                    order,
                    idx: [rot_idx[0], rot_idx[1], rot_idx[2]],
                }),
                (n, _) => {
                    return Err(format!(
                        "joint {} turns by {n} rotation channels; pga needs three about three axes",
                        joint.name
                    ))
                }
            };
            let mut index = None;
            if j == root {
                root_rotation = turning;
            } else if let Some(t) = turning {
                index = Some(inner.len());
                inner.push(t);
            }
            links.push(Link {
                parent: joint.parent.filter(|_| j > root).map(|p| p - root),
                translation: if j == root {
                    Vector3::zeros()
                } else {
                    translation
                },
                inner: index,
            });
            first += joint.channels.len();
        }
        if inner.is_empty() {
            return Err("no joint below the root turns".into());
        }
        let mut has_child = vec![false; links.len()];
        for l in &links {
            if let Some(p) = l.parent {
                has_child[p] = true;
            }
        }
        let ends: Vec<usize> = (1..links.len()).filter(|&j| !has_child[j]).collect();
        let chain = Chain::new(links, ends).ok_or("the skeleton's joints are out of order")?;
        Ok(Layout {
            channels: cc,
            root,
            root_position,
            root_offset: Vector3::from(joints[root].offset),
            root_rotation,
            inner,
            constants: constants.to_vec(),
            chain,
        })
    }

    /// The IK chain (root at the origin, in the root's frame).
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// The joints whose Euler triples are decoded (the root's rotation and the inner
    /// joints'), for their [`branches`](crate::codec::branches).
    pub fn turnings(&self) -> Vec<crate::codec::branches::Turning> {
        self.root_rotation
            .iter()
            .chain(&self.inner)
            .map(|t| crate::codec::branches::Turning {
                idx: t.idx,
                order: t.order,
            })
            .collect()
    }

    /// The number of inner joints.
    pub fn inner_count(&self) -> usize {
        self.inner.len()
    }

    /// One frame's channel values as the root's position and rotation and the inner joints'
    /// rotations (into `inner`).
    pub fn split(
        &self,
        values: &[f64],
        inner: &mut [UnitQuaternion<f64>],
    ) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let mut p = self.root_offset;
        for (axis, i) in self.root_position.iter().enumerate() {
            if let Some(i) = i {
                p[axis] = values[*i];
            }
        }
        let r = self
            .root_rotation
            .map_or(UnitQuaternion::identity(), |t| rotation(&t, values));
        for (q, t) in inner.iter_mut().zip(&self.inner) {
            *q = rotation(t, values);
        }
        (p, r)
    }

    /// One frame's channel values from the root's position and rotation and the inner
    /// joints' rotations, Euler angles nearest `previous` (the frame before, if any).
    pub fn join(
        &self,
        root: (Vector3<f64>, UnitQuaternion<f64>),
        inner: &[UnitQuaternion<f64>],
        previous: Option<&[f64]>,
        out: &mut [f64],
    ) {
        for (axis, i) in self.root_position.iter().enumerate() {
            if let Some(i) = i {
                out[*i] = root.0[axis];
            }
        }
        let euler = |t: &Turning, q: &UnitQuaternion<f64>, out: &mut [f64]| {
            let near = previous.map(|p| [p[t.idx[0]], p[t.idx[1]], p[t.idx[2]]]);
            let e = to_euler(q, t.order, near);
            for k in 0..3 {
                out[t.idx[k]] = e[k];
            }
        };
        if let Some(t) = &self.root_rotation {
            euler(t, &root.1, out);
        }
        for (t, q) in self.inner.iter().zip(inner) {
            euler(t, q, out);
        }
        for &(i, v) in &self.constants {
            out[i] = v;
        }
    }

    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The channels that hold one value (every channel above the root, the position
    /// channels below it) and their values, in channel order.
    pub fn constants(&self) -> &[(usize, f64)] {
        &self.constants
    }

    /// The joint PGA codes from.
    pub fn root(&self) -> usize {
        self.root
    }
}

/// Whether the joints above `root` form one chain down to it and every other joint hangs
/// below it.
fn everything_below(rig: &Skeleton, root: usize) -> bool {
    let joints = rig.joints();
    root < joints.len()
        && (1..=root).all(|j| joints[j].parent == Some(j - 1))
        && joints[root + 1..]
            .iter()
            .all(|j| j.parent.is_some_and(|p| p >= root))
}

/// The channels [`Layout::with_constants`] wants values for, in channel order: every
/// channel above `root`, and the channels below it that do not turn a joint.
fn constant_channels(rig: &Skeleton, root: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut first = 0;
    for (j, joint) in rig.joints().iter().enumerate() {
        for (c, ch) in joint.channels.iter().enumerate() {
            if j < root || (j > root && !ch.axis().1) {
                out.push(first + c);
            }
        }
        first += joint.channels.len();
    }
    out
}

fn rotation(t: &Turning, values: &[f64]) -> UnitQuaternion<f64> {
    from_euler(
        t.order,
        [values[t.idx[0]], values[t.idx[1]], values[t.idx[2]]],
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::synthetic::dancer;

    #[test]
    fn split_and_join_give_the_same_pose_back() {
        let m = dancer(30, 60.0, 2);
        let sk = m.skeleton.as_ref().unwrap();
        let rig = Skeleton::new(sk.joints.clone()).unwrap();
        let l = Layout::new(&rig, &sk.values, 30).unwrap();
        let turning = sk.joints[1..]
            .iter()
            .filter(|j| euler_order(&j.channels).is_some())
            .count();
        assert!(turning > 5);
        assert_eq!(l.inner_count(), turning);
        assert!(!l.chain().ends().is_empty());
        let cc = rig.channel_count();
        let mut inner = vec![UnitQuaternion::identity(); l.inner_count()];
        let mut back = vec![0.0; 30 * cc];
        for f in 0..30 {
            let root = l.split(sk.frame_values(f), &mut inner);
            let (done, rest) = back.split_at_mut(f * cc);
            let previous = (f > 0).then(|| &done[(f - 1) * cc..]);
            l.join(root, &inner, previous, &mut rest[..cc]);
        }
        let mut a = vec![0f32; m.positions().len()];
        rig.positions(&back, &mut a);
        for (x, y) in a.iter().zip(m.positions()) {
            assert!((x - y).abs() < 1e-4);
        }
    }

    /// Bandai Namco's shape: a root that never moves above the `Hips` that do.
    #[test]
    fn a_still_root_above_the_moving_joint_codes_from_that_joint() {
        use crate::motion::skeleton::{Channel, Joint};
        let frames = 30;
        let m = dancer(frames, 60.0, 4);
        let sk = m.skeleton.as_ref().unwrap();
        let mut joints = vec![Joint {
            name: "Top".into(),
            parent: None,
            offset: [0.0, 0.0, 0.0],
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
        for j in &sk.joints {
            let mut j = j.clone();
            j.parent = Some(j.parent.map_or(0, |p| p + 1));
            joints.push(j);
        }
        let still = [3.0, -2.0, 1.0, 10.0, 0.0, 5.0];
        let mut values = Vec::new();
        for f in 0..frames {
            values.extend_from_slice(&still);
            values.extend_from_slice(sk.frame_values(f));
        }
        let rig = Skeleton::new(joints).unwrap();
        let l = Layout::new(&rig, &values, frames).unwrap();
        assert_eq!(l.root(), 1);
        assert_eq!(
            &l.constants()[..6],
            &[(0, 3.0), (1, -2.0), (2, 1.0), (3, 10.0), (4, 0.0), (5, 5.0)]
        );
        let cc = rig.channel_count();
        let mut inner = vec![UnitQuaternion::identity(); l.inner_count()];
        let mut back = vec![0.0; frames * cc];
        for f in 0..frames {
            let root = l.split(&values[f * cc..(f + 1) * cc], &mut inner);
            let (done, rest) = back.split_at_mut(f * cc);
            let previous = (f > 0).then(|| &done[(f - 1) * cc..]);
            l.join(root, &inner, previous, &mut rest[..cc]);
        }
        let (mut a, mut b) = (vec![0f32; frames * rig.joints().len() * 3], vec![0f32; 0]);
        b.resize(a.len(), 0.0);
        rig.positions(&back, &mut a);
        rig.positions(&values, &mut b);
        assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-4));
        // Moving the top joint too leaves no joint to code from.
        values[cc] = 4.0;
        let e = Layout::new(&rig, &values, frames).unwrap_err();
        assert!(e.contains("moves") && e.contains("Top's Xposition"), "{e}");
    }

    #[test]
    fn moving_position_channels_below_the_root_are_refused_by_name() {
        let m = dancer(10, 60.0, 2);
        let sk = m.skeleton.as_ref().unwrap();
        let mut joints = sk.joints.clone();
        // Give joint 1 a position channel that moves.
        joints[1]
            .channels
            .insert(0, crate::motion::skeleton::Channel::Xposition);
        let rig = Skeleton::new(joints.clone()).unwrap();
        let cc = rig.channel_count();
        let first: usize = joints[0].channels.len();
        let mut values = vec![0.0; 10 * cc];
        for f in 0..10 {
            values[f * cc + first] = f as f64;
        }
        let e = Layout::new(&rig, &values, 10).unwrap_err();
        assert!(
            e.contains(&joints[1].name) && e.contains("Xposition"),
            "{e}"
        );
    }
}
