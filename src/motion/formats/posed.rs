//! A node hierarchy posed frame by frame in world space, as the FBX and glTF readers
//! evaluate it, written as a BVH-style skeleton: the root's world position and rotation,
//! every other joint's rotation relative to its parent's, and its translation where it
//! moves. Forward kinematics of that skeleton gives back the evaluated joint positions;
//! where a file scales a joint unevenly (a skeleton has no scale) the take says how far
//! apart they lie.

use std::collections::{HashMap, HashSet};

use nalgebra::{Matrix3, Matrix4, Rotation3, UnitQuaternion, Vector3};

use crate::motion::error::Result;
use crate::motion::rotation::to_euler;
use crate::motion::skeleton::{Animation, Channel, Joint};

/// Euler order of every joint's rotation channels (Z, then X, then Y: BVH's usual one;
/// any order gives the same rotations back).
const ORDER: [usize; 3] = [2, 0, 1];
const ROTATIONS: [Channel; 3] = [Channel::Zrotation, Channel::Xrotation, Channel::Yrotation];
const POSITIONS: [Channel; 3] = [Channel::Xposition, Channel::Yposition, Channel::Zposition];

/// A joint whose translation from its parent moves less than this (file units) over the
/// take keeps it as a fixed offset; else it gets position channels.
const FIXED: f64 = 1e-6;

/// Where the skeleton's joints may lie from the file's before the take says so (file
/// units; evaluation itself is exact to far less).
const SCALE_WARNING: f64 = 1e-3;

/// A world transform: a position, and a rotation with any scale taken out.
pub(crate) type Place = (Vector3<f64>, UnitQuaternion<f64>);

