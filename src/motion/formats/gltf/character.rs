//! A glTF character with motion on it: the character file as it was uploaded (meshes,
//! skin, materials, textures, its node tree), its own animations replaced by one that moves
//! its joint nodes. What a game engine, Blender or three.js opens and plays at once, the
//! mesh deforming, with no retargeting of its own.
//!
//! The motion is on the character's skeleton ([`super::read::bind_pose`]): each joint's
//! channels give its rotation and translation relative to its parent joint, in metres with
//! no scale. The file's nodes may scale (an `Armature` of scale 0.01 over a rig in
//! centimetres): a joint's node is written with the rotation the channels give and the
//! translation divided by its parent's world scale; the head joint's, relative to the
//! fixed node above it.

use base64::Engine;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde_json::{json, Value};

use super::read::{bind_pose, Bind};
use crate::motion::error::{Error, Location, Result};
use crate::motion::format::Format;
use crate::motion::formats::ReadLimits;
use crate::motion::skeleton::{local_rotation, translation, Joint};

fn err(reason: impl Into<String>) -> Error {
    Error::parse(Format::Gltf, Location::Whole, reason)
}

/// Motion to put on a character.
pub struct Motion<'a> {
    pub name: &'a str,
    /// The character's skeleton (as [`bind_pose`] reads it) and its channel values,
    /// `frames × channels` (metres, degrees).
    pub joints: &'a [Joint],
    pub values: &'a [f64],
    pub frames: usize,
    pub fps: f64,
    /// The animation's `extras` (which take, its bound and codec).
    pub extras: Value,
}

/// Bytes of the character file with `motion` on it, at most: for sizes checked before
/// anything is built.
pub fn len_bound(character: usize, frames: usize, joints: usize) -> u64 {
    character as u64 + super::glb_len_bound(frames, joints)
}

