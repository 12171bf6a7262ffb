//! Joint hierarchies (as in BVH) and forward kinematics.
//!
//! A skeleton keeps exactly what a BVH file says — offsets, channel order, per-frame channel
//! values — so that a take can be written back as BVH, and computes joint positions from it.
//! FK runs in f64: positions are stored as f32 later, but accumulating rotations down a
//! 10-joint chain in f32 would already cost more precision than the codecs are allowed.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::decimal::PrintedValues;
use super::error::{Error, Result};

/// One animated degree of freedom, in the order the file lists them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

impl Channel {
    pub fn parse(name: &str) -> Option<Channel> {
        Some(match name.to_ascii_lowercase().as_str() {
            "xposition" => Channel::Xposition,
            "yposition" => Channel::Yposition,
            "zposition" => Channel::Zposition,
            "xrotation" => Channel::Xrotation,
            "yrotation" => Channel::Yrotation,
            "zrotation" => Channel::Zrotation,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Channel::Xposition => "Xposition",
            Channel::Yposition => "Yposition",
            Channel::Zposition => "Zposition",
            Channel::Xrotation => "Xrotation",
            Channel::Yrotation => "Yrotation",
            Channel::Zrotation => "Zrotation",
        }
    }

    /// The axis (0 = x, 1 = y, 2 = z) of a rotation channel.
    pub fn rotation_axis(self) -> Option<usize> {
        let (axis, rot) = self.axis();
        rot.then_some(axis)
    }

    /// The axis (0 = x, 1 = y, 2 = z) and whether it is a rotation.
    pub(crate) fn axis(self) -> (usize, bool) {
        match self {
            Channel::Xposition => (0, false),
            Channel::Yposition => (1, false),
            Channel::Zposition => (2, false),
            Channel::Xrotation => (0, true),
            Channel::Yrotation => (1, true),
            Channel::Zrotation => (2, true),
        }
    }
}

/// A joint or an end site. End sites have no channels; they are points all the same,
/// because end effectors (hands, feet, head top) are what a viewer notices first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Joint {
    pub name: String,
    pub parent: Option<usize>,
    pub offset: [f64; 3],
    pub channels: Vec<Channel>,
    pub end_site: bool,
}

/// Where each joint stands in the rest pose (offsets summed down the hierarchy, no
/// channels), in file units; joints parents first.
pub fn rest_places(joints: &[Joint]) -> Vec<[f64; 3]> {
    let mut pos: Vec<[f64; 3]> = Vec::with_capacity(joints.len());
    for j in joints {
        let base = j.parent.map(|p| pos[p]).unwrap_or([0.0; 3]);
        pos.push([
            base[0] + j.offset[0],
            base[1] + j.offset[1],
            base[2] + j.offset[2],
        ]);
    }
    pos
}

/// The channel values of the pose a hierarchy's offsets describe: rotations zero, and
/// position channels at their offset's component (they replace it: zero would put every
/// such joint on its parent). What a rig stands in when nothing moves it.
pub fn rest_values(joints: &[Joint]) -> Vec<f64> {
    joints
        .iter()
        .flat_map(|j| {
            j.channels.iter().map(|c| match c.axis() {
                (axis, false) => j.offset[axis],
                (_, true) => 0.0,
            })
        })
        .collect()
}

/// A hierarchy plus its per-frame channel values.
///
/// Joints are stored parents-first (the order of the BVH file), so FK is one forward pass.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Animation {
    pub joints: Vec<Joint>,
    /// `frames × channel_count()` values in file order: degrees for rotations, file units
    /// for positions.
    pub values: Vec<f64>,
    /// The same values as the file printed them, when read from text: what a lossless
    /// archive gives back character for character.
    #[serde(skip)]
    pub printed: Option<PrintedValues>,
}

impl Animation {
    pub fn new(joints: Vec<Joint>, values: Vec<f64>) -> Result<Self> {
        for (i, j) in joints.iter().enumerate() {
            if let Some(p) = j.parent {
                if p >= i {
                    return Err(Error::Invalid(format!(
                        "joint {:?} comes before its parent",
                        j.name
                    )));
                }
                if joints[p].end_site {
                    return Err(Error::Invalid(format!(
                        "joint {:?} has an end site as parent",
                        j.name
                    )));
                }
            } else if i != 0 {
                return Err(Error::Invalid(format!(
                    "joint {:?} has no parent but is not the root",
                    j.name
                )));
            }
            if j.end_site && !j.channels.is_empty() {
                return Err(Error::Invalid(format!(
                    "end site {:?} has channels",
                    j.name
                )));
            }
        }
        let s = Animation {
            joints,
            values,
            printed: None,
        };
        let cc = s.channel_count();
        if cc == 0 && !s.values.is_empty() || cc > 0 && !s.values.len().is_multiple_of(cc) {
            return Err(Error::Invalid(format!(
                "{} channel values do not fill whole frames of {cc} channels",
                s.values.len()
            )));
        }
        Ok(s)
    }