/// The place of an affine world matrix (column-major entries as nalgebra keeps them).
pub(crate) fn place(m: &Matrix4<f64>) -> Place {
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let rot = Rotation3::from_matrix_eps(&r, 1e-12, 64, Rotation3::identity());
    (
        Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

/// A hierarchy of joints, parents first, and each joint's world place at every frame.
pub(crate) struct Posed {
    /// The file's node names (made unique and non-empty here).
    pub names: Vec<String>,
    pub parents: Vec<Option<usize>>,
    pub frames: usize,
    /// `frames × joints`.
    pub places: Vec<Place>,
}

/// The skeleton of a posed hierarchy, with the joints' world positions (file units).
pub(crate) struct Skeletal {
    pub names: Vec<String>,
    pub positions: Vec<f32>,
    pub skeleton: Animation,
    pub warnings: Vec<String>,
}

/// Name `i` made unique among `taken` and never empty (exporters repeat names and leave
/// them out; a take's points may do neither); `next` holds each base's next suffix, so that
/// a thousand joints of one name cost a thousand lookups, not half a million.
fn unique(
    base: &str,
    i: usize,
    taken: &HashSet<String>,
    next: &mut HashMap<String, usize>,
) -> String {
    let base = match base.trim() {
        "" => format!("node{i}"),
        _ => base.to_string(),
    };
    if !taken.contains(&base) {
        return base;
    }
    let suffix = next.entry(base.clone()).or_insert(2);
    loop {
        let name = format!("{base}_{suffix}");
        *suffix += 1;
        if !taken.contains(&name) {
            return name;
        }
    }
}

impl Posed {
    /// The skeleton that gives back these places: a leaf's rotation turns nothing below
    /// it, so a leaf that does not move from its parent is an end site.
    pub(crate) fn skeleton(self) -> Result<Skeletal> {
        let n = self.names.len();
        let frames = self.frames;
        let places = &self.places;
        let mut leaf = vec![true; n];
        for p in self.parents.iter().flatten() {
            leaf[*p] = false;
        }
        let local = |f: usize, k: usize| -> Place {
            let (p, q) = places[f * n + k];
            match self.parents[k] {
                None => (p, q),
                Some(pk) => {
                    let (pp, pq) = places[f * n + pk];
                    (pq.inverse() * (p - pp), pq.inverse() * q)
                }
            }
        };
        let mut joints = Vec::with_capacity(n);
        let mut moves = vec![false; n];
        let mut rotates = vec![false; n];
        let mut taken = HashSet::new();
        let mut next = HashMap::new();
        for k in 0..n {
            let (t0, _) = local(0, k);
            moves[k] = k == 0 || (1..frames).any(|f| (local(f, k).0 - t0).amax() > FIXED);
            let mut channels = Vec::new();
            if moves[k] {
                channels.extend(POSITIONS);
            }
            rotates[k] = !leaf[k] || k == 0;
            if rotates[k] {
                channels.extend(ROTATIONS);
            }
            let name = unique(&self.names[k], k, &taken, &mut next);
            taken.insert(name.clone());
            joints.push(Joint {
                name,
                parent: self.parents[k],
                offset: if k == 0 { [0.0; 3] } else { t0.into() },
                end_site: channels.is_empty(),
                channels,
            });
        }
        let mut values = Vec::new();
        let mut last: Vec<Option<[f64; 3]>> = vec![None; n];
        for f in 0..frames {
            for (k, j) in joints.iter().enumerate() {
                if j.channels.is_empty() {
                    continue;
                }
                let (t, q) = local(f, k);
                if moves[k] {
                    values.extend_from_slice(&[t.x, t.y, t.z]);
                }
                if rotates[k] {
                    let e = to_euler(&q, ORDER, last[k]);
                    last[k] = Some(e);
                    values.extend_from_slice(&e);
                }
            }
        }
        let names: Vec<String> = joints.iter().map(|j| j.name.clone()).collect();
        let skeleton = Animation::new(joints, values)?;
        let fk = skeleton.forward_kinematics();
        let mut worst = 0.0f64;
        for (f, chunk) in fk.chunks_exact(n * 3).enumerate() {
            for k in 0..n {
                let p = places[f * n + k].0;
                let d = Vector3::new(chunk[k * 3], chunk[k * 3 + 1], chunk[k * 3 + 2]) - p;
                worst = worst.max(d.norm());
            }
        }
        let mut warnings = Vec::new();
        if worst > SCALE_WARNING {
            warnings.push(format!(
                "the file scales joints unevenly: the skeleton's joints lie up to {worst:.4} \
                 file units from the file's (a skeleton has no scale)"
            ));
        }
        Ok(Skeletal {
            names,
            positions: fk.into_iter().map(|v| v as f32).collect(),
            skeleton,
            warnings,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain of three nodes, the middle one turning about Z and the last sliding along
    /// its parent's X: forward kinematics of the skeleton gives back every world position.
    #[test]
    fn the_skeleton_gives_back_the_world_places() {
        let frames = 5;
        let mut places = Vec::new();
        for f in 0..frames {
            let a = f as f64 * 0.3;
            let root = (
                Vector3::new(1.0, 2.0, 3.0 + f as f64),
                UnitQuaternion::identity(),
            );
            let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
            let mid = (root.0 + Vector3::new(0.0, 1.0, 0.0), q);
            let tip = (mid.0 + q * Vector3::new(0.5 + 0.1 * f as f64, 0.0, 0.0), q);
            places.extend([root, mid, tip]);
        }
        let posed = Posed {
            names: vec!["root".into(), "".into(), "root".into()],
            parents: vec![None, Some(0), Some(1)],
            frames,
            places: places.clone(),
        };
        let s = posed.skeleton().unwrap();
        assert_eq!(s.names, ["root", "node1", "root_2"]);
        assert!(s.skeleton.joints[2].channels.contains(&Channel::Xposition));
        assert!(s.warnings.is_empty());
        for (f, chunk) in s.positions.chunks_exact(9).enumerate() {
            for k in 0..3 {
                let p = places[f * 3 + k].0;
                for c in 0..3 {
                    assert!((f64::from(chunk[k * 3 + c]) - p[c]).abs() < 1e-5, "{f} {k}");
                }
            }
        }
    }
}