/// The character file `character` (a GLB, or a `.gltf` with its one buffer embedded)
/// playing `motion`: a GLB when `binary`, else a `.gltf` with its buffer embedded.
pub fn animate(
    character: &[u8],
    limits: &ReadLimits,
    motion: &Motion<'_>,
    binary: bool,
) -> Result<Vec<u8>> {
    let bind = bind_pose(character, limits)?;
    let same = bind.skeleton.joints.len() == motion.joints.len()
        && bind
            .skeleton
            .joints
            .iter()
            .zip(motion.joints)
            .all(|(a, b)| a.name == b.name && a.parent == b.parent && a.channels == b.channels);
    if !same {
        return Err(err(
            "the motion is not on this character's skeleton (its joints differ)",
        ));
    }
    let cc: usize = motion.joints.iter().map(|j| j.channels.len()).sum();
    if motion.frames == 0 {
        return Err(err("no frames to put on the character"));
    }
    if motion.values.len() != motion.frames * cc {
        return Err(err(format!(
            "{} channel values for {} frames of {cc} channels",
            motion.values.len(),
            motion.frames
        )));
    }
    let (mut doc, mut bin) = document(character)?;
    let above = Above::of(&bind);
    let (times, tracks) = tracks(&bind, &above, motion);
    // A joint node given as a matrix cannot be animated (the specification forbids it): it
    // is given as the translation, rotation and scale of its bind pose instead.
    let cc_rest: Vec<usize> = offsets(&bind.skeleton.joints);
    for (k, j) in bind.skeleton.joints.iter().enumerate() {
        let node = &mut doc["nodes"][bind.nodes[k]];
        if node.get("matrix").is_none() {
            continue;
        }
        let vals = &bind.skeleton.values[cc_rest[k]..cc_rest[k] + j.channels.len()];
        let (t, q) = above.local(&bind, j, vals);
        let parent = j.parent.map_or(above.scale, |p| bind.scales[p]);
        let s = bind.scales[k] / parent;
        let c = q.coords;
        if let Some(n) = node.as_object_mut() {
            n.remove("matrix");
            n.insert("translation".into(), json!([t.x, t.y, t.z]));
            n.insert("rotation".into(), json!([c.x, c.y, c.z, c.w]));
            n.insert("scale".into(), json!([s, s, s]));
        }
    }

    // The animation's data after the file's own, each accessor in a view of its own.
    let mut views = doc["bufferViews"].as_array().cloned().unwrap_or_default();
    let mut accessors = doc["accessors"].as_array().cloned().unwrap_or_default();
    let mut accessor = |kind: &str, width: usize, values: &[f32], bounds: bool| -> usize {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let offset = bin.len();
        for v in values {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": values.len() * 4}));
        let mut a = json!({
            "bufferView": views.len() - 1,
            "componentType": 5126,
            "count": values.len() / width,
            "type": kind,
        });
        if bounds {
            let lo = values.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            a["min"] = json!([lo]);
            a["max"] = json!([hi]);
        }
        accessors.push(a);
        accessors.len() - 1
    };
    let input = accessor("SCALAR", 1, &times, true);
    let (mut channels, mut samplers) = (Vec::new(), Vec::new());
    for t in &tracks {
        let (kind, width) = if t.path == "rotation" {
            ("VEC4", 4)
        } else {
            ("VEC3", 3)
        };
        let output = accessor(kind, width, &t.values, false);
        samplers.push(json!({"input": input, "output": output, "interpolation": "LINEAR"}));
        channels.push(json!({
            "sampler": samplers.len() - 1,
            "target": {"node": t.node, "path": t.path},
        }));
    }
    doc["bufferViews"] = Value::Array(views);
    doc["accessors"] = Value::Array(accessors);
    doc["animations"] = json!([{
        "name": motion.name,
        "channels": channels,
        "samplers": samplers,
        "extras": motion.extras,
    }]);
    doc["buffers"] = json!([{"byteLength": bin.len()}]);
    if binary {
        return Ok(super::write::pack_glb(&doc, &bin));
    }
    doc["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    ));
    Ok(serde_json::to_vec(&doc).expect("glTF JSON serialises"))
}

/// One channel of the animation: a node's rotations (x, y, z, w) or translations.
struct Track {
    node: usize,
    path: &'static str,
    values: Vec<f32>,
}

/// Where each joint's channel values start in a frame.
fn offsets(joints: &[Joint]) -> Vec<usize> {
    joints
        .iter()
        .scan(0, |at, j| {
            let here = *at;
            *at += j.channels.len();
            Some(here)
        })
        .collect()
}

/// The fixed node the head joint hangs from, in the world: its position, rotation and
/// (even) scale.
struct Above {
    at: Vector3<f64>,
    rot: UnitQuaternion<f64>,
    scale: f64,
}

impl Above {
    fn of(bind: &Bind) -> Above {
        let m = bind.above;
        let scale = (0..3)
            .map(|c| m.fixed_view::<3, 1>(0, c).norm())
            .sum::<f64>()
            / 3.0;
        let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned() / scale;
        Above {
            at: Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
            rot: UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_eps(
                &r,
                1e-12,
                64,
                Rotation3::identity(),
            )),
            scale,
        }
    }

    /// Joint `j`'s node-local translation and rotation for its channel values `vals`: the
    /// channels give them relative to the parent joint in metres with no scale; the file's
    /// node divides the translation by its parent's world scale, and the head joint's is
    /// relative to the node above it.
    fn local(&self, bind: &Bind, j: &Joint, vals: &[f64]) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
            local_rotation(j, vals),
        ));
        let t = Vector3::from(translation(j, vals));
        match j.parent {
            Some(p) => (t / bind.scales[p], q),
            None => (
                self.rot.inverse() * (t - self.at) / self.scale,
                self.rot.inverse() * q,
            ),
        }
    }
}

/// The key times and, for every joint with channels, its node's rotation (and, where it
/// moves, translation) track.
fn tracks(bind: &Bind, above: &Above, motion: &Motion<'_>) -> (Vec<f32>, Vec<Track>) {
    let times = (0..motion.frames)
        .map(|f| (f as f64 / motion.fps) as f32)
        .collect();
    let cc: usize = motion.joints.iter().map(|j| j.channels.len()).sum();
    let mut tracks = Vec::new();
    let mut start = 0;
    for (k, j) in motion.joints.iter().enumerate() {
        let n = j.channels.len();
        let at = start;
        start += n;
        if n == 0 {
            continue;
        }
        let rotates = j.channels.iter().any(|c| c.rotation_axis().is_some());
        let moves = j.channels.iter().any(|c| c.rotation_axis().is_none());
        let mut rotations = Vec::with_capacity(if rotates { motion.frames * 4 } else { 0 });
        let mut translations = Vec::with_capacity(if moves { motion.frames * 3 } else { 0 });
        let mut last: Option<UnitQuaternion<f64>> = None;
        for f in 0..motion.frames {
            let vals = &motion.values[f * cc + at..f * cc + at + n];
            let (t, mut q) = above.local(bind, j, vals);
            // Kept on one hemisphere from key to key, so that interpolation goes the short way.
            if last.is_some_and(|l| l.coords.dot(&q.coords) < 0.0) {
                q = UnitQuaternion::new_unchecked(-q.into_inner());
            }
            last = Some(q);
            if rotates {
                let c = q.coords;
                rotations.extend([c.x as f32, c.y as f32, c.z as f32, c.w as f32]);
            }
            if moves {
                translations.extend([t.x as f32, t.y as f32, t.z as f32]);
            }
        }
        let node = bind.nodes[k];
        if rotates {
            tracks.push(Track {
                node,
                path: "rotation",
                values: rotations,
            });
        }
        if moves {
            tracks.push(Track {
                node,
                path: "translation",
                values: translations,
            });
        }
    }
    (times, tracks)
}

