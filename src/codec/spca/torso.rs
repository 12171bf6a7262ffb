//! Normalisation by the torso (Liu & McMillan 2006, §3): each frame's pose is moved so that
//! the first torso point is the origin, turned about the vertical axis so that the shoulder
//! vector, projected on the horizontal plane, is the first horizontal axis, and the vertical
//! axis is kept. What is left is the body's shape, which one PCA model per segment codes
//! well wherever the performer walks or faces.
//!
//! The torso points are found by name ([`find`]) — for a skeleton its hips (or spine, chest,
//! neck) and shoulders, for a marker set C7 and the shoulder markers — or given. Which axis is
//! vertical is found from the data ([`vertical_axis`]): BVH files are usually y-up, C3D
//! files z-up, and neither says so.
//!
//! The turn is computed from the horizontal shoulder vector by a square root, not by
//! trigonometry: `sqrt` is exact in IEEE arithmetic, library `atan2`/`cos` are not, and a
//! decoder on another machine must reproduce the encoder's frames bit for bit.

/// A name reduced to lower-case letters and digits (`L.Shoulder`, `LeftShoulder` and
/// `l_shoulder` compare equal).
fn key(name: &str) -> String {
    name.chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// Names of the origin point, in order of preference: a marker set's C7, a skeleton's hips
/// or pelvis, else its spine, chest or neck.
const ORIGIN: [&str; 9] = [
    "c7", "hips", "hip", "pelvis", "root", "spine", "chest", "spine1", "neck",
];
/// Names of the left shoulder: markers (`LSHO`, `L.Shoulder`), then skeletons' shoulder
/// joints (CMU `LeftArm` is the shoulder joint, `LeftShoulder` the clavicle).
const LEFT: [&str; 9] = [
    "lsho",
    "lshoulder",
    "leftarm",
    "upperarml",
    "lupperarm",
    "leftupperarm",
    "leftshoulder",
    "shoulderl",
    "lclavicle",
];
const RIGHT: [&str; 9] = [
    "rsho",
    "rshoulder",
    "rightarm",
    "upperarmr",
    "rupperarm",
    "rightupperarm",
    "rightshoulder",
    "shoulderr",
    "rclavicle",
];

/// The first point whose name is one of `wanted` (earlier ones preferred).
fn first_named(names: &[String], wanted: &[&str]) -> Option<usize> {
    let keys: Vec<String> = names.iter().map(|n| key(n)).collect();
    wanted.iter().find_map(|w| keys.iter().position(|k| k == w))
}

/// The torso points `[origin, left shoulder, right shoulder]` found by name, if all three
/// are there and distinct.
pub fn find(names: &[String]) -> Option<[usize; 3]> {
    let t = [
        first_named(names, &ORIGIN)?,
        first_named(names, &LEFT)?,
        first_named(names, &RIGHT)?,
    ];
    (t[0] != t[1] && t[0] != t[2] && t[1] != t[2]).then_some(t)
}

/// Name fragments of foot points (ankles, heels, toes, metatarsals), which the PCA holds to
/// a tighter tolerance: a sliding foot is the error viewers notice first.
const FOOT: [&str; 7] = ["foot", "toe", "heel", "ankle", "hee", "ank", "mt5"];

/// Whether each point is a foot point, by name.
pub fn feet(names: &[String], points: usize) -> Vec<bool> {
    (0..points)
        .map(|p| {
            names
                .get(p)
                .is_some_and(|n| FOOT.iter().any(|f| key(n).contains(f)))
        })
        .collect()
}

/// The vertical axis (0 = x, 1 = y, 2 = z) of `frames × points × 3` data: the axis along
/// which the body is tallest — the median over frames of the extent of the points along it
/// is largest. (A body stands taller than it is wide or deep in most frames of most takes;
/// a wrong guess costs compression, never correctness.)
pub fn vertical_axis(data: &[f32], points: usize, valid: Option<&[bool]>) -> u8 {
    let w = points * 3;
    let frames = data.len().checked_div(w).unwrap_or(0);
    if frames == 0 {
        return 1;
    }
    // At most 200 frames, evenly spread: a median needs no more.
    let stride = frames.div_ceil(200);
    let mut extents: [Vec<f32>; 3] = Default::default();
    for f in (0..frames).step_by(stride) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in 0..points {
            if valid.is_some_and(|v| !v[f * points + p]) {
                continue;
            }
            for a in 0..3 {
                let x = data[f * w + p * 3 + a];
                lo[a] = lo[a].min(x);
                hi[a] = hi[a].max(x);
            }
        }
        if lo[0].is_finite() {
            for a in 0..3 {
                extents[a].push(hi[a] - lo[a]);
            }
        }
    }
    let median = |v: &mut Vec<f32>| {
        if v.is_empty() {
            return 0.0;
        }
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let m: Vec<f32> = extents.iter_mut().map(median).collect();
    let mut best = 1;
    for a in [0, 2] {
        if m[a] > m[best] {
            best = a;
        }
    }
    best as u8
}

/// Where one frame's body is: the origin and the turn about the vertical axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    pub origin: [f64; 3],
    /// Cosine and sine of the turn.
    pub cos: f64,
    pub sin: f64,
}

