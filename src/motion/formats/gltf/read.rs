//! glTF 2.0 in (`.glb`, or `.gltf` with its buffers embedded as data URIs): a skeleton
//! take from a file's skin or animated node tree and one of its animations, evaluated as
//! a player does.
//!
//! - **The joints** are the largest skin's (the nodes between them included), or, where
//!   the file has no skin, the nodes its animation moves; headed by the lowest node above
//!   all of them, with the plain end nodes below them (a `HeadTop_End`) as end sites.
//!   Nodes that carry meshes or cameras and no joint are left out.
//! - **The animation** is sampled at its keyframe rate (the spacing of its keys) or the
//!   rate asked for, from its first key to its last, with each sampler's interpolation:
//!   STEP holds, LINEAR lerps translations and scales and slerps rotations the short way,
//!   CUBICSPLINE is the Hermite spline of its tangents (rotations normalised after), as
//!   the specification's Appendix C gives them. Every frame composes the whole node tree,
//!   so what lies above the skeleton (an `Armature` that turns Blender's Z-up into Y-up and
//!   scales centimetres to metres) is in the joints' world places.
//! - glTF is metres and +Y up by its specification: the take says so.
//!
//! Every index and byte range the document states is checked against what the file holds
//! before it is read; nothing is allocated from a count the file only claims.

use std::collections::HashMap;
use std::rc::Rc;

use base64::Engine;
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3, Vector4};
use serde::de::IgnoredAny;
use serde::Deserialize;

use super::super::posed::{place, Posed, Skeletal};
use super::super::{Extras, Format, Parsed, Pick, ReadOptions};
use crate::motion::body::{Axis, Prior};
use crate::motion::error::{Error, Location, Result};
use crate::motion::model::Motion;

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

/// The frame rate of an animation whose keys do not tell one (a single key).
const LONE_KEY_FPS: f64 = 30.0;

fn err(reason: impl Into<String>) -> Error {
    Error::parse(Format::Gltf, Location::Whole, reason)
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct Doc {
    asset: Asset,
    scene: Option<usize>,
    #[serde(default)]
    scenes: Vec<Scene>,
    #[serde(default)]
    nodes: Vec<Node>,
    #[serde(default)]
    skins: Vec<Skin>,
    #[serde(default)]
    animations: Vec<Animation>,
    #[serde(default)]
    accessors: Vec<Accessor>,
    #[serde(default)]
    buffer_views: Vec<View>,
    #[serde(default)]
    buffers: Vec<Buffer>,
    #[serde(default)]
    meshes: Vec<IgnoredAny>,
    #[serde(default)]
    materials: Vec<IgnoredAny>,
    #[serde(default)]
    textures: Vec<IgnoredAny>,
    #[serde(default)]
    extensions_required: Vec<String>,
}

#[derive(Deserialize)]
struct Asset {
    version: String,
}

#[derive(Deserialize)]
struct Scene {
    #[serde(default)]
    nodes: Vec<usize>,
}

#[derive(Deserialize)]
struct Node {
    name: Option<String>,
    #[serde(default)]
    children: Vec<usize>,
    matrix: Option<[f64; 16]>,
    translation: Option<[f64; 3]>,
    rotation: Option<[f64; 4]>,
    scale: Option<[f64; 3]>,
    mesh: Option<usize>,
    camera: Option<usize>,
}

#[derive(Deserialize)]
struct Skin {
    joints: Vec<usize>,
}

#[derive(Deserialize)]
struct Animation {
    name: Option<String>,
    channels: Vec<Channel>,
    samplers: Vec<Sampler>,
}

#[derive(Deserialize)]
struct Channel {
    sampler: usize,
    target: Target,
}

#[derive(Deserialize)]
struct Target {
    node: Option<usize>,
    path: String,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "UPPERCASE")]
enum Interpolation {
    #[default]
    Linear,
    Step,
    Cubicspline,
}

