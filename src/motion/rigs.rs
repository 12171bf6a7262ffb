//! Standard rigs shipped with the service, the targets a take can be put on by name (issue
//! 52's `skeleton=mixamo`, `skeleton=smpl`): each a hierarchy in its rest pose, in metres,
//! +Y up, facing +Z, the performer's left on +X, as BVH would write it (a root with its
//! position and rotation, every other joint rotating about its offset; zero channels are
//! the rest pose).
//!
//! # Where the numbers come from
//! - **Mixamo**: the HumanIK body of Mixamo's characters (`mixamorig:` names), in the
//!   T-pose its characters are bound in; places from the Y Bot's rest pose, to about a
//!   centimetre. Fingers are not listed yet.
//! - **SMPL**: the 24 joints of SMPL's kinematic tree with its names and parents, at the
//!   mean shape's rest (T-pose), rounded to the millimetre. Listed depth first, as every
//!   rig here (a BVH file's values run so): SMPL's own joint numbers are the table's order
//!   below, not the skeleton's.
//!
//! Each is checked by its own names: the body conventions ([`super::body`]) place every
//! role on it, and its rest pose stands up with the arms level.

use super::skeleton::{Channel, Joint};

/// A standard rig: its name and its joints, parents first.
#[derive(Debug, Clone)]
pub struct Rig {
    pub name: &'static str,
    pub about: &'static str,
    pub joints: Vec<Joint>,
}

/// One joint as listed below: name, parent (none for the root), rest place in the world
/// (metres), and whether it is an end site.
type Row = (&'static str, Option<&'static str>, [f64; 3], bool);

/// Mixamo's body, right side mirrored from the left (x negated).
const MIXAMO: &[Row] = &[
    ("mixamorig:Hips", None, [0.0, 0.998, 0.0], false),
    (
        "mixamorig:Spine",
        Some("mixamorig:Hips"),
        [0.0, 1.097, -0.012],
        false,
    ),
    (
        "mixamorig:Spine1",
        Some("mixamorig:Spine"),
        [0.0, 1.214, -0.016],
        false,
    ),
    (
        "mixamorig:Spine2",
        Some("mixamorig:Spine1"),
        [0.0, 1.347, -0.020],
        false,
    ),
    (
        "mixamorig:Neck",
        Some("mixamorig:Spine2"),
        [0.0, 1.498, -0.035],
        false,
    ),
    (
        "mixamorig:Head",
        Some("mixamorig:Neck"),
        [0.0, 1.601, 0.0],
        false,
    ),
    (
        "mixamorig:HeadTop_End",
        Some("mixamorig:Head"),
        [0.0, 1.786, 0.063],
        true,
    ),
    (
        "mixamorig:LeftShoulder",
        Some("mixamorig:Spine2"),
        [0.061, 1.438, -0.036],
        false,
    ),
    (
        "mixamorig:LeftArm",
        Some("mixamorig:LeftShoulder"),
        [0.188, 1.436, -0.062],
        false,
    ),
    (
        "mixamorig:LeftForeArm",
        Some("mixamorig:LeftArm"),
        [0.462, 1.436, -0.062],
        false,
    ),
    (
        "mixamorig:LeftHand",
        Some("mixamorig:LeftForeArm"),
        [0.738, 1.436, -0.062],
        false,
    ),
    (
        "mixamorig:LeftUpLeg",
        Some("mixamorig:Hips"),
        [0.091, 0.931, 0.0],
        false,
    ),
    (
        "mixamorig:LeftLeg",
        Some("mixamorig:LeftUpLeg"),
        [0.094, 0.525, -0.006],
        false,
    ),
    (
        "mixamorig:LeftFoot",
        Some("mixamorig:LeftLeg"),
        [0.091, 0.105, -0.026],
        false,
    ),
    (
        "mixamorig:LeftToeBase",
        Some("mixamorig:LeftFoot"),
        [0.095, 0.0, 0.100],
        false,
    ),
    (
        "mixamorig:LeftToe_End",
        Some("mixamorig:LeftToeBase"),
        [0.095, 0.0, 0.200],
        true,
    ),
];