    pub fn channel_count(&self) -> usize {
        self.joints.iter().map(|j| j.channels.len()).sum()
    }

    pub fn frame_count(&self) -> usize {
        match self.channel_count() {
            0 => 0,
            cc => self.values.len() / cc,
        }
    }

    /// Joints that are not end sites: what BVH tools call "the joints".
    pub fn joint_count(&self) -> usize {
        self.joints.iter().filter(|j| !j.end_site).count()
    }

    pub fn frame_values(&self, frame: usize) -> &[f64] {
        let cc = self.channel_count();
        &self.values[frame * cc..(frame + 1) * cc]
    }

    /// Keep frames `start..end` only.
    pub fn slice_frames(&self, start: usize, end: usize) -> Animation {
        let cc = self.channel_count();
        Animation {
            joints: self.joints.clone(),
            values: self.values[start * cc..end * cc].to_vec(),
            printed: self.printed.as_ref().map(|p| p.slice(start, end, cc)),
        }
    }

    /// Keep the values as printed (`printed.values` one per value, in file order).
    pub fn with_printed(mut self, printed: PrintedValues) -> Result<Animation> {
        if printed.values.len() != self.values.len() {
            return Err(Error::Invalid(format!(
                "{} printed values for {} channel values",
                printed.values.len(),
                self.values.len()
            )));
        }
        self.printed = Some(printed);
        Ok(self)
    }

    /// The translation of each joint relative to its parent in one frame: the offset, with
    /// any position channel replacing its component. (Exporters such as Vicon and Bandai
    /// write position channels on every joint whose values repeat the offset, so replacing
    /// — not adding — is the reading that keeps bones rigid.)
    pub fn local_translations(&self, frame: usize, out: &mut Vec<[f64; 3]>) {
        local_translations(&self.joints, self.frame_values(frame), out);
    }

    /// Joint positions (file units) of every frame, `frames × joints × 3`, in f64.
    pub fn forward_kinematics(&self) -> Vec<f64> {
        let n = self.joints.len();
        let frames = self.frame_count();
        let mut out = vec![0.0; frames * n * 3];
        let mut fk = Fk::new(&self.joints);
        for f in 0..frames {
            fk.frame(
                &self.joints,
                self.frame_values(f),
                &mut out[f * n * 3..(f + 1) * n * 3],
            );
        }
        out
    }

    /// Height of the rest pose (offsets only, no channels) along the axis with the
    /// largest extent among Y (BVH's usual up axis) and Z; used to guess the unit.
    pub fn rest_height(&self) -> f64 {
        let pos = rest_places(&self.joints);
        let extent = |axis: usize| {
            let (lo, hi) = pos.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
                (lo.min(p[axis]), hi.max(p[axis]))
            });
            if pos.is_empty() {
                0.0
            } else {
                hi - lo
            }
        };
        // A T-pose is as wide as it is tall, so X is never taken as up.
        extent(1).max(extent(2))
    }
}

/// The translation of each joint relative to its parent in one frame (`vals`, that frame's
/// channel values): see [`Animation::local_translations`].
pub fn local_translations(joints: &[Joint], vals: &[f64], out: &mut Vec<[f64; 3]>) {
    out.clear();
    let mut k = 0;
    for j in joints {
        out.push(translation(j, &vals[k..k + j.channels.len()]));
        k += j.channels.len();
    }
}

/// One joint's translation from its parent: its offset, with any position channel (from
/// `vals`, the joint's own channel values) replacing its component.
pub fn translation(joint: &Joint, vals: &[f64]) -> [f64; 3] {
    let mut t = joint.offset;
    for (&c, &v) in joint.channels.iter().zip(vals) {
        let (axis, rot) = c.axis();
        if !rot {
            t[axis] = v;
        }
    }
    t
}

/// Reusable FK state: global rotations and local translations per joint, allocated once
/// (decoders run FK chunk by chunk, frame by frame).
pub struct Fk {
    rotations: Vec<Matrix3<f64>>,
    translations: Vec<[f64; 3]>,
}