#[derive(Deserialize)]
struct Sampler {
    input: usize,
    output: usize,
    #[serde(default)]
    interpolation: Interpolation,
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct Accessor {
    buffer_view: Option<usize>,
    #[serde(default)]
    byte_offset: u64,
    component_type: u32,
    #[serde(default)]
    normalized: bool,
    count: u64,
    #[serde(rename = "type")]
    kind: String,
    sparse: Option<IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct View {
    buffer: usize,
    #[serde(default)]
    byte_offset: u64,
    byte_length: u64,
    byte_stride: Option<u64>,
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct Buffer {
    uri: Option<String>,
    byte_length: u64,
}

/// Whether `bytes` are a glTF JSON document (an object with an `asset`), not a JSON take.
pub(crate) fn is_gltf_json(bytes: &[u8]) -> bool {
    #[derive(Deserialize)]
    struct Head {
        asset: Option<IgnoredAny>,
    }
    serde_json::from_slice::<Head>(bytes).is_ok_and(|h| h.asset.is_some())
}

/// The JSON document and the binary chunk of a GLB, or the document of a `.gltf`.
pub(super) fn split(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>)> {
    if !bytes.starts_with(GLB_MAGIC) {
        return Ok((bytes, None));
    }
    let word = |at: usize| -> Result<u32> {
        bytes
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or_else(|| {
                err(format!(
                    "the GLB ends at byte {} inside a header",
                    bytes.len()
                ))
            })
    };
    let version = word(4)?;
    if version != 2 {
        return Err(err(format!("GLB version {version}; only glTF 2.0 is read")));
    }
    let total = word(8)? as usize;
    if total > bytes.len() {
        return Err(err(format!(
            "the GLB says it is {total} bytes long but {} arrived",
            bytes.len()
        )));
    }
    let (mut json, mut bin) = (None, None);
    let mut at = 12usize;
    while at + 8 <= total {
        let len = word(at)? as usize;
        let kind = word(at + 4)?;
        let body = bytes
            .get(at + 8..(at + 8).saturating_add(len))
            .filter(|_| at + 8 + len <= total)
            .ok_or_else(|| {
                err(format!(
                    "a GLB chunk of {len} bytes at byte {at} runs past the file"
                ))
            })?;
        match kind {
            CHUNK_JSON if json.is_none() => json = Some(body),
            CHUNK_BIN if bin.is_none() => bin = Some(body),
            _ => {}
        }
        at += 8 + len.next_multiple_of(4);
    }
    let json = json.ok_or_else(|| err("the GLB has no JSON chunk"))?;
    Ok((json, bin))
}

/// The bytes of every buffer: the GLB's binary chunk, or a base64 data URI. A file that
/// points elsewhere cannot be read from one upload.
fn buffers(doc: &Doc, bin: Option<&[u8]>) -> Result<Vec<Vec<u8>>> {
    doc.buffers
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let data = match (&b.uri, bin) {
                (None, Some(bin)) if i == 0 => bin.to_vec(),
                (None, _) => {
                    return Err(err(format!(
                        "buffer {i} has no data (no uri, no GLB chunk)"
                    )))
                }
                (Some(uri), _) => {
                    let payload = uri
                        .strip_prefix("data:")
                        .and_then(|rest| rest.split_once(";base64,"))
                        .map(|(_, data)| data)
                        .ok_or_else(|| {
                            err(format!(
                                "buffer {i} lies in another file ({uri:?}); upload a GLB, or a \
                                 .gltf with its buffers embedded"
                            ))
                        })?;
                    base64::engine::general_purpose::STANDARD
                        .decode(payload)
                        .map_err(|e| err(format!("buffer {i}'s data URI: {e}")))?
                }
            };
            if (data.len() as u64) < b.byte_length {
                return Err(err(format!(
                    "buffer {i} says it holds {} bytes but has {}",
                    b.byte_length,
                    data.len()
                )));
            }
            Ok(data)
        })
        .collect()
}

/// Reads accessors, every range checked against its view and buffer, each once: channels
/// that share one are given the same values, and all that is decoded is bounded together
/// (a byte of a normalised accessor is 8 as a number), so that no file can make reading it
/// hold more than its limits allow.
struct Data<'a> {
    doc: &'a Doc,
    buffers: Vec<Vec<u8>>,
    /// By accessor and row width (only one width reads an accessor).
    decoded: HashMap<(usize, usize), Rc<Vec<f64>>>,
    /// Numbers that may still be decoded.
    budget: u64,
}