impl Placement {
    pub const IDENTITY: Placement = Placement {
        origin: [0.0; 3],
        cos: 1.0,
        sin: 0.0,
    };
}

/// The two horizontal axes for vertical axis `up`, in the order that makes the turn a
/// proper rotation.
#[inline]
fn horizontal(up: u8) -> (usize, usize) {
    let u = usize::from(up);
    ((u + 1) % 3, (u + 2) % 3)
}

/// The placement of a frame from its three torso points (`origin, left, right`, 9 values):
/// origin at the first, first horizontal axis along the horizontal part of left → right.
/// A shoulder vector with no horizontal part leaves the frame unturned.
pub fn placement(torso: &[f64], up: u8) -> Placement {
    let (a, b) = horizontal(up);
    let (da, db) = (torso[6 + a] - torso[3 + a], torso[6 + b] - torso[3 + b]);
    let len = (da * da + db * db).sqrt();
    let (cos, sin) = if len > 1e-12 && len.is_finite() {
        (da / len, db / len)
    } else {
        (1.0, 0.0)
    };
    Placement {
        origin: [torso[0], torso[1], torso[2]],
        cos,
        sin,
    }
}

/// A world point in the body's frame.
#[inline]
pub fn to_local(p: &Placement, up: u8, x: [f64; 3]) -> [f64; 3] {
    let (a, b) = horizontal(up);
    let d = [x[0] - p.origin[0], x[1] - p.origin[1], x[2] - p.origin[2]];
    let mut q = [0.0; 3];
    q[a] = p.cos * d[a] + p.sin * d[b];
    q[b] = -p.sin * d[a] + p.cos * d[b];
    q[usize::from(up)] = d[usize::from(up)];
    q
}

/// A point of the body's frame in the world.
#[inline]
pub fn to_world(p: &Placement, up: u8, q: [f64; 3]) -> [f64; 3] {
    let (a, b) = horizontal(up);
    let mut x = [0.0; 3];
    x[a] = p.cos * q[a] - p.sin * q[b] + p.origin[a];
    x[b] = p.sin * q[a] + p.cos * q[b] + p.origin[b];
    let u = usize::from(up);
    x[u] = q[u] + p.origin[u];
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn finds_torso_points_of_skeletons_and_marker_sets() {
        let cmu = names(&[
            "Hips",
            "LeftUpLeg",
            "Spine",
            "LeftShoulder",
            "LeftArm",
            "RightArm",
        ]);
        assert_eq!(find(&cmu), Some([0, 4, 5]));
        let bandai = names(&["joint_Root", "Hips", "Chest", "Shoulder_L", "Shoulder_R"]);
        assert_eq!(find(&bandai), Some([1, 3, 4]));
        let pig = names(&["RFHD", "C7", "T10", "LSHO", "LELB", "RSHO"]);
        assert_eq!(find(&pig), Some([1, 3, 5]));
        let trc = names(&["R.Shoulder", "L.Shoulder", "C7", "IJ"]);
        assert_eq!(find(&trc), Some([2, 1, 0]));
        assert_eq!(find(&names(&["M1", "M2", "M3"])), None);
        let f = feet(&names(&["LTOE", "LKNE", "RightFoot", "R.Heel", "C7"]), 5);
        assert_eq!(f, vec![true, false, true, true, false]);
    }

    #[test]
    fn the_vertical_axis_is_the_tallest() {
        // A 1.7 m tall, 0.5 m wide, 0.3 m deep box of points, z up.
        let mut d = Vec::new();
        for f in 0..10 {
            for &(x, y, z) in &[(0.0, 0.0, 0.0), (0.5, 0.3, 1.7), (0.2, 0.1, 0.9)] {
                d.extend_from_slice(&[x + f as f32, y, z]);
            }
        }
        assert_eq!(vertical_axis(&d, 3, None), 2);
    }

    #[test]
    fn local_and_world_are_inverse_and_the_shoulders_lie_on_the_first_axis() {
        for up in 0..3u8 {
            let torso = [0.1, 1.0, -0.3, -0.2, 1.4, 0.2, 0.3, 1.45, -0.1];
            let p = placement(&torso, up);
            let x = [0.7, -0.4, 2.5];
            let back = to_world(&p, up, to_local(&p, up, x));
            for k in 0..3 {
                assert!((back[k] - x[k]).abs() < 1e-12);
            }
            let (_, b) = horizontal(up);
            let l = to_local(&p, up, [torso[3], torso[4], torso[5]]);
            let r = to_local(&p, up, [torso[6], torso[7], torso[8]]);
            assert!(
                (r[b] - l[b]).abs() < 1e-12,
                "shoulders differ across the body"
            );
        }
    }
}
