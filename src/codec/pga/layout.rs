//! How a skeleton's channels map onto what `pga` codes: the root's position and rotation,
//! the rotations of the inner joints (every other joint that turns), and the end points IK
//! aims (End Sites and leaf joints); and back.
//!
//! PGA keeps bones rigid, so position channels below the root must hold one value for the
//! whole take (exporters such as Bandai's and Blender's write the offset again on every
//! joint); those values become part of the bones. A joint that turns about fewer or other
//! than three axes, or a moving position channel below the root, makes the take unsuited.

use nalgebra::{UnitQuaternion, Vector3};

use super::ik::{Chain, Link};
use crate::codec::rig::Rig;
use crate::motion::rotation::{euler_order, from_euler, to_euler};

/// A joint whose rotation is three Euler channels.
#[derive(Debug, Clone, Copy)]
struct Turning {
    joint: usize,
    order: [usize; 3],
    /// Its rotation channels' indices in a frame, in channel order.
    idx: [usize; 3],
}

/// The mapping for one rig and take.
#[derive(Debug, Clone)]
pub struct Layout {
    channels: usize,
    /// The root's position channels (x, y, z; `None` where the offset holds).
    root_position: [Option<usize>; 3],
    root_offset: Vector3<f64>,
    root_rotation: Option<Turning>,
    /// The inner joints, in rig order: the [`Geodesics`](super::model::Geodesics) joints.
    inner: Vec<Turning>,
    /// Position channels below the root and the value they hold.
    constants: Vec<(usize, f64)>,
    chain: Chain,
}

impl Layout {
    /// The layout of `rig` for a take of `frames` frames of `values`; the reason when PGA
    /// cannot code it.
    pub fn new(rig: &Rig, values: &[f64], frames: usize) -> Result<Layout, String> {
        let joints = rig.joints();
        let cc = rig.channel_count();
        if joints.is_empty() || joints[0].parent.is_some() || frames == 0 {
            return Err("the skeleton has no root".into());
        }
        if values.len() != frames * cc {
            return Err(format!(
                "{} channel values for {frames} frames of {cc}",
                values.len()
            ));
        }
        let mut first = 0;
        let mut root_position = [None; 3];
        let mut root_rotation = None;
        let mut inner = Vec::new();
        let mut constants = Vec::new();
        let mut links = Vec::with_capacity(joints.len());
        for (j, joint) in joints.iter().enumerate() {
            let mut translation = Vector3::from(joint.offset);
            let mut rot_idx = Vec::new();
            for (c, ch) in joint.channels.iter().enumerate() {
                let i = first + c;
                let (axis, rotation) = ch.axis();
                if rotation {
                    rot_idx.push(i);
                } else if j == 0 {
                    root_position[axis] = Some(i);
                } else {
                    let v = values[i];
                    if (1..frames).any(|f| values[f * cc + i] != v) {
                        return Err(format!(
                            "joint {}'s {} channel moves, and pga keeps bones rigid",
                            joint.name,
                            ch.name()
                        ));
                    }
                    translation[axis] = v;
                    constants.push((i, v));
                }
            }
            let turning = match (rot_idx.len(), euler_order(&joint.channels)) {
                (0, _) => None,
                (3, Some(order)) => Some(Turning {
                    joint: j,
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
            if j == 0 {
                root_rotation = turning;
            } else if let Some(t) = turning {
                index = Some(inner.len());
                inner.push(t);
            }
            links.push(Link {
                parent: joint.parent,
                translation: if j == 0 {
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
        let mut has_child = vec![false; joints.len()];
        for j in joints {
            if let Some(p) = j.parent {
                has_child[p] = true;
            }
        }
        let ends: Vec<usize> = (1..joints.len()).filter(|&j| !has_child[j]).collect();
        let chain = Chain::new(links, ends).ok_or("the skeleton's joints are out of order")?;
        Ok(Layout {
            channels: cc,
            root_position,
            root_offset: Vector3::from(joints[0].offset),
            root_rotation,
            inner,
            constants,
            chain,
        })
    }

    /// The IK chain (root at the origin, in the root's frame).
    pub fn chain(&self) -> &Chain {
        &self.chain
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

    /// The rig joint of inner joint `i`.
    pub fn inner_joint(&self, i: usize) -> usize {
        self.inner[i].joint
    }
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
        let rig = Rig::new(sk.joints.clone()).unwrap();
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

    #[test]
    fn moving_position_channels_below_the_root_are_refused_by_name() {
        let m = dancer(10, 60.0, 2);
        let sk = m.skeleton.as_ref().unwrap();
        let mut joints = sk.joints.clone();
        // Give joint 1 a position channel that moves.
        joints[1]
            .channels
            .insert(0, crate::motion::skeleton::Channel::Xposition);
        let rig = Rig::new(joints.clone()).unwrap();
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