impl Data<'_> {
    /// Accessor `i` as [`Data::rows`] reads it, decoded once; `times`: key times, which
    /// the specification has be floats.
    fn get(&mut self, i: usize, width: usize, what: &str, times: bool) -> Result<Rc<Vec<f64>>> {
        if let Some(v) = self.decoded.get(&(i, width)) {
            return Ok(v.clone());
        }
        let a = self
            .doc
            .accessors
            .get(i)
            .ok_or_else(|| err(format!("{what}: accessor {i} does not exist")))?;
        if times && a.component_type != 5126 {
            return Err(err(format!(
                "{what}: key times (accessor {i}) are not floats"
            )));
        }
        let numbers = a.count.saturating_mul(width as u64);
        if numbers > self.budget {
            return Err(Error::Limit {
                what: "animation values decoded",
                actual: numbers,
                limit: self.budget,
            });
        }
        self.budget -= numbers;
        let v = Rc::new(self.rows(i, width, what)?);
        self.decoded.insert((i, width), v.clone());
        Ok(v)
    }

    /// Accessor `i` as rows of `width` numbers (normalised integers as the specification
    /// maps them to [-1, 1] or [0, 1]).
    fn rows(&self, i: usize, width: usize, what: &str) -> Result<Vec<f64>> {
        let a = self
            .doc
            .accessors
            .get(i)
            .ok_or_else(|| err(format!("{what}: accessor {i} does not exist")))?;
        let comps = match a.kind.as_str() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            "MAT4" => 16,
            other => return Err(err(format!("{what}: accessor {i} is of type {other}"))),
        };
        if comps != width {
            return Err(err(format!(
                "{what}: accessor {i} has {comps} components, not {width}"
            )));
        }
        if a.sparse.is_some() {
            return Err(err(format!(
                "{what}: accessor {i} is sparse, which is not read"
            )));
        }
        let (size, read): (u64, fn(&[u8]) -> f64) = match (a.component_type, a.normalized) {
            (5126, _) => (4, |b| {
                f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            }),
            (5120, true) => (1, |b| (f64::from(b[0] as i8) / 127.0).max(-1.0)),
            (5121, true) => (1, |b| f64::from(b[0]) / 255.0),
            (5122, true) => (2, |b| {
                (f64::from(i16::from_le_bytes([b[0], b[1]])) / 32767.0).max(-1.0)
            }),
            (5123, true) => (2, |b| f64::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0),
            (t, n) => {
                return Err(err(format!(
                    "{what}: accessor {i} has component type {t}{}; animation data is float \
                     or normalised integers",
                    if n { " (normalised)" } else { "" }
                )))
            }
        };
        let element = size * comps as u64;
        let Some(v) = a.buffer_view else {
            // No view: all zeros (the specification's default), bounded like any data.
            let n = a.count.saturating_mul(comps as u64);
            let limit = self.buffers.iter().map(|b| b.len() as u64).sum::<u64>() + 1024;
            if n > limit {
                return Err(err(format!(
                    "{what}: accessor {i} claims {} elements",
                    a.count
                )));
            }
            return Ok(vec![0.0; n as usize]);
        };
        let view = self
            .doc
            .buffer_views
            .get(v)
            .ok_or_else(|| err(format!("{what}: buffer view {v} does not exist")))?;
        let buffer = self
            .buffers
            .get(view.buffer)
            .ok_or_else(|| err(format!("{what}: buffer {} does not exist", view.buffer)))?;
        let stride = view.byte_stride.unwrap_or(element).max(element);
        let span = match a.count {
            0 => 0,
            c => (c - 1).saturating_mul(stride).saturating_add(element),
        };
        let fits = a.byte_offset.saturating_add(span) <= view.byte_length
            && view.byte_offset.saturating_add(view.byte_length) <= buffer.len() as u64;
        if !fits {
            return Err(err(format!(
                "{what}: accessor {i} ({} elements from byte {}) runs past its buffer view {v}",
                a.count, a.byte_offset
            )));
        }
        let start = (view.byte_offset + a.byte_offset) as usize;
        let mut out = Vec::with_capacity(a.count as usize * comps);
        for e in 0..a.count as usize {
            let at = start + e * stride as usize;
            for c in 0..comps {
                let b = at + c * size as usize;
                out.push(read(&buffer[b..b + size as usize]));
            }
        }
        Ok(out)
    }
}

/// What a channel moves.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Path {
    Translation,
    Rotation,
    Scale,
}

impl Path {
    fn width(self) -> usize {
        match self {
            Path::Rotation => 4,
            _ => 3,
        }
    }
}

/// One channel's keys, ready to sample.
struct Track {
    node: usize,
    path: Path,
    interpolation: Interpolation,
    times: Rc<Vec<f64>>,
    /// `keys × width`, or `keys × 3 × width` (in-tangent, value, out-tangent) for
    /// CUBICSPLINE.
    values: Rc<Vec<f64>>,
}

impl Track {
    fn value(&self, k: usize) -> &[f64] {
        let w = self.path.width();
        let at = if self.interpolation == Interpolation::Cubicspline {
            (3 * k + 1) * w
        } else {
            k * w
        };
        &self.values[at..at + w]
    }

    fn tangent(&self, k: usize, out: bool) -> &[f64] {
        let w = self.path.width();
        let at = (3 * k + if out { 2 } else { 0 }) * w;
        &self.values[at..at + w]
    }

    /// The value at time `t`: held before the first key and after the last.
    fn sample(&self, t: f64) -> Vector4<f64> {
        let w = self.path.width();
        let to4 = |s: &[f64]| Vector4::new(s[0], s[1], s[2], if w == 4 { s[3] } else { 0.0 });
        let last = self.times.len() - 1;
        // The key at or before t.
        let k = self.times.partition_point(|&k| k <= t).saturating_sub(1);
        if t <= self.times[0] || k >= last {
            return to4(self.value(if t <= self.times[0] { 0 } else { last }));
        }
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let dt = t1 - t0;
        let s = if dt > 0.0 { (t - t0) / dt } else { 0.0 };
        let (a, b) = (to4(self.value(k)), to4(self.value(k + 1)));
        match self.interpolation {
            Interpolation::Step => a,
            Interpolation::Linear if self.path == Path::Rotation => slerp(a, b, s),
            Interpolation::Linear => a + (b - a) * s,
            Interpolation::Cubicspline => {
                let (s2, s3) = (s * s, s * s * s);
                let out = to4(self.tangent(k, true)) * dt;
                let inn = to4(self.tangent(k + 1, false)) * dt;
                a * (2.0 * s3 - 3.0 * s2 + 1.0)
                    + out * (s3 - 2.0 * s2 + s)
                    + b * (-2.0 * s3 + 3.0 * s2)
                    + inn * (s3 - s2)
            }
        }
    }
}

