//! The encoder's spatial closed loop: each joint's rotation is coded not as the file had it
//! but as the rotation that, from its *decoded* parent, points its children where they were.
//!
//! Temporal prediction alone lets quantisation errors add up along a chain: a wrong hip
//! moves the knee, the ankle and the toe, and the wrist's error adds to the shoulder's, so
//! the hand carries the sum of its ancestors' errors. Aiming each joint from its decoded
//! parent (the IK view: the bones below correct what the bones above got wrong) leaves each
//! point with its own bone's quantisation error only. The correction is the smallest
//! rotation that does it, applied to the file's rotation, so a joint's twist (which moves
//! none of its children) stays what the file said. The decoder does not know any of this:
//! it decodes rotations as always.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::codec::skeleton::Skeleton;
use crate::motion::skeleton::{self, Joint};

/// What aiming needs of the rig, once per take.
pub(super) struct Bones {
    joints: Vec<Bone>,
}

struct Bone {
    joint: Joint,
    /// The joint's first channel in a frame's values.
    first: usize,
    /// Joints and End Sites this joint's rotation moves directly (aiming skips those at a
    /// zero offset: the joint's rotation does not move them).
    children: Vec<usize>,
}

impl Bones {
    pub(super) fn new(rig: &Skeleton) -> Bones {
        let mut first = 0;
        let mut joints: Vec<Bone> = rig
            .joints()
            .iter()
            .map(|j| {
                let b = Bone {
                    joint: j.clone(),
                    first,
                    children: Vec::new(),
                };
                first += j.channels.len();
                b
            })
            .collect();
        for (c, j) in rig.joints().iter().enumerate() {
            if let Some(p) = j.parent {
                joints[p].children.push(c);
            }
        }
        Bones { joints }
    }

    /// The joint's channel values in a frame's `values`.
    fn own<'v>(&self, j: usize, values: &'v [f64]) -> &'v [f64] {
        let b = &self.joints[j];
        &values[b.first..b.first + b.joint.channels.len()]
    }

    /// The joint's translation from its parent in one frame.
    fn translation(&self, j: usize, values: &[f64]) -> Vector3<f64> {
        Vector3::from(skeleton::translation(
            &self.joints[j].joint,
            self.own(j, values),
        ))
    }

    /// The joint's local rotation in one frame, from its channel values (degrees).
    fn rotation(&self, j: usize, values: &[f64]) -> UnitQuaternion<f64> {
        let mut q = UnitQuaternion::identity();
        for (c, v) in self.joints[j]
            .joint
            .channels
            .iter()
            .zip(self.own(j, values))
        {
            let (axis, rot) = c.axis();
            if rot {
                q *= UnitQuaternion::from_axis_angle(&Vector3::ith_axis(axis), v.to_radians());
            }
        }
        q
    }
}

/// What aiming needs for a chunk being encoded: the rig's bones and the chunk's original
/// positions (`points` per frame).
pub(super) struct Aim<'a> {
    pub(super) bones: &'a Bones,
    pub(super) positions: &'a [f32],
    pub(super) points: usize,
}

impl Aim<'_> {
    /// The original positions of frame `f` of the chunk.
    pub(super) fn frame(&self, f: usize) -> &[f32] {
        let w = self.points * 3;
        &self.positions[f * w..(f + 1) * w]
    }
}

/// One frame's decoded pose as far as it has been decoded: global rotations and positions,
/// computed on demand from the channel values decoded so far.
pub(super) struct Pose {
    /// Local rotations the caller has decoded already (saves rebuilding them from Euler
    /// angles).
    local: Vec<Option<UnitQuaternion<f64>>>,
    rotation: Vec<UnitQuaternion<f64>>,
    position: Vec<Vector3<f64>>,
    /// Which joints' global rotation (`.0`) and position (`.1`) are known this frame.
    known: Vec<(bool, bool)>,
}