/// The character's document and its one buffer's bytes.
fn document(character: &[u8]) -> Result<(Value, Vec<u8>)> {
    let (json, bin) = super::read::split(character)?;
    if json.len() > crate::limits::MAX_CHARACTER_JSON_BYTES {
        return Err(Error::Limit {
            what: "character JSON chunk bytes",
            actual: json.len() as u64,
            limit: crate::limits::MAX_CHARACTER_JSON_BYTES as u64,
        });
    }
    let doc: Value = serde_json::from_slice(json).map_err(|e| err(format!("its JSON: {e}")))?;
    let buffers = doc["buffers"].as_array().map_or(0, Vec::len);
    if buffers != 1 {
        return Err(err(format!(
            "a character file of {buffers} buffers; one is written back (a GLB's, or one \
             embedded)"
        )));
    }
    let declared = doc["buffers"][0]["byteLength"]
        .as_u64()
        .ok_or_else(|| err("its buffer states no byteLength"))? as usize;
    let mut data = match (doc["buffers"][0]["uri"].as_str(), bin) {
        (None, Some(bin)) => bin.to_vec(),
        (Some(uri), _) => {
            let payload = uri
                .strip_prefix("data:")
                .and_then(|rest| rest.split_once(";base64,"))
                .map(|(_, data)| data)
                .ok_or_else(|| err("its buffer lies in another file"))?;
            base64::engine::general_purpose::STANDARD
                .decode(payload)
                .map_err(|e| err(format!("its buffer's data URI: {e}")))?
        }
        (None, None) => return Err(err("its buffer has no data")),
    };
    if data.len() < declared {
        return Err(err(format!(
            "its buffer says it holds {declared} bytes but has {}",
            data.len()
        )));
    }
    data.truncate(declared);
    Ok((doc, data))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::formats::{read, ReadOptions};

    fn ybot() -> Option<Vec<u8>> {
        let root = std::env::var("MOCAP_CORPUS").unwrap_or_else(|_| "../shared/data".into());
        std::fs::read(format!("{root}/gltf/mixamo_ybot_character.glb")).ok()
    }

    /// The Y Bot at its bind pose: the skeleton stands as the file's nodes do. Written back
    /// with its bind pose as a one-frame animation and read again as a take, every joint is
    /// where the character's own nodes put it (the reader composes the file's node tree,
    /// Armature and scales included, independently of how the animation was made).
    #[test]
    fn the_ybot_stands_in_its_bind_pose_and_plays_back_in_place() {
        let Some(bytes) = ybot() else {
            eprintln!("no corpus: skipped");
            return;
        };
        let limits = ReadOptions::default().limits;
        let bind = bind_pose(&bytes, &limits).unwrap();
        let s = &bind.skeleton;
        assert_eq!(s.joints.len(), 67, "{:?}", s.joints.len());
        assert_eq!(s.joints[0].name, "mixamorig:Hips");
        assert!(bind.scales.iter().all(|&k| (k - 0.01).abs() < 1e-6));
        let rest = s.forward_kinematics();
        let at = |name: &str| {
            let k = s.joints.iter().position(|j| j.name == name).unwrap();
            [rest[k * 3], rest[k * 3 + 1], rest[k * 3 + 2]]
        };
        // Standing, in metres, Y up: the head well above the feet.
        let (head, foot) = (at("mixamorig:Head"), at("mixamorig:LeftFoot"));
        assert!(head[1] - foot[1] > 1.3, "{head:?} {foot:?}");
        let frames = 3;
        let values: Vec<f64> = (0..frames).flat_map(|_| s.values.clone()).collect();
        let out = animate(
            &bytes,
            &limits,
            &Motion {
                name: "rest",
                joints: &s.joints,
                values: &values,
                frames,
                fps: 30.0,
                extras: json!({}),
            },
            true,
        )
        .unwrap();
        let back = read(&out, &ReadOptions::default()).unwrap().motion;
        assert_eq!(back.frame_count(), frames);
        let pos = back.positions();
        for (k, j) in s.joints.iter().enumerate() {
            let b = back.point_names.iter().position(|n| *n == j.name).unwrap();
            for c in 0..3 {
                let d = (f64::from(pos[b * 3 + c]) - rest[k * 3 + c]).abs();
                assert!(d < 1e-4, "{} axis {c}: {d} m", j.name);
            }
        }
        // The mesh and skin came along.
        let (json, _) = super::super::read::split(&out).unwrap();
        let doc: Value = serde_json::from_slice(json).unwrap();
        assert_eq!(doc["meshes"].as_array().unwrap().len(), 2);
        assert_eq!(doc["skins"].as_array().unwrap().len(), 1);
        assert_eq!(doc["animations"].as_array().unwrap().len(), 1);
    }

    /// A small character: an Armature moved, turned (Z-up to Y-up) and scaled (cm to m)
    /// over a hips → spine → head chain, the spine given as a matrix. Motion that is not
    /// the bind pose (the hips travelling, the spine turning) written onto it and read back
    /// as a take (the reader composes the file's node tree) is where forward kinematics of
    /// the skeleton puts it; the spine's matrix became a translation, rotation and scale.
    #[test]
    fn motion_on_a_moved_turned_scaled_rig_plays_where_it_was_put() {
        let (c, s) = (20f64.to_radians().cos(), 20f64.to_radians().sin());
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let doc = json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [
                {"name": "Armature", "translation": [0.5, 0.0, -0.25],
                 "rotation": [-h, 0.0, 0.0, h], "scale": [0.01, 0.01, 0.01], "children": [1]},
                {"name": "hips", "translation": [0.0, 0.0, 100.0], "children": [2]},
                {"name": "spine", "children": [3],
                 "matrix": [c, 0.0, -s, 0.0, 0.0, 1.0, 0.0, 0.0, s, 0.0, c, 0.0, 0.0, 0.0, 30.0, 1.0]},
                {"name": "head", "translation": [0.0, 0.0, 25.0]}
            ],
            "skins": [{"joints": [1, 2, 3]}],
            "buffers": [{"byteLength": 4, "uri": "data:application/octet-stream;base64,AAAAAA=="}]
        });
        let bytes = serde_json::to_vec(&doc).unwrap();
        let limits = ReadOptions::default().limits;
        let bind = bind_pose(&bytes, &limits).unwrap();
        let s = &bind.skeleton;
        assert_eq!(s.joints.len(), 3);
        // At rest, in the world: the hips 1 m above the Armature's place (Z-up turned to
        // Y-up), the head 0.55 m above them, leaning 20° about the file's Y.
        let rest = s.forward_kinematics();
        assert!(
            (rest[1] - 1.0).abs() < 1e-9 && (rest[0] - 0.5).abs() < 1e-9,
            "{rest:?}"
        );
        let cc = s.channel_count();
        let frames = 3;
        let mut values = Vec::new();
        for f in 0..frames {
            let mut v = s.values.clone();
            v[0] += 0.1 * f as f64; // the hips' position channels come first
            v[2] += 0.05 * f as f64;
            let spine = s.joints[0].channels.len();
            v[spine] += 15.0 * f as f64; // the spine's first rotation channel
            values.extend(v);
        }
        assert_eq!(values.len(), frames * cc);
        let out = animate(
            &bytes,
            &limits,
            &Motion {
                name: "moved",
                joints: &s.joints,
                values: &values,
                frames,
                fps: 10.0,
                extras: json!({}),
            },
            false,
        )
        .unwrap();
        let written: Value = serde_json::from_slice(&out).unwrap();
        let spine = &written["nodes"][2];
        assert!(spine.get("matrix").is_none() && spine["scale"] == json!([1.0, 1.0, 1.0]));
        let back = read(&out, &ReadOptions::default()).unwrap().motion;
        let want = crate::motion::skeleton::Animation::new(s.joints.clone(), values)
            .unwrap()
            .forward_kinematics();
        let got = back.positions();
        assert_eq!(got.len(), want.len());
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                (f64::from(*g) - w).abs() < 1e-5,
                "coordinate {i}: {g} vs {w}"
            );
        }
        // The motion moved: the last frame's head is not where the first's was.
        assert!((want[want.len() - 3] - want[6]).abs() > 0.1);
    }

    #[test]
    fn a_file_without_a_skin_is_no_character() {
        let doc = br#"{"asset": {"version": "2.0"}, "nodes": [{"name": "a"}]}"#;
        let e = bind_pose(doc, &ReadOptions::default().limits)
            .err()
            .unwrap();
        assert!(e.to_string().contains("no skin"), "{e}");
    }
}