/// Spherical interpolation of two quaternions (x, y, z, w) the short way; never panics
/// (nearly equal keys are lerped and normalised).
fn slerp(a: Vector4<f64>, b: Vector4<f64>, s: f64) -> Vector4<f64> {
    let (a, b) = (a.normalize(), b.normalize());
    let mut d = a.dot(&b);
    let b = if d < 0.0 {
        d = -d;
        -b
    } else {
        b
    };
    if d > 0.9995 {
        return (a + (b - a) * s).normalize();
    }
    let theta = d.clamp(-1.0, 1.0).acos();
    let sin = theta.sin();
    a * (((1.0 - s) * theta).sin() / sin) + b * ((s * theta).sin() / sin)
}

fn rotation(q: Vector4<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(Quaternion::new(q[3], q[0], q[1], q[2]))
}

/// A node's local transform from its translation, rotation and scale.
fn trs(t: Vector3<f64>, r: UnitQuaternion<f64>, s: Vector3<f64>) -> Matrix4<f64> {
    Matrix4::new_translation(&t) * r.to_homogeneous() * Matrix4::new_nonuniform_scaling(&s)
}

/// A node's resting translation, rotation (x, y, z, w) and scale, or its matrix.
type Rest = (
    Vector3<f64>,
    Vector4<f64>,
    Vector3<f64>,
    Option<Matrix4<f64>>,
);

/// The node tree: each node's parent, and the scene's nodes parents first.
struct Tree {
    parents: Vec<Option<usize>>,
    order: Vec<usize>,
}

fn tree(doc: &Doc, max_depth: u64) -> Result<Tree> {
    let n = doc.nodes.len();
    let mut parents = vec![None; n];
    for (i, node) in doc.nodes.iter().enumerate() {
        for &c in &node.children {
            if c >= n {
                return Err(err(format!("node {i} has child {c}, which does not exist")));
            }
            if parents[c].replace(i).is_some() || c == i {
                return Err(err(format!("node {c} has two parents (or is its own)")));
            }
        }
    }
    let roots: Vec<usize> = match doc.scenes.get(doc.scene.unwrap_or(0)) {
        Some(scene) => scene.nodes.clone(),
        None if doc.scene.is_some() => return Err(err("the default scene does not exist")),
        None => (0..n).filter(|&i| parents[i].is_none()).collect(),
    };
    let mut seen = vec![false; n];
    let mut order = Vec::new();
    let mut stack: Vec<(usize, u64)> = Vec::new();
    for &r in roots.iter().rev() {
        if r >= n || parents[r].is_some() {
            return Err(err(format!(
                "scene root {r} does not exist or is not a root"
            )));
        }
        stack.push((r, 1));
    }
    while let Some((i, depth)) = stack.pop() {
        if depth > max_depth {
            return Err(Error::Limit {
                what: "skeleton depth",
                actual: depth,
                limit: max_depth,
            });
        }
        if std::mem::replace(&mut seen[i], true) {
            return Err(err(format!("node {i} is reached twice (a cycle)")));
        }
        order.push(i);
        for &c in doc.nodes[i].children.iter().rev() {
            stack.push((c, depth + 1));
        }
    }
    Ok(Tree { parents, order })
}

/// The animations of a glTF file, by name (or `animation N`), in the file's order.
fn animation_names(doc: &Doc) -> Vec<String> {
    doc.animations
        .iter()
        .enumerate()
        .map(|(i, a)| match a.name.as_deref().map(str::trim) {
            Some(n) if !n.is_empty() => n.to_string(),
            _ => format!("animation {i}"),
        })
        .collect()
}

/// The keyframe rate: the shortest of the samplers' median key spacings, snapped to a
/// whole rate where the keys are one printed with rounding.
fn keyframe_rate(tracks: &[Track]) -> Option<f64> {
    let dt = tracks
        .iter()
        .filter(|t| t.times.len() >= 2)
        .filter_map(|t| {
            let mut d: Vec<f64> = t.times.windows(2).map(|w| w[1] - w[0]).collect();
            d.sort_by(f64::total_cmp);
            let m = d[d.len() / 2];
            (m > 0.0).then_some(m)
        })
        .min_by(f64::total_cmp)?;
    let fps = 1.0 / dt;
    let whole = fps.round();
    Some(if (fps - whole).abs() <= 1e-3 * fps {
        whole
    } else {
        (fps * 1e4).round() / 1e4
    })
}