impl Pose {
    pub(super) fn new(bones: &Bones) -> Pose {
        let n = bones.joints.len();
        Pose {
            local: vec![None; n],
            rotation: vec![UnitQuaternion::identity(); n],
            position: vec![Vector3::zeros(); n],
            known: vec![(false, false); n],
        }
    }

    /// Start a new frame.
    pub(super) fn clear(&mut self) {
        self.known.iter_mut().for_each(|k| *k = (false, false));
        self.local.iter_mut().for_each(|l| *l = None);
    }

    /// Joint `j`'s local rotation as decoded.
    pub(super) fn decoded(&mut self, j: usize, q: UnitQuaternion<f64>) {
        self.local[j] = Some(q);
    }

    /// Global position of joint `j`: needs its ancestors' channels and its own position
    /// channels decoded.
    fn position(&mut self, bones: &Bones, j: usize, decoded: &[f64]) -> Vector3<f64> {
        if !self.known[j].1 {
            let t = bones.translation(j, decoded);
            self.position[j] = match bones.joints[j].joint.parent {
                Some(p) => self.position(bones, p, decoded) + self.rotation(bones, p, decoded) * t,
                None => t,
            };
            self.known[j].1 = true;
        }
        self.position[j]
    }

    /// Global rotation of joint `j`: needs its and its ancestors' channels decoded.
    fn rotation(&mut self, bones: &Bones, j: usize, decoded: &[f64]) -> UnitQuaternion<f64> {
        if !self.known[j].0 {
            let local = self.local[j].unwrap_or_else(|| bones.rotation(j, decoded));
            self.rotation[j] = match bones.joints[j].joint.parent {
                Some(p) => self.rotation(bones, p, decoded) * local,
                None => local,
            };
            self.known[j].0 = true;
        }
        self.rotation[j]
    }
}

/// The local rotation to code for joint `j` in one frame: `wanted` (the file's) turned by the
/// smallest rotation that points the joint's children, from where the decoded parent puts
/// the joint, at their original positions (`original`, the frame's points × 3).
///
/// `decoded` holds the frame's values decoded so far (every ancestor's, and `j`'s position
/// channels); `given` the frame's original values (for the children's position channels,
/// not decoded yet).
pub(super) fn aim(
    bones: &Bones,
    pose: &mut Pose,
    j: usize,
    wanted: UnitQuaternion<f64>,
    decoded: &[f64],
    given: &[f64],
    original: &[f32],
) -> UnitQuaternion<f64> {
    let parent = match bones.joints[j].joint.parent {
        Some(p) => pose.rotation(bones, p, decoded),
        None => UnitQuaternion::identity(),
    };
    let at = pose.position(bones, j, decoded);
    let global = parent * wanted;
    // Where the file's rotation points each child from here, and where the child was.
    let mut pairs: Vec<(Vector3<f64>, Vector3<f64>)> = Vec::new();
    for &c in &bones.joints[j].children {
        let t = bones.translation(c, given);
        if t.norm_squared() < 1e-18 {
            continue;
        }
        let o = Vector3::new(
            f64::from(original[c * 3]),
            f64::from(original[c * 3 + 1]),
            f64::from(original[c * 3 + 2]),
        );
        pairs.push((global * t, o - at));
    }
    let turn = match pairs.len() {
        0 => return wanted,
        1 => UnitQuaternion::rotation_between(&pairs[0].0, &pairs[0].1),
        _ => kabsch(&pairs),
    };
    // Corrections are not capped: at loose bounds a short bone (a toe, a finger) may turn
    // far and still be within the bound, which is all its points are held to. A rig whose
    // children do not follow the joint (position channels that move them) can make aiming
    // miss the bound; the encoder then codes that chunk unaimed.
    match turn {
        Some(turn) => parent.inverse() * turn * global,
        None => wanted,
    }
}

/// Children this near one line (the second singular value against the first) leave the
/// turn about it to the noise of the decoded positions: a child a micrometre off the line
/// (a position channel printing the offset with rounding) set a twisting root to any angle
/// about the hips' line (Blender's rig in bvhtools_test3.bvh: 150° off the file's). The
/// file's twist is kept instead.
const COLLINEAR: f64 = 1e-3;

