//! glTF 2.0 out: a binary `.glb`, or a `.gltf` (JSON with its buffer embedded as a data
//! URI), holding the take as nodes and one animation. Every node carries one small shared
//! mesh (an octahedron 3 cm across), so that a viewer shows the joints or markers at once
//! and importers that refuse a scene without meshes or materials (assimp) open it.
//!
//! - **A skeleton take** is one node per joint and End Site (names kept, parents as in the
//!   file), resting at its offset. The animation has a rotation channel (unit quaternions,
//!   each joint's rotation channels composed in their order, as BVH does) for every joint
//!   that rotates, and a translation channel for every joint with position channels (the
//!   root; some exporters give every joint position channels).
//! - **A marker take** is one node per point, each with a translation channel. A missing
//!   sample holds the point at its last position (the first it has, before it appears), and
//!   a scale channel with STEP interpolation hides it (scale 0) until it is seen again.
//!
//! glTF is metres and +Y up: the read path turns the take so before it gets here. Samplers
//! are LINEAR at the take's (or the requested) rate, so a player that slerps between keys
//! plays the frames as decoded. Rotations are kept on one hemisphere from frame to frame, so
//! that interpolation takes the short way. Every buffer view is one accessor's, tightly
//! packed (animation data may not be strided).

use base64::Engine;
use nalgebra::{UnitQuaternion, Vector3};
use serde_json::{json, Value};

use crate::motion::skeleton::{translation, Joint};

/// What the file shows.
pub enum Figure<'a> {
    /// A skeleton and its channel values, `frames × channels` (metres, degrees).
    Skeleton {
        joints: &'a [Joint],
        values: &'a [f64],
    },
    /// Points and their positions, `frames × points × 3` (metres; NaN where missing).
    Markers {
        names: &'a [String],
        positions: &'a [f64],
    },
}

/// A take to write as glTF.
pub struct Scene<'a> {
    pub name: &'a str,
    pub figure: Figure<'a>,
    pub frames: usize,
    pub fps: f64,
    /// The scene's `extras` (which take, its bound and codec).
    pub extras: Value,
}