/// The joints of a file: the largest skin's, else the nodes `moved` (an animation's); in
/// the scene, parents first, headed by the lowest node above them all, with the plain end
/// nodes below them. Each joint's node, and its parent among the joints.
fn choose(
    doc: &Doc,
    tree: &Tree,
    moved: &[usize],
    warnings: &mut Vec<String>,
) -> Result<(Vec<usize>, Vec<Option<usize>>)> {
    let nodes = &doc.nodes;
    let Tree { parents, order } = tree;
    let count = nodes.len();
    let in_scene = {
        let mut s = vec![false; count];
        for &i in order {
            s[i] = true;
        }
        s
    };
    let mut marked = vec![false; count];
    match doc.skins.iter().max_by_key(|s| s.joints.len()) {
        Some(skin) => {
            for &j in &skin.joints {
                *marked
                    .get_mut(j)
                    .ok_or_else(|| err(format!("a skin names node {j}, which does not exist")))? =
                    true;
            }
            if doc.skins.len() > 1 {
                warnings.push(format!(
                    "{} skins; the largest ({} joints) is the take's skeleton",
                    doc.skins.len(),
                    skin.joints.len()
                ));
            }
        }
        None => moved.iter().for_each(|&i| marked[i] = true),
    }
    // Marked nodes and meshes or cameras in each subtree, children before parents.
    let mut below = vec![0usize; count];
    let mut shown = vec![false; count];
    for &i in order.iter().rev() {
        below[i] += usize::from(marked[i] && in_scene[i]);
        shown[i] |= nodes[i].mesh.is_some() || nodes[i].camera.is_some();
        if let Some(p) = parents[i] {
            below[p] += below[i];
            shown[p] |= shown[i];
        }
    }
    let tops: Vec<usize> = order
        .iter()
        .copied()
        .filter(|&i| parents[i].is_none() && below[i] > 0)
        .collect();
    let mut head = *tops
        .iter()
        .max_by_key(|&&t| below[t])
        .ok_or_else(|| err("no node of the scene is a joint or moves"))?;
    for &other in tops.iter().filter(|&&t| t != head) {
        warnings.push(format!(
            "the nodes under {:?} left out: a take holds one skeleton, the largest",
            nodes[other].name.clone().unwrap_or_default()
        ));
    }
    // Down to the lowest node above every joint: a grouping node is not one.
    while !marked[head] {
        let mut branches = nodes[head].children.iter().filter(|&&c| below[c] > 0);
        match (branches.next(), branches.next()) {
            (Some(&only), None) => head = only,
            _ => break,
        }
    }
    let joint = |c: usize| below[c] > 0 || !shown[c];
    let mut chosen = Vec::new();
    let mut stack = vec![head];
    while let Some(i) = stack.pop() {
        chosen.push(i);
        stack.extend(
            nodes[i]
                .children
                .iter()
                .rev()
                .copied()
                .filter(|&c| joint(c)),
        );
    }
    let index_of: HashMap<usize, usize> = chosen.iter().enumerate().map(|(k, &i)| (i, k)).collect();
    let joint_parents: Vec<Option<usize>> = chosen
        .iter()
        .map(|&i| parents[i].and_then(|p| index_of.get(&p).copied()))
        .collect();

    Ok((chosen, joint_parents))
}