/// The rotation `R` minimising `Σ |R·a − b|²` over the pairs; `None` when the `a` are all on
/// one line (then the turn about that line is undetermined, and the caller keeps the
/// file's rotation).
fn kabsch(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Option<UnitQuaternion<f64>> {
    let mut h = Matrix3::zeros();
    for (a, b) in pairs {
        h += b * a.transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let s = svd.singular_values;
    if s[1] <= COLLINEAR * s[0] {
        // On one line (e.g. two hips either side of the pelvis): turn the longest onto its
        // target; the turn about the line stays the file's.
        let (a, b) = pairs
            .iter()
            .max_by(|x, y| x.0.norm_squared().total_cmp(&y.0.norm_squared()))?;
        return UnitQuaternion::rotation_between(a, b);
    }
    let d = (u * v_t).determinant().signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
    Some(UnitQuaternion::from_matrix(&r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::rotation;
    use crate::motion::synthetic::dancer;

    /// A decoded parent that is a few degrees off: the aimed rotation of each one-child
    /// joint points its child, from where that parent puts the joint, at where the child
    /// was; the file's rotation does not.
    #[test]
    fn aimed_joints_point_their_children_at_the_original_positions() {
        let m = dancer(3, 60.0, 4);
        let sk = m.skeleton.as_ref().unwrap();
        let rig = Skeleton::new(sk.joints.clone()).unwrap();
        let bones = Bones::new(&rig);
        let given = sk.frame_values(1).to_vec();
        let original: Vec<f32> = m.positions()[m.point_count() * 3..m.point_count() * 6].to_vec();
        let mut checked = 0;
        for (j, b) in bones.joints.iter().enumerate() {
            let (Some(p), [c]) = (b.joint.parent, b.children.as_slice()) else {
                continue;
            };
            let Some(order) = rotation::euler_order(&b.joint.channels) else {
                continue;
            };
            // The parent decoded 3° off on its first rotation channel.
            let mut decoded = given.clone();
            let pb = &bones.joints[p];
            let k = pb.joint.channels.iter().position(|c| c.axis().1).unwrap();
            decoded[pb.first + k] += 3.0;
            let r = &given[b.first + b.joint.channels.len() - 3..b.first + b.joint.channels.len()];
            let wanted = rotation::from_euler(order, [r[0], r[1], r[2]]);
            let mut pose = Pose::new(&bones);
            let aimed = aim(&bones, &mut pose, j, wanted, &decoded, &given, &original);
            let at = pose.position(&bones, j, &decoded);
            let parent = pose.rotation(&bones, p, &decoded);
            let t = bones.translation(*c, &given);
            let o = Vector3::new(
                f64::from(original[c * 3]),
                f64::from(original[c * 3 + 1]),
                f64::from(original[c * 3 + 2]),
            );
            let towards = (o - at).normalize();
            assert!((parent * aimed * t).normalize().dot(&towards) > 1.0 - 1e-9);
            assert!((parent * wanted * t).normalize().dot(&towards) < 1.0 - 1e-6);
            checked += 1;
        }
        assert!(checked >= 8, "{checked} joints checked");
    }

    #[test]
    fn kabsch_recovers_a_rotation() {
        let r = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.9);
        let pairs: Vec<_> = [
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 2.0, 0.5),
            Vector3::new(-1.0, 0.3, 0.0),
        ]
        .into_iter()
        .map(|a| (a, r * a))
        .collect();
        let k = kabsch(&pairs).unwrap();
        assert!(k.angle_to(&r) < 1e-9);
        // Two opposite children (hips either side of a pelvis): still the turn that
        // aligns them, not a degenerate one.
        let a = Vector3::new(0.1, 0.0, 0.0);
        let k = kabsch(&[(a, r * a), (-a, r * -a)]).unwrap();
        assert!((k * a - r * a).norm() < 1e-12);
    }
}