/// The scene of a whole take `m`, named `name`, handed to `write` (the glTF and FBX writers
/// take the same scene).
pub fn with_scene<T>(
    m: &crate::motion::Motion,
    name: &str,
    extras: Value,
    write: impl FnOnce(&Scene<'_>) -> T,
) -> T {
    let positions: Vec<f64>;
    let figure = match &m.skeleton {
        Some(s) => Figure::Skeleton {
            joints: &s.joints,
            values: &s.values,
        },
        None => {
            positions = m.positions().iter().map(|&v| f64::from(v)).collect();
            Figure::Markers {
                names: &m.point_names,
                positions: &positions,
            }
        }
    };
    write(&Scene {
        name,
        figure,
        frames: m.frame_count(),
        fps: m.fps,
        extras,
    })
}

/// A whole take as glTF (`binary`: GLB), named `name`; it must be in metres and +Y up
/// already ([`crate::motion::transform::whole::apply`] with those).
pub fn of_motion(m: &crate::motion::Motion, name: &str, binary: bool, extras: Value) -> Vec<u8> {
    with_scene(m, name, extras, |scene| {
        if binary {
            glb(scene)
        } else {
            gltf(scene)
        }
    })
}

/// Bytes of a GLB of `scene`, in all: for sizes checked before anything is built.
pub fn glb_len_bound(frames: usize, nodes: usize) -> u64 {
    // Times, and per node a translation (12 bytes), a rotation (16) or a scale (12) a
    // frame; the JSON is a few hundred bytes a node; the gizmo a few hundred bytes.
    frames as u64 * (4 + nodes as u64 * 40) + nodes as u64 * 1024 + 8192
}

/// The binary glTF (`.glb`) of `scene`.
pub fn glb(scene: &Scene<'_>) -> Vec<u8> {
    let (doc, bin) = build(scene, None);
    pack_glb(&doc, &bin)
}

/// A GLB of a document and its one buffer: the JSON chunk padded with spaces, the binary
/// chunk with zeros, each to 4 bytes.
pub(super) fn pack_glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json = serde_json::to_vec(doc).expect("glTF JSON serialises");
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let padded = bin.len().next_multiple_of(4);
    let total = 12 + 8 + json.len() + 8 + padded;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(padded as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(bin);
    out.resize(total, 0);
    out
}

/// The JSON glTF (`.gltf`) of `scene`, its buffer embedded as a base64 data URI.
pub fn gltf(scene: &Scene<'_>) -> Vec<u8> {
    let (doc, _) = build(scene, Some(()));
    serde_json::to_vec_pretty(&doc).expect("glTF JSON serialises")
}

/// The buffer being laid out, and the accessors and views over it.
#[derive(Default)]
struct Buffer {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Buffer {
    /// The gizmo every node shows: an octahedron of `radius` metres (positions and
    /// indices, in views for vertex data), its material and its mesh; the mesh's index.
    fn gizmo(&mut self, radius: f32) -> (Value, Value) {
        let r = radius;
        let vertices = [
            r, 0.0, 0.0, -r, 0.0, 0.0, 0.0, r, 0.0, 0.0, -r, 0.0, 0.0, 0.0, r, 0.0, 0.0, -r,
        ];
        let position = self.accessor("VEC3", 3, &vertices, true);
        self.views[self.accessors[position]["bufferView"].as_u64().unwrap_or(0) as usize]
            ["target"] = json!(34962);
        // Eight faces, counter-clockwise seen from outside.
        let faces: [u16; 24] = [
            0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5,
        ];
        let offset = self.bin.len();
        for i in faces {
            self.bin.extend_from_slice(&i.to_le_bytes());
        }
        self.views.push(json!({
            "buffer": 0,
            "byteOffset": offset,
            "byteLength": faces.len() * 2,
            "target": 34963,
        }));
        self.accessors.push(json!({
            "bufferView": self.views.len() - 1,
            "componentType": 5123,
            "count": faces.len(),
            "type": "SCALAR",
        }));
        let indices = self.accessors.len() - 1;
        let material = json!({
            "name": "joint",
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.12, 0.37, 0.75, 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 1.0,
            },
        });
        let mesh = json!({
            "name": "joint",
            "primitives": [{ "attributes": { "POSITION": position }, "indices": indices, "material": 0 }],
        });
        (material, mesh)
    }

    /// One accessor of `kind` ("SCALAR", "VEC3", "VEC4") over `values` (f32), in a view
    /// of its own; with min/max when `bounds`.
    fn accessor(&mut self, kind: &str, width: usize, values: &[f32], bounds: bool) -> usize {
        let offset = self.bin.len();
        for v in values {
            self.bin.extend_from_slice(&v.to_le_bytes());
        }
        self.views.push(json!({
            "buffer": 0,
            "byteOffset": offset,
            "byteLength": values.len() * 4,
        }));
        let mut a = json!({
            "bufferView": self.views.len() - 1,
            "componentType": 5126,
            "count": values.len() / width,
            "type": kind,
        });
        if bounds {
            let mut lo = vec![f32::INFINITY; width];
            let mut hi = vec![f32::NEG_INFINITY; width];
            for row in values.chunks_exact(width) {
                for (k, &v) in row.iter().enumerate() {
                    lo[k] = lo[k].min(v);
                    hi[k] = hi[k].max(v);
                }
            }
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }
}

/// The document and its buffer; with `embed`, the buffer as a data URI in the document.
fn build(scene: &Scene<'_>, embed: Option<()>) -> (Value, Vec<u8>) {
    let mut buf = Buffer::default();
    let times: Vec<f32> = (0..scene.frames)
        .map(|f| (f as f64 / scene.fps) as f32)
        .collect();
    let time = (scene.frames > 0).then(|| buf.accessor("SCALAR", 1, &times, true));
    let mut nodes = Vec::new();
    let mut samplers = Vec::new();
    let mut channels = Vec::new();
    let mut animate = |node: usize, path: &str, accessor: usize, step: bool| {
        samplers.push(json!({
            "input": time.expect("animated only with frames"),
            "output": accessor,
            "interpolation": if step { "STEP" } else { "LINEAR" },
        }));
        channels.push(json!({
            "sampler": samplers.len() - 1,
            "target": { "node": node, "path": path },
        }));
    };
    let roots: Vec<usize> = match &scene.figure {
        Figure::Skeleton { joints, values } => {
            let width: usize = joints.iter().map(|j| j.channels.len()).sum();
            let mut k = 0;
            for (i, j) in joints.iter().enumerate() {
                let n = j.channels.len();
                let children: Vec<usize> = (i + 1..joints.len())
                    .filter(|&c| joints[c].parent == Some(i))
                    .collect();
                let mut node = json!({ "name": j.name, "translation": j.offset.map(|v| v as f32) });
                if !children.is_empty() {
                    node["children"] = json!(children);
                }
                nodes.push(node);
                let rotates = j.channels.iter().any(|c| c.rotation_axis().is_some());
                let moves = j.channels.iter().any(|c| c.rotation_axis().is_none());
                if scene.frames > 0 && moves {
                    let t: Vec<f32> = (0..scene.frames)
                        .flat_map(|f| {
                            translation(j, &values[f * width + k..f * width + k + n])
                                .map(|v| v as f32)
                        })
                        .collect();
                    let a = buf.accessor("VEC3", 3, &t, false);
                    animate(i, "translation", a, false);
                }
                if scene.frames > 0 && rotates {
                    let mut prev: Option<UnitQuaternion<f64>> = None;
                    let mut q4 = Vec::with_capacity(scene.frames * 4);
                    for f in 0..scene.frames {
                        let vals = &values[f * width + k..f * width + k + n];
                        let mut q = rotation(j, vals);
                        if prev.is_some_and(|p| p.coords.dot(&q.coords) < 0.0) {
                            q = UnitQuaternion::new_unchecked(-q.into_inner());
                        }
                        prev = Some(q);
                        // glTF's order is x, y, z, w.
                        let c = q.coords;
                        q4.extend([c.x as f32, c.y as f32, c.z as f32, c.w as f32]);
                    }
                    let a = buf.accessor("VEC4", 4, &q4, false);
                    animate(i, "rotation", a, false);
                }
                k += n;
            }
            if joints.is_empty() {
                vec![]
            } else {
                vec![0]
            }
        }
        Figure::Markers { names, positions } => {
            let points = names.len();
            for (p, name) in names.iter().enumerate() {
                let at = |f: usize| {
                    let s = &positions[(f * points + p) * 3..][..3];
                    s.iter()
                        .all(|v| v.is_finite())
                        .then(|| [s[0] as f32, s[1] as f32, s[2] as f32])
                };
                let first = (0..scene.frames).find_map(at);
                let mut held = first.unwrap_or([0.0; 3]);
                let mut t = Vec::with_capacity(scene.frames * 3);
                let mut s = Vec::with_capacity(scene.frames * 3);
                for f in 0..scene.frames {
                    let here = at(f);
                    if let Some(v) = here {
                        held = v;
                    }
                    t.extend(held);
                    s.extend([if here.is_some() { 1.0f32 } else { 0.0 }; 3]);
                }
                nodes.push(json!({ "name": name, "translation": first.unwrap_or([0.0; 3]) }));
                if scene.frames > 0 {
                    let a = buf.accessor("VEC3", 3, &t, false);
                    animate(p, "translation", a, false);
                    if s.contains(&0.0) {
                        let a = buf.accessor("VEC3", 3, &s, false);
                        animate(p, "scale", a, true);
                    }
                }
            }
            (0..points).collect()
        }
    };
    // The shared gizmo, after the animation's data (the times stay accessor 0).
    let (material, mesh) = buf.gizmo(0.015);
    for node in &mut nodes {
        node["mesh"] = json!(0);
    }
    let mut buffer = json!({ "byteLength": buf.bin.len() });
    if embed.is_some() {
        buffer["uri"] = json!(format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&buf.bin)
        ));
    }
    let mut doc = json!({
        "asset": { "version": "2.0", "generator": concat!("mocapstore ", env!("CARGO_PKG_VERSION")) },
        "scene": 0,
        "scenes": [{ "name": scene.name, "nodes": roots, "extras": scene.extras }],
        "nodes": nodes,
        "meshes": [mesh],
        "materials": [material],
    });
    if !channels.is_empty() {
        doc["animations"] =
            json!([{ "name": scene.name, "samplers": samplers, "channels": channels }]);
    }
    doc["buffers"] = json!([buffer]);
    doc["bufferViews"] = json!(buf.views);
    doc["accessors"] = json!(buf.accessors);
    (doc, buf.bin)
}