pub(crate) fn read(bytes: &[u8], options: &ReadOptions) -> Result<Parsed> {
    let limits = &options.limits;
    let (json, bin) = split(bytes)?;
    let doc: Doc = serde_json::from_slice(json).map_err(|e| err(format!("its JSON: {e}")))?;
    if !doc.asset.version.starts_with("2.") {
        return Err(err(format!(
            "glTF version {}; only 2.x is read",
            doc.asset.version
        )));
    }
    if let Some(x) = doc
        .extensions_required
        .iter()
        .find(|x| x.contains("meshopt_compression"))
    {
        return Err(err(format!(
            "its buffers are compressed ({x}), which is not read"
        )));
    }
    let mut data = Data {
        buffers: buffers(&doc, bin)?,
        doc: &doc,
        decoded: HashMap::new(),
        // Key times and values for every sample a take may hold, four numbers each.
        budget: limits.max_samples.saturating_mul(4),
    };
    let nodes = &doc.nodes;
    let count = nodes.len();
    let tree = tree(&doc, limits.max_depth)?;
    let Tree { parents, order } = &tree;

    // The animation asked for, or the first.
    let names = animation_names(&doc);
    if doc.animations.is_empty() {
        return Err(err("the file holds no animation (no animations)"));
    }
    let pick = Pick::place(options.animation.as_ref(), &names)?;
    let animation = &doc.animations[pick];
    let mut warnings = Vec::new();
    let mut tracks = Vec::new();
    let mut skipped = std::collections::BTreeSet::new();
    for (c, ch) in animation.channels.iter().enumerate() {
        let path = match ch.target.path.as_str() {
            "translation" => Path::Translation,
            "rotation" => Path::Rotation,
            "scale" => Path::Scale,
            other => {
                skipped.insert(other.to_string());
                continue;
            }
        };
        let Some(node) = ch.target.node else {
            continue;
        };
        if node >= count {
            return Err(err(format!(
                "channel {c} moves node {node}, which does not exist"
            )));
        }
        let s = animation.samplers.get(ch.sampler).ok_or_else(|| {
            err(format!(
                "channel {c}: sampler {} does not exist",
                ch.sampler
            ))
        })?;
        let what = format!("channel {c}");
        let times = data.get(s.input, 1, &what, true)?;
        let values = data.get(s.output, path.width(), &what, false)?;
        let per_key = if s.interpolation == Interpolation::Cubicspline {
            3
        } else {
            1
        };
        if times.is_empty() || values.len() != times.len() * per_key * path.width() {
            return Err(err(format!(
                "{what}: {} key times and {} values",
                times.len(),
                values.len() / path.width()
            )));
        }
        if times.iter().any(|t| !t.is_finite()) || times.windows(2).any(|w| w[1] < w[0]) {
            return Err(err(format!(
                "{what}: its key times are not increasing numbers"
            )));
        }
        tracks.push(Track {
            node,
            path,
            interpolation: s.interpolation,
            times,
            values,
        });
    }
    if !skipped.is_empty() {
        warnings.push(format!(
            "animation channels of {} are not joint motion: left out",
            skipped.into_iter().collect::<Vec<_>>().join(", ")
        ));
    }
    if tracks.is_empty() {
        return Err(err(format!(
            "animation {:?} moves no node (no translation, rotation or scale channel)",
            names[pick]
        )));
    }

    // The joints: the largest skin's, else the animated nodes; in the scene, parents first.
    let moved: Vec<usize> = tracks.iter().map(|t| t.node).collect();
    let (chosen, joint_parents) = choose(&doc, &tree, &moved, &mut warnings)?;

    // The frames: the animation's keys, from its first to its last.
    let t0 = tracks
        .iter()
        .map(|t| t.times[0])
        .fold(f64::INFINITY, f64::min);
    let t1 = tracks
        .iter()
        .map(|t| t.times[t.times.len() - 1])
        .fold(f64::NEG_INFINITY, f64::max);
    let fps = match options.fps.or_else(|| keyframe_rate(&tracks)) {
        Some(fps) => fps,
        None => {
            warnings.push(format!(
                "the animation has one key: one frame, at {LONE_KEY_FPS} fps (state fps to \
                 override)"
            ));
            LONE_KEY_FPS
        }
    };
    crate::limits::fps(fps).map_err(|e| err(format!("its keyframe rate: {e}")))?;
    let frames_f = ((t1 - t0) * fps).round() + 1.0;
    let frames_checked = if frames_f < 1e15 {
        frames_f as usize
    } else {
        usize::MAX
    };
    limits.check_shape(frames_checked, chosen.len())?;
    // Every frame composes the whole tree and samples every channel: bounded the same way.
    limits.check_work(frames_checked, count.max(tracks.len()))?;
    let frames = frames_checked;

    // Each node's resting transform; animated parts replace their own.
    let rest: Vec<Rest> = nodes
        .iter()
        .map(|n| {
            (
                Vector3::from(n.translation.unwrap_or([0.0; 3])),
                Vector4::from(n.rotation.unwrap_or([0.0, 0.0, 0.0, 1.0])),
                Vector3::from(n.scale.unwrap_or([1.0; 3])),
                n.matrix.map(|m| Matrix4::from_column_slice(&m)),
            )
        })
        .collect();
    let mut animated = vec![false; count];
    tracks.iter().for_each(|t| animated[t.node] = true);
    let mut places = Vec::with_capacity(frames * chosen.len());
    let mut world = vec![Matrix4::identity(); count];
    let mut pose = rest.clone();
    for f in 0..frames {
        let t = t0 + f as f64 / fps;
        for track in &tracks {
            let v = track.sample(t);
            let p = &mut pose[track.node];
            match track.path {
                Path::Translation => p.0 = v.xyz(),
                Path::Rotation => p.1 = v,
                Path::Scale => p.2 = v.xyz(),
            }
        }
        for &i in order {
            let (t, r, s, m) = &pose[i];
            let local = match m {
                Some(m) if !animated[i] => *m,
                _ => trs(*t, rotation(*r), *s),
            };
            world[i] = match parents[i] {
                Some(p) => world[p] * local,
                None => local,
            };
        }
        places.extend(chosen.iter().map(|&i| place(&world[i])));
    }

    let Skeletal {
        names: joint_names,
        positions,
        skeleton,
        warnings: scaled,
    } = Posed {
        names: chosen
            .iter()
            .map(|&i| nodes[i].name.clone().unwrap_or_default())
            .collect(),
        parents: joint_parents,
        frames,
        places,
    }
    .skeleton()?;
    warnings.extend(scaled);
    if doc.animations.len() > 1 {
        warnings.push(format!(
            "animation {:?} of {} ({}); each is a take of its own",
            names[pick],
            names.len(),
            names.join(", ")
        ));
    }
    if !(doc.meshes.is_empty() && doc.materials.is_empty() && doc.textures.is_empty()) {
        warnings.push(format!(
            "{} meshes, {} materials and {} textures are not motion: left out",
            doc.meshes.len(),
            doc.materials.len(),
            doc.textures.len()
        ));
    }
    let mut contradictions = Vec::new();
    let bad = positions.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        contradictions.push(format!("{bad} joint coordinates are not finite"));
    }
    let motion = Motion::new(
        fps,
        super::super::unsettled_unit(),
        joint_names,
        positions,
        Some(skeleton),
    )?;
    Ok(Parsed {
        motion,
        declared_unit: Some(1.0),
        warnings,
        contradictions,
        extras: Extras {
            up: Some(Prior {
                up: Axis::Y,
                says: "glTF is +Y up by its specification".into(),
            }),
            animations: names,
            animation: pick,
            ..Default::default()
        },
    })
}