impl Fk {
    pub fn new(joints: &[Joint]) -> Self {
        Fk {
            rotations: vec![Matrix3::identity(); joints.len()],
            translations: Vec::with_capacity(joints.len()),
        }
    }

    /// Each joint's rotation in the world after the last [`Fk::frame`]: what its offset and
    /// children's offsets are turned by (an end site has its parent's).
    pub fn rotations(&self) -> &[Matrix3<f64>] {
        &self.rotations
    }

    /// Positions of one frame (`vals`, its channel values) into `out` (`joints × 3`).
    pub fn frame(&mut self, joints: &[Joint], vals: &[f64], out: &mut [f64]) {
        local_translations(joints, vals, &mut self.translations);
        let mut k = 0;
        for (i, j) in joints.iter().enumerate() {
            let local = local_rotation(j, &vals[k..k + j.channels.len()]);
            k += j.channels.len();
            let t = Vector3::from(self.translations[i]);
            let (pos, rot) = match j.parent {
                Some(p) => {
                    let pr = self.rotations[p];
                    let pp = Vector3::new(out[p * 3], out[p * 3 + 1], out[p * 3 + 2]);
                    (pp + pr * t, pr * local)
                }
                None => (t, local),
            };
            self.rotations[i] = rot;
            out[i * 3..i * 3 + 3].copy_from_slice(pos.as_slice());
        }
    }
}

/// A joint's rotation relative to its parent for its channel values `vals`: its rotation
/// channels composed left to right, `R = R_c0 · R_c1 · R_c2`, as BVH applies them.
pub fn local_rotation(joint: &Joint, vals: &[f64]) -> Matrix3<f64> {
    let mut local = Matrix3::identity();
    for (&c, &v) in joint.channels.iter().zip(vals) {
        if let Some(axis) = c.rotation_axis() {
            local *= axis_rotation(axis, v.to_radians());
        }
    }
    local
}

/// Right-handed rotation about one coordinate axis.
fn axis_rotation(axis: usize, a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    match axis {
        0 => Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c),
        1 => Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c),
        _ => Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(channels: Vec<Channel>, values: Vec<f64>) -> Animation {
        let mut root_channels = vec![Channel::Xposition, Channel::Yposition, Channel::Zposition];
        root_channels.extend(channels);
        Animation::new(
            vec![
                Joint {
                    name: "root".into(),
                    parent: None,
                    offset: [0.0; 3],
                    channels: root_channels,
                    end_site: false,
                },
                Joint {
                    name: "tip".into(),
                    parent: Some(0),
                    offset: [1.0, 0.0, 0.0],
                    channels: vec![],
                    end_site: true,
                },
            ],
            values,
        )
        .unwrap()
    }

    fn close(a: &[f64], b: &[f64]) {
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-12, "{a:?} != {b:?}");
        }
    }

    #[test]
    fn single_axis_rotations_follow_the_right_hand_rule() {
        // Z 90°: x → y.
        let s = chain(vec![Channel::Zrotation], vec![1.0, 2.0, 3.0, 90.0]);
        close(&s.forward_kinematics()[3..], &[1.0, 3.0, 3.0]);
        // Y 90°: x → -z.
        let s = chain(vec![Channel::Yrotation], vec![0.0, 0.0, 0.0, 90.0]);
        close(&s.forward_kinematics()[3..], &[0.0, 0.0, -1.0]);
    }

    #[test]
    fn channel_order_composes_left_to_right() {
        // R = Rz(90)·Rx(90) applied to x: Rx leaves x alone, Rz takes it to y.
        let s = chain(
            vec![Channel::Zrotation, Channel::Xrotation],
            vec![0.0, 0.0, 0.0, 90.0, 90.0],
        );
        close(&s.forward_kinematics()[3..], &[0.0, 1.0, 0.0]);
        // R = Rx(90)·Rz(90) applied to x: Rz takes x to y, Rx takes y to z.
        let s = chain(
            vec![Channel::Xrotation, Channel::Zrotation],
            vec![0.0, 0.0, 0.0, 90.0, 90.0],
        );
        close(&s.forward_kinematics()[3..], &[0.0, 0.0, 1.0]);
    }

    #[test]
    fn rejects_children_before_parents() {
        let j = |name: &str, parent| Joint {
            name: name.into(),
            parent,
            offset: [0.0; 3],
            channels: vec![],
            end_site: false,
        };
        assert!(Animation::new(vec![j("a", None), j("b", Some(1))], vec![]).is_err());
        assert!(Animation::new(vec![j("a", None), j("b", None)], vec![]).is_err());
    }
}