/// SMPL's 24 joints in its order, left side listed (the right mirrors it).
const SMPL: &[Row] = &[
    ("pelvis", None, [0.0, 0.94, 0.0], false),
    ("left_hip", Some("pelvis"), [0.069, 0.849, -0.007], false),
    ("right_hip", Some("pelvis"), [-0.069, 0.849, -0.007], false),
    ("spine1", Some("pelvis"), [-0.003, 1.049, -0.027], false),
    ("left_knee", Some("left_hip"), [0.103, 0.474, -0.012], false),
    (
        "right_knee",
        Some("right_hip"),
        [-0.103, 0.474, -0.012],
        false,
    ),
    ("spine2", Some("spine1"), [0.002, 1.184, -0.026], false),
    (
        "left_ankle",
        Some("left_knee"),
        [0.089, 0.076, -0.056],
        false,
    ),
    (
        "right_ankle",
        Some("right_knee"),
        [-0.089, 0.076, -0.056],
        false,
    ),
    ("spine3", Some("spine2"), [0.003, 1.237, -0.001], false),
    (
        "left_foot",
        Some("left_ankle"),
        [0.115, 0.020, 0.063],
        false,
    ),
    (
        "right_foot",
        Some("right_ankle"),
        [-0.115, 0.020, 0.063],
        false,
    ),
    ("neck", Some("spine3"), [0.0, 1.451, -0.044], false),
    ("left_collar", Some("spine3"), [0.082, 1.359, -0.035], false),
    (
        "right_collar",
        Some("spine3"),
        [-0.082, 1.359, -0.035],
        false,
    ),
    ("head", Some("neck"), [0.005, 1.516, 0.007], false),
    (
        "left_shoulder",
        Some("left_collar"),
        [0.173, 1.389, -0.044],
        false,
    ),
    (
        "right_shoulder",
        Some("right_collar"),
        [-0.173, 1.389, -0.044],
        false,
    ),
    (
        "left_elbow",
        Some("left_shoulder"),
        [0.433, 1.376, -0.072],
        false,
    ),
    (
        "right_elbow",
        Some("right_shoulder"),
        [-0.433, 1.376, -0.072],
        false,
    ),
    (
        "left_wrist",
        Some("left_elbow"),
        [0.682, 1.385, -0.073],
        false,
    ),
    (
        "right_wrist",
        Some("right_elbow"),
        [-0.682, 1.385, -0.073],
        false,
    ),
    (
        "left_hand",
        Some("left_wrist"),
        [0.766, 1.377, -0.088],
        false,
    ),
    (
        "right_hand",
        Some("right_wrist"),
        [-0.766, 1.377, -0.088],
        false,
    ),
];

const ROOT_CHANNELS: [Channel; 6] = [
    Channel::Xposition,
    Channel::Yposition,
    Channel::Zposition,
    Channel::Zrotation,
    Channel::Xrotation,
    Channel::Yrotation,
];
const CHANNELS: [Channel; 3] = [Channel::Zrotation, Channel::Xrotation, Channel::Yrotation];

/// The mirror of a left-side row, for tables that list the left side alone.
fn mirrored(rows: &[Row]) -> Vec<(String, Option<String>, [f64; 3], bool)> {
    let swap = |n: &str| n.replace("Left", "Right");
    let mut out = Vec::new();
    for (name, parent, at, end) in rows {
        out.push((name.to_string(), parent.map(str::to_string), *at, *end));
        if name.contains("Left") {
            out.push((swap(name), parent.map(swap), [-at[0], at[1], at[2]], *end));
        }
    }
    out
}

/// Joints from rows of rest places (a parent's row comes before its children's in every
/// table here), in the order a BVH file lists them: each joint's subtree whole before its
/// next sibling, as a file's channel values run (tables list the two sides in turn).
fn joints(rows: Vec<(String, Option<String>, [f64; 3], bool)>) -> Vec<Joint> {
    let mut out: Vec<Joint> = Vec::with_capacity(rows.len());
    let mut places: Vec<[f64; 3]> = Vec::with_capacity(rows.len());
    for (name, parent, at, end_site) in rows {
        let parent = parent.map(|p| {
            out.iter()
                .position(|j| j.name == p)
                .unwrap_or_else(|| panic!("{name}: parent {p} listed after it"))
        });
        let offset = match parent {
            Some(p) => [
                at[0] - places[p][0],
                at[1] - places[p][1],
                at[2] - places[p][2],
            ],
            None => at,
        };
        let channels = match (parent, end_site) {
            (_, true) => Vec::new(),
            (None, false) => ROOT_CHANNELS.to_vec(),
            (Some(_), false) => CHANNELS.to_vec(),
        };
        out.push(Joint {
            name,
            parent,
            offset,
            channels,
            end_site,
        });
        places.push(at);
    }
    depth_first(out)
}