/// A skinned character at its bind pose, as `POST /v1/skeletons` keeps a glTF character:
/// the skeleton of its largest skin, standing as its nodes rest (animations aside), and
/// where each joint lies in the file's node tree, so that motion on that skeleton can be
/// written back onto the file's own nodes ([`super::character`]).
pub(crate) struct Bind {
    /// The skeleton, with one frame of values: the bind pose (metres, degrees).
    pub skeleton: crate::motion::skeleton::Animation,
    /// The file's node of each joint.
    pub nodes: Vec<usize>,
    /// Each joint's scale in the world (the product of its node's and its ancestors'; even
    /// on all three axes).
    pub scales: Vec<f64>,
    /// The world transform of the node the head joint hangs from (identity for a scene
    /// root): an `Armature` that turns Z-up to Y-up and centimetres to metres.
    pub above: Matrix4<f64>,
    pub warnings: Vec<String>,
}

/// How far a joint's world scale may differ between its axes: a skeleton has no scale, and
/// one even on all axes is carried as a number; an uneven one would bend the mesh.
const EVEN_SCALE: f64 = 1e-4;

/// The bind pose of the skinned character `bytes` (a GLB, or a `.gltf` with its buffers
/// embedded).
pub(crate) fn bind_pose(bytes: &[u8], limits: &super::super::ReadLimits) -> Result<Bind> {
    let (json, _) = split(bytes)?;
    let doc: Doc = serde_json::from_slice(json).map_err(|e| err(format!("its JSON: {e}")))?;
    if !doc.asset.version.starts_with("2.") {
        return Err(err(format!(
            "glTF version {}; only 2.x is read",
            doc.asset.version
        )));
    }
    if doc.skins.is_empty() {
        return Err(err(
            "the file has no skin: a character is a mesh skinned to a skeleton",
        ));
    }
    let tree = tree(&doc, limits.max_depth)?;
    let mut warnings = Vec::new();
    let (chosen, joint_parents) = choose(&doc, &tree, &[], &mut warnings)?;
    limits.check_shape(1, chosen.len())?;
    let mut world = vec![Matrix4::identity(); doc.nodes.len()];
    for &i in &tree.order {
        let n = &doc.nodes[i];
        let local = match n.matrix {
            Some(m) => Matrix4::from_column_slice(&m),
            None => trs(
                Vector3::from(n.translation.unwrap_or([0.0; 3])),
                rotation(Vector4::from(n.rotation.unwrap_or([0.0, 0.0, 0.0, 1.0]))),
                Vector3::from(n.scale.unwrap_or([1.0; 3])),
            ),
        };
        world[i] = match tree.parents[i] {
            Some(p) => world[p] * local,
            None => local,
        };
    }
    let mut scales = Vec::with_capacity(chosen.len());
    for &i in &chosen {
        let m = &world[i];
        let axes: Vec<f64> = (0..3).map(|c| m.fixed_view::<3, 1>(0, c).norm()).collect();
        let mean = (axes[0] + axes[1] + axes[2]) / 3.0;
        if m.fixed_view::<3, 3>(0, 0).determinant() <= 0.0 {
            return Err(err(format!(
                "joint {:?} is mirrored in the world (a negative scale): a skeleton has no \
                 mirror",
                doc.nodes[i].name.clone().unwrap_or_default()
            )));
        }
        if !(mean.is_finite() && mean > 0.0)
            || axes.iter().any(|a| (a - mean).abs() > EVEN_SCALE * mean)
        {
            return Err(err(format!(
                "joint {:?} is scaled unevenly ({:.4}, {:.4}, {:.4}) in the world: a \
                 character's skeleton may only scale evenly",
                doc.nodes[i].name.clone().unwrap_or_default(),
                axes[0],
                axes[1],
                axes[2]
            )));
        }
        scales.push(mean);
    }
    let above = tree.parents[chosen[0]].map_or_else(Matrix4::identity, |p| world[p]);
    let Skeletal {
        skeleton,
        warnings: scaled,
        ..
    } = Posed {
        names: chosen
            .iter()
            .map(|&i| doc.nodes[i].name.clone().unwrap_or_default())
            .collect(),
        parents: joint_parents,
        frames: 1,
        places: chosen.iter().map(|&i| place(&world[i])).collect(),
    }
    .skeleton()?;
    warnings.extend(scaled);
    Ok(Bind {
        skeleton,
        nodes: chosen,
        scales,
        above,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// A `.gltf` whose one buffer holds `floats`, with one accessor per `(offset, count,
    /// type)` (offsets in floats).
    fn document(
        floats: &[f32],
        accessors: &[(usize, usize, &str)],
        rest: serde_json::Value,
    ) -> Vec<u8> {
        let blob: Vec<u8> = floats.iter().flat_map(|v| v.to_le_bytes()).collect();
        let mut doc = rest;
        doc["asset"] = json!({"version": "2.0"});
        doc["buffers"] = json!([{
            "byteLength": blob.len(),
            "uri": format!("data:application/gltf-buffer;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&blob)),
        }]);
        doc["bufferViews"] = json!([{"buffer": 0, "byteLength": blob.len()}]);
        doc["accessors"] = accessors
            .iter()
            .map(|&(at, count, kind)| {
                json!({"bufferView": 0, "byteOffset": at * 4, "componentType": 5126,
                       "count": count, "type": kind})
            })
            .collect();
        serde_json::to_vec(&doc).unwrap()
    }

    fn read_at(bytes: &[u8], fps: f64) -> Parsed {
        let options = ReadOptions {
            fps: Some(fps),
            ..Default::default()
        };
        read(bytes, &options).unwrap()
    }

    /// A root moved by a CUBICSPLINE (zero tangents: 3s² − 2s³), an arm turned by a STEP
    /// rotation, a hand placed by a matrix, and a mesh node that is no joint.
    #[test]
    fn interpolations_and_node_transforms_are_honoured() {
        let half = std::f32::consts::FRAC_1_SQRT_2;
        #[rustfmt::skip]
        let floats = [
            0.0, 1.0,                                   // 0: times
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, // 2: key 0: in, value, out
            0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, // 11: key 1
            0.0, 0.0, 0.0, 1.0, 0.0, half, 0.0, half,   // 20: rotations: identity, 90° about Y
        ];
        let bytes = document(
            &floats,
            &[(0, 2, "SCALAR"), (2, 6, "VEC3"), (20, 2, "VEC4")],
            json!({
                "nodes": [
                    {"name": "hips", "children": [1, 3]},
                    {"name": "arm", "translation": [0.0, 1.0, 0.0], "children": [2]},
                    {"name": "hand", "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 1,0,0,1]},
                    {"name": "body", "mesh": 0},
                ],
                "meshes": [{}],
                "animations": [{
                    "samplers": [
                        {"input": 0, "output": 1, "interpolation": "CUBICSPLINE"},
                        {"input": 0, "output": 2, "interpolation": "STEP"},
                    ],
                    "channels": [
                        {"sampler": 0, "target": {"node": 0, "path": "translation"}},
                        {"sampler": 1, "target": {"node": 1, "path": "rotation"}},
                    ],
                }],
            }),
        );
        let p = read_at(&bytes, 4.0);
        let m = &p.motion;
        assert_eq!(
            m.point_names,
            ["hips", "arm", "hand"],
            "the mesh node is no joint"
        );
        assert_eq!(m.frame_count(), 5);
        let at = |f: usize, k: usize| {
            let s = &m.positions()[(f * 3 + k) * 3..][..3];
            [s[0], s[1], s[2]]
        };
        for f in 0..5 {
            let s = f as f32 / 4.0;
            let x = 3.0 * s * s - 2.0 * s * s * s;
            assert!((at(f, 0)[0] - x).abs() < 1e-6, "frame {f}: {:?}", at(f, 0));
            // The arm holds its first key until the last: the hand lies along +X of it,
            // then along −Z once the arm has turned 90° about Y.
            let hand = if f < 4 {
                [x + 1.0, 1.0, 0.0]
            } else {
                [x, 1.0, -1.0]
            };
            let got = at(f, 2);
            assert!(
                got.iter().zip(hand).all(|(g, w)| (g - w).abs() < 1e-5),
                "frame {f}: {got:?}"
            );
        }
        assert!(
            p.warnings.iter().any(|w| w.contains("not motion")),
            "{:?}",
            p.warnings
        );
        assert_eq!(p.extras.up.as_ref().unwrap().up, Axis::Y);
    }

    /// LINEAR rotations slerp the short way, even between keys on opposite hemispheres.
    #[test]
    fn linear_rotations_take_the_short_way() {
        let s = std::f32::consts::FRAC_1_SQRT_2;
        // 0° and 90° about Z, the second written as its negation.
        let floats = [0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -s, -s];
        let bytes = document(
            &floats,
            &[(0, 2, "SCALAR"), (2, 2, "VEC4")],
            json!({
                "nodes": [{"name": "root", "children": [1]}, {"name": "tip", "translation": [1.0, 0.0, 0.0]}],
                "animations": [{
                    "samplers": [{"input": 0, "output": 1}],
                    "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}],
                }],
            }),
        );
        let p = read_at(&bytes, 2.0);
        let tip = &p.motion.positions()[(2 + 1) * 3..][..3]; // frame 1 (0.5 s), joint 1
        let h = (0.5f32).sqrt();
        assert!(
            (tip[0] - h).abs() < 1e-5 && (tip[1] - h).abs() < 1e-5,
            "45°: {tip:?}"
        );
    }

    #[test]
    fn the_keyframe_rate_is_read_from_the_keys() {
        let track = |times: Vec<f64>| Track {
            node: 0,
            path: Path::Translation,
            interpolation: Interpolation::Linear,
            values: Rc::new(vec![0.0; times.len() * 3]),
            times: Rc::new(times),
        };
        let thirty: Vec<f64> = (1..40).map(|k| k as f64 * 0.033_333_3).collect();
        assert_eq!(keyframe_rate(&[track(thirty)]), Some(30.0));
        let odd: Vec<f64> = (0..10).map(|k| k as f64 / 29.97).collect();
        assert_eq!(keyframe_rate(&[track(odd)]), Some(29.97));
        assert_eq!(keyframe_rate(&[track(vec![0.5])]), None);
    }
}