/// A joint's rotation in one frame: its rotation channels composed in their order.
fn rotation(j: &Joint, vals: &[f64]) -> UnitQuaternion<f64> {
    let mut q = UnitQuaternion::identity();
    for (&c, &v) in j.channels.iter().zip(vals) {
        if let Some(axis) = c.rotation_axis() {
            let mut a = Vector3::zeros();
            a[axis] = 1.0;
            q *= UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(a), v.to_radians());
        }
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::synthetic::dancer_bvh;

    fn dancer() -> crate::motion::Motion {
        crate::motion::formats::read(dancer_bvh(30, 30.0, 1, 6).as_bytes(), &Default::default())
            .unwrap()
            .motion
    }

    fn parse_glb(b: &[u8]) -> (Value, &[u8]) {
        assert_eq!(&b[..4], b"glTF");
        let total = u32::from_le_bytes(b[8..12].try_into().unwrap()) as usize;
        assert_eq!(total, b.len());
        let jl = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        assert_eq!(&b[16..20], b"JSON");
        let doc: Value = serde_json::from_slice(&b[20..20 + jl]).unwrap();
        let bin = &b[20 + jl + 8..];
        assert_eq!(&b[20 + jl + 4..20 + jl + 8], b"BIN\0");
        (doc, bin)
    }

    fn floats(doc: &Value, bin: &[u8], accessor: usize) -> Vec<f32> {
        let a = &doc["accessors"][accessor];
        let v = &doc["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
        let at = v["byteOffset"].as_u64().unwrap() as usize;
        let len = v["byteLength"].as_u64().unwrap() as usize;
        bin[at..at + len]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    /// Evaluating the file's nodes at each frame (TRS down the tree) gives FK's positions.
    #[test]
    fn a_skeleton_evaluates_to_its_joint_positions() {
        let m = dancer();
        let s = m.skeleton.as_ref().unwrap();
        let scene = Scene {
            name: "dance",
            figure: Figure::Skeleton {
                joints: &s.joints,
                values: &s.values,
            },
            frames: s.frame_count(),
            fps: m.fps,
            extras: json!({"id": "x"}),
        };
        let bytes = glb(&scene);
        let (doc, bin) = parse_glb(&bytes);
        let n = s.joints.len();
        let mut t: Vec<Vec<f32>> = doc["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|node| {
                let v = node["translation"].as_array().unwrap();
                let per: Vec<f32> = v.iter().map(|x| x.as_f64().unwrap() as f32).collect();
                per.repeat(s.frame_count())
            })
            .collect();
        let mut r: Vec<Vec<f32>> = vec![[0.0, 0.0, 0.0, 1.0].repeat(s.frame_count()); n];
        for ch in doc["animations"][0]["channels"].as_array().unwrap() {
            let node = ch["target"]["node"].as_u64().unwrap() as usize;
            let sampler =
                &doc["animations"][0]["samplers"][ch["sampler"].as_u64().unwrap() as usize];
            let out = floats(&doc, bin, sampler["output"].as_u64().unwrap() as usize);
            match ch["target"]["path"].as_str().unwrap() {
                "translation" => t[node] = out,
                "rotation" => r[node] = out,
                p => panic!("{p}"),
            }
        }
        let fk = s.forward_kinematics();
        for f in 0..s.frame_count() {
            let mut world: Vec<(UnitQuaternion<f64>, Vector3<f64>)> = Vec::new();
            for (i, j) in s.joints.iter().enumerate() {
                let q = &r[i][f * 4..f * 4 + 4];
                let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    q[3] as f64,
                    q[0] as f64,
                    q[1] as f64,
                    q[2] as f64,
                ));
                let tr = Vector3::new(
                    t[i][f * 3] as f64,
                    t[i][f * 3 + 1] as f64,
                    t[i][f * 3 + 2] as f64,
                );
                let w = match j.parent {
                    Some(p) => (world[p].0 * q, world[p].1 + world[p].0 * tr),
                    None => (q, tr),
                };
                for k in 0..3 {
                    let want = fk[(f * n + i) * 3 + k];
                    assert!(
                        (w.1[k] - want).abs() < 1e-3,
                        "frame {f} joint {} axis {k}: {} vs {want}",
                        j.name,
                        w.1[k]
                    );
                }
                world.push(w);
            }
        }
        // The JSON form holds the same buffer, embedded.
        let doc2: Value = serde_json::from_slice(&gltf(&scene)).unwrap();
        let uri = doc2["buffers"][0]["uri"].as_str().unwrap();
        let b64 = uri
            .strip_prefix("data:application/octet-stream;base64,")
            .unwrap();
        assert_eq!(
            base64::engine::general_purpose::STANDARD
                .decode(b64)
                .unwrap(),
            bin
        );
    }

    /// A marker's gap holds its last position and hides it with a STEP scale key.
    #[test]
    fn marker_gaps_hold_and_hide() {
        let names = vec!["a".to_string(), "b".to_string()];
        let nan = f64::NAN;
        let positions = [
            0.0, 1.0, 0.0, nan, nan, nan, //
            0.1, 1.0, 0.0, 2.0, 0.0, 0.0, //
            0.2, 1.0, 0.0, nan, nan, nan,
        ];
        let bytes = glb(&Scene {
            name: "m",
            figure: Figure::Markers {
                names: &names,
                positions: &positions,
            },
            frames: 3,
            fps: 100.0,
            extras: Value::Null,
        });
        let (doc, bin) = parse_glb(&bytes);
        let anim = &doc["animations"][0];
        assert_eq!(anim["channels"].as_array().unwrap().len(), 3);
        let out = |c: usize| {
            let s = anim["channels"][c]["sampler"].as_u64().unwrap() as usize;
            floats(
                &doc,
                bin,
                anim["samplers"][s]["output"].as_u64().unwrap() as usize,
            )
        };
        assert_eq!(out(1), vec![2.0, 0.0, 0.0, 2.0, 0.0, 0.0, 2.0, 0.0, 0.0]);
        assert_eq!(out(2), vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0]);
        assert_eq!(anim["samplers"][2]["interpolation"], "STEP");
        let times = floats(&doc, bin, 0);
        assert_eq!(times, vec![0.0, 0.01, 0.02]);
        assert_eq!(doc["accessors"][0]["max"][0].as_f64().unwrap() as f32, 0.02);
    }
}