/// `joints` (parents first) reordered depth first, siblings in their order, parents renumbered.
fn depth_first(joints: Vec<Joint>) -> Vec<Joint> {
    let mut order = Vec::with_capacity(joints.len());
    let mut stack: Vec<usize> = (0..joints.len())
        .filter(|&i| joints[i].parent.is_none())
        .rev()
        .collect();
    while let Some(i) = stack.pop() {
        order.push(i);
        stack.extend(
            (0..joints.len())
                .filter(|&c| joints[c].parent == Some(i))
                .rev(),
        );
    }
    let mut at = vec![0; joints.len()];
    for (new, &old) in order.iter().enumerate() {
        at[old] = new;
    }
    order
        .iter()
        .map(|&old| Joint {
            parent: joints[old].parent.map(|p| at[p]),
            ..joints[old].clone()
        })
        .collect()
}

/// Every standard rig, by name.
pub fn all() -> Vec<Rig> {
    vec![
        Rig {
            name: "mixamo",
            about:
                "Mixamo's characters (HumanIK names under mixamorig:), T-pose, body without fingers",
            joints: joints(mirrored(MIXAMO)),
        },
        Rig {
            name: "smpl",
            about: "SMPL's 24 joints (SMPL-H/X bodies, AMASS), T-pose of the mean shape",
            joints: joints(
                SMPL.iter()
                    .map(|(n, p, at, e)| (n.to_string(), p.map(str::to_string), *at, *e))
                    .collect(),
            ),
        },
    ]
}

/// The standard rig called `name`.
pub fn named(name: &str) -> Option<Rig> {
    all().into_iter().find(|r| r.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::body::{Part, Role, Roles, Side};
    use crate::motion::skeleton::rest_places;

    #[test]
    fn every_rig_has_its_roles_by_name_and_stands_in_a_t_pose() {
        for rig in all() {
            let roles = Roles::of_skeleton(&rig.joints);
            let names: Vec<String> = rig.joints.iter().map(|j| j.name.clone()).collect();
            for role in Role::all() {
                assert!(
                    !roles.points(role, &names).is_empty(),
                    "{}: {} unplaced",
                    rig.name,
                    role.name()
                );
            }
            let at = rest_places(&rig.joints);
            let y = |role: Role| at[roles.points(role, &names)[0]][1];
            let x = |role: Role| at[roles.points(role, &names)[0]][0];
            assert!(y(Role::Head) > y(Role::Pelvis), "{}", rig.name);
            for side in [Side::Left, Side::Right] {
                let limb = |p: Part| Role::Limb(side, p);
                assert!(y(Role::Pelvis) > y(limb(Part::Knee)), "{}", rig.name);
                assert!(y(limb(Part::Knee)) > y(limb(Part::Ankle)), "{}", rig.name);
                // Arms level: the wrist within 3 cm of the shoulder's height.
                assert!(
                    (y(limb(Part::Wrist)) - y(limb(Part::Shoulder))).abs() < 0.03,
                    "{}: not a T-pose",
                    rig.name
                );
                // The performer's left on +X.
                let sign = if side == Side::Left { 1.0 } else { -1.0 };
                assert!(sign * x(limb(Part::Wrist)) > 0.5, "{}", rig.name);
            }
            let height = y(Role::Head) - y(Role::Limb(Side::Left, Part::Ankle));
            assert!((1.3..1.8).contains(&height), "{}: {height}", rig.name);
        }
        assert!(named("mixamo").is_some() && named("nope").is_none());
        // Depth first, as a BVH file's values run: each joint follows its parent or a
        // subtree that ends with a sibling of it (its parent's earlier child's last joint).
        for rig in all() {
            let mut open: Vec<usize> = Vec::new();
            for (i, j) in rig.joints.iter().enumerate() {
                while open.last().is_some_and(|&o| Some(o) != j.parent) {
                    open.pop();
                }
                assert!(
                    j.parent.is_none() || open.last() == j.parent.as_ref(),
                    "{}: {} out of depth-first order",
                    rig.name,
                    j.name
                );
                open.push(i);
            }
        }
    }
}
