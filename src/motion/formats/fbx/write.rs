//! FBX out: binary FBX 7.4, what Blender, Maya, MotionBuilder, Unity and Unreal import.
//!
//! - **A skeleton take** is one `LimbNode` model per joint and End Site (names kept, parents
//!   as in the file), resting at its offset with no rotation, and one animation stack
//!   (`Take 001`) whose curves key every frame: `Lcl Rotation` for every joint that rotates,
//!   `Lcl Translation` for every joint with position channels. A joint with three rotation
//!   channels keeps its own order (`RotationOrder`; BVH's `Zrotation Xrotation Yrotation`,
//!   `R = Rz·Rx·Ry`, is FBX's `eEulerYXZ`), so its curves are the channel values themselves,
//!   on the same Euler branches; any other set of rotation channels is composed and written
//!   in FBX's default order, continuous from frame to frame.
//! - **A marker take** is one `Null` model per marker with translation curves; a missing
//!   sample holds the marker at its last position (the first it has, before it appears).
//!
//! Keys are linear (`KeyAttrFlags` 0x4) at the take's rate, so a player evaluates the frames
//! as decoded. `GlobalSettings` state the unit (`UnitScaleFactor`, centimetres per unit) and
//! the axes the read path turned the take to (+Y or +Z up, right-handed), the frame rate
//! (`TimeMode`, `CustomFrameRate`) and the time span.
//!
//! The binary layout is the one [`records`](super::records) reads: 32-bit record headers
//! (end offset, property count, property bytes, name), typed properties, nested lists closed
//! by a 13-byte null record, the top level closed by one, then the footer.

use nalgebra::UnitQuaternion;

use super::super::gltf::{Figure, Scene};
use crate::motion::body::Axis;
use crate::motion::error::{Error, Result};
use crate::motion::rotation::{euler_order, from_euler, to_euler};
use crate::motion::skeleton::{translation, Joint};

/// FBX's time unit: ticks a second.
const KTIME_PER_SECOND: f64 = 46_186_158_000.0;
const VERSION: u32 = 7400;

/// A typed property.
enum Prop {
    I32(i32),
    I64(i64),
    F64(f64),
    Bool(bool),
    Str(Vec<u8>),
    Raw(Vec<u8>),
    F32s(Vec<f32>),
    I32s(Vec<i32>),
    I64s(Vec<i64>),
}

fn s(v: &str) -> Prop {
    Prop::Str(v.as_bytes().to_vec())
}

/// An object's name as FBX stores it: `name`, `\0\x01`, its class.
fn named(name: &str, class: &str) -> Prop {
    let mut b = name.replace('\0', "").into_bytes();
    b.extend_from_slice(b"\x00\x01");
    b.extend_from_slice(class.as_bytes());
    Prop::Str(b)
}

/// One record: a name, properties, nested records (`scope`: it has a nested list, empty or
/// not; readers such as assimp require one of an object like an animation layer even when
/// it holds nothing).
struct Node {
    name: &'static str,
    props: Vec<Prop>,
    children: Vec<Node>,
    scope: bool,
}

fn node(name: &'static str, props: Vec<Prop>) -> Node {
    Node {
        name,
        props,
        children: Vec::new(),
        scope: false,
    }
}

impl Node {
    fn with(mut self, children: Vec<Node>) -> Node {
        self.children = children;
        self.scope = true;
        self
    }
}

/// A `P` entry of `Properties70`.
fn p(name: &str, kind: &str, label: &str, flags: &str, values: Vec<Prop>) -> Node {
    let mut props = vec![s(name), s(kind), s(label), s(flags)];
    props.extend(values);
    node("P", props)
}

fn p_int(name: &str, v: i32) -> Node {
    p(name, "int", "Integer", "", vec![Prop::I32(v)])
}

fn p_enum(name: &str, v: i32) -> Node {
    p(name, "enum", "", "", vec![Prop::I32(v)])
}

fn p_double(name: &str, v: f64) -> Node {
    p(name, "double", "Number", "", vec![Prop::F64(v)])
}

fn p_time(name: &str, v: i64) -> Node {
    p(name, "KTime", "Time", "", vec![Prop::I64(v)])
}

fn p_vec(name: &str, v: [f64; 3]) -> Node {
    p(
        name,
        name,
        "",
        "A",
        v.iter().map(|&x| Prop::F64(x)).collect(),
    )
}

fn properties(children: Vec<Node>) -> Node {
    node("Properties70", Vec::new()).with(children)
}

fn put_array<T: Copy>(out: &mut Vec<u8>, kind: u8, v: &[T], bytes: impl Fn(T) -> Vec<u8>) {
    out.push(kind);
    out.extend_from_slice(&(v.len() as u32).to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes()); // not compressed
    let data: Vec<u8> = v.iter().flat_map(|&x| bytes(x)).collect();
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(&data);
}

fn put_prop(out: &mut Vec<u8>, prop: &Prop) {
    match prop {
        Prop::I32(v) => {
            out.push(b'I');
            out.extend_from_slice(&v.to_le_bytes());
        }
        Prop::I64(v) => {
            out.push(b'L');
            out.extend_from_slice(&v.to_le_bytes());
        }
        Prop::F64(v) => {
            out.push(b'D');
            out.extend_from_slice(&v.to_le_bytes());
        }
        Prop::Bool(v) => {
            out.push(b'C');
            out.push(u8::from(*v));
        }
        Prop::Str(b) | Prop::Raw(b) => {
            out.push(if matches!(prop, Prop::Str(_)) {
                b'S'
            } else {
                b'R'
            });
            out.extend_from_slice(&(b.len() as u32).to_le_bytes());
            out.extend_from_slice(b);
        }
        Prop::F32s(v) => put_array(out, b'f', v, |x| x.to_le_bytes().to_vec()),
        Prop::I32s(v) => put_array(out, b'i', v, |x| x.to_le_bytes().to_vec()),
        Prop::I64s(v) => put_array(out, b'l', v, |x| x.to_le_bytes().to_vec()),
    }
}

/// The null record that closes a nested list (and the top level): 13 zero bytes in 7.4.
const NULL_RECORD: [u8; 13] = [0; 13];

fn put_node(out: &mut Vec<u8>, n: &Node) {
    let start = out.len();
    out.extend_from_slice(&[0; 12]);
    out.push(n.name.len() as u8);
    out.extend_from_slice(n.name.as_bytes());
    let props_at = out.len();
    for prop in &n.props {
        put_prop(out, prop);
    }
    let props_len = (out.len() - props_at) as u32;
    // A nested list ends with a null record; so does a record of no properties (as the
    // FBX SDK writes them), which readers take for an empty list.
    if n.scope || n.props.is_empty() {
        for c in &n.children {
            put_node(out, c);
        }
        out.extend_from_slice(&NULL_RECORD);
    }
    let end = out.len() as u32;
    out[start..start + 4].copy_from_slice(&end.to_le_bytes());
    out[start + 4..start + 8].copy_from_slice(&(n.props.len() as u32).to_le_bytes());
    out[start + 8..start + 12].copy_from_slice(&props_len.to_le_bytes());
}

/// The axes a file states: `up` (+Y or +Z), right-handed, with FBX's usual front for each
/// (Maya's Y-up: front +Z; Max's and Blender's Z-up: front −Y).
fn axes(up: Axis) -> [(&'static str, i32); 6] {
    let (up, front, front_sign) = match up {
        Axis::Z => (2, 1, -1),
        _ => (1, 2, 1),
    };
    [
        ("UpAxis", up),
        ("UpAxisSign", 1),
        ("FrontAxis", front),
        ("FrontAxisSign", front_sign),
        ("CoordAxis", 0),
        ("CoordAxisSign", 1),
    ]
}

/// FBX's `TimeMode` for a rate it names, else 14 (custom, with `CustomFrameRate`).
fn time_mode(fps: f64) -> i32 {
    const NAMED: [(f64, i32); 11] = [
        (120.0, 1),
        (100.0, 2),
        (60.0, 3),
        (50.0, 4),
        (48.0, 5),
        (30.0, 6),
        (25.0, 10),
        (24.0, 11),
        (1000.0, 12),
        (96.0, 15),
        (72.0, 16),
    ];
    NAMED
        .iter()
        .find(|(r, _)| (fps - r).abs() < 1e-9)
        .map_or(14, |&(_, m)| m)
}

/// FBX's `RotationOrder` for a joint whose rotation is `R = R_a · R_b · R_c` about the axes
/// `order` = `[a, b, c]`: FBX names the axis applied first first (`eEulerXYZ` is
/// `Rz · Ry · Rx`), so it is the order reversed.
fn rotation_order(order: [usize; 3]) -> i32 {
    match [order[2], order[1], order[0]] {
        [0, 1, 2] => 0,
        [0, 2, 1] => 1,
        [1, 2, 0] => 2,
        [1, 0, 2] => 3,
        [2, 0, 1] => 4,
        _ => 5,
    }
}

/// Ids of objects: unique, positive, never 0 (the scene's root).
struct Ids(i64);

impl Ids {
    fn next(&mut self) -> i64 {
        self.0 += 1;
        self.0
    }
}

/// What the file is made of, as it is built.
struct Build {
    ids: Ids,
    objects: Vec<Node>,
    connections: Vec<Node>,
    times: Vec<i64>,
    layer: i64,
    counts: [usize; 5],
}

/// Counts per object type, in `Definitions` order.
const TYPES: [&str; 5] = [
    "Model",
    "NodeAttribute",
    "AnimationCurveNode",
    "AnimationCurve",
    "AnimationStack",
];

impl Build {
    fn connect(&mut self, child: i64, parent: i64) {
        self.connections.push(node(
            "C",
            vec![s("OO"), Prop::I64(child), Prop::I64(parent)],
        ));
    }

    fn connect_property(&mut self, child: i64, parent: i64, property: &str) {
        self.connections.push(node(
            "C",
            vec![s("OP"), Prop::I64(child), Prop::I64(parent), s(property)],
        ));
    }

    /// A model of `kind` (`LimbNode`, `Null`) under `parent`, resting at `t`, with its node
    /// attribute.
    fn model(&mut self, name: &str, kind: &str, parent: i64, t: [f64; 3], order: i32) -> i64 {
        let id = self.ids.next();
        self.objects.push(
            node("Model", vec![Prop::I64(id), named(name, "Model"), s(kind)]).with(vec![
                node("Version", vec![Prop::I32(232)]),
                properties(vec![
                    p_enum("RotationOrder", order),
                    p("RotationActive", "bool", "", "", vec![Prop::I32(1)]),
                    p_enum("InheritType", 1),
                    p_int("DefaultAttributeIndex", 0),
                    p_vec("Lcl Translation", t),
                    p_vec("Lcl Rotation", [0.0; 3]),
                    p_vec("Lcl Scaling", [1.0; 3]),
                ]),
                node("Shading", vec![Prop::Bool(true)]),
                node("Culling", vec![s("CullingOff")]),
            ]),
        );
        let attr = self.ids.next();
        let flags = if kind == "LimbNode" {
            "Skeleton"
        } else {
            "Null"
        };
        self.objects.push(
            node(
                "NodeAttribute",
                vec![Prop::I64(attr), named(name, "NodeAttribute"), s(kind)],
            )
            .with(vec![
                properties(vec![p_double("Size", 10.0)]),
                node("TypeFlags", vec![s(flags)]),
            ]),
        );
        self.connect(attr, id);
        self.connect(id, parent);
        self.counts[0] += 1;
        self.counts[1] += 1;
        id
    }

    /// Curves of `model`'s `property` (`Lcl Translation`, `Lcl Rotation`): one per axis of
    /// `values` (`frames × 3`).
    fn curves(&mut self, model: i64, property: &str, short: &str, values: &[[f64; 3]]) {
        let node_id = self.ids.next();
        let first = values.first().copied().unwrap_or([0.0; 3]);
        self.objects.push(
            node(
                "AnimationCurveNode",
                vec![Prop::I64(node_id), named(short, "AnimCurveNode"), s("")],
            )
            .with(vec![properties(
                ["d|X", "d|Y", "d|Z"]
                    .iter()
                    .zip(first)
                    .map(|(n, v)| p(n, "Number", "", "A", vec![Prop::F64(v)]))
                    .collect(),
            )]),
        );
        self.connect(node_id, self.layer);
        self.connect_property(node_id, model, property);
        self.counts[2] += 1;
        for (axis, channel) in ["d|X", "d|Y", "d|Z"].iter().enumerate() {
            let id = self.ids.next();
            let keys: Vec<f32> = values.iter().map(|v| v[axis] as f32).collect();
            self.objects.push(
                node(
                    "AnimationCurve",
                    vec![Prop::I64(id), named("", "AnimCurve"), s("")],
                )
                .with(vec![
                    node("Default", vec![Prop::F64(first[axis])]),
                    node("KeyVer", vec![Prop::I32(4008)]),
                    node("KeyTime", vec![Prop::I64s(self.times.clone())]),
                    node("KeyValueFloat", vec![Prop::F32s(keys)]),
                    // Linear keys, one run covering them all.
                    node("KeyAttrFlags", vec![Prop::I32s(vec![0x4])]),
                    node("KeyAttrDataFloat", vec![Prop::F32s(vec![0.0; 4])]),
                    node(
                        "KeyAttrRefCount",
                        vec![Prop::I32s(vec![values.len() as i32])],
                    ),
                ]),
            );
            self.connect_property(id, node_id, channel);
            self.counts[3] += 1;
        }
    }
}

/// Each joint's rotation a frame as FBX Euler angles (x, y, z degrees) in its
/// `RotationOrder`, continuous: FBX curves are interpolated angle by angle, so a key that
/// wraps (179° to −179°) or flips to the other triple would turn the joint the long way
/// between frames (an importer that resamples, a player at another rate). A joint of three
/// rotation channels keeps its channels' values wherever they are the triple nearest the
/// frame before (and at the first frame), else the equivalent one that is; any other is its
/// channels composed, in FBX's default order.
fn joint_rotations(
    joint: &Joint,
    first: usize,
    values: &[f64],
    frames: usize,
) -> (i32, Vec<[f64; 3]>) {
    let cc = values.len() / frames.max(1);
    let own = |f: usize| &values[f * cc + first..f * cc + first + joint.channels.len()];
    if let Some(order) = euler_order(&joint.channels) {
        let rot: Vec<usize> = (0..joint.channels.len())
            .filter(|&c| joint.channels[c].rotation_axis().is_some())
            .collect();
        let mut prev: Option<[f64; 3]> = None;
        let out = (0..frames)
            .map(|f| {
                // In channel order, as `to_euler` gives them.
                let mut e = [0.0; 3];
                for (k, &c) in rot.iter().enumerate() {
                    e[k] = own(f)[c];
                }
                if let Some(p) = prev {
                    let near = to_euler(&from_euler(order, e), order, Some(p));
                    let far =
                        |x: &[f64; 3]| x.iter().zip(p).map(|(a, b)| (a - b).abs()).sum::<f64>();
                    if far(&near) + 1e-6 < far(&e) {
                        e = near;
                    }
                }
                prev = Some(e);
                let mut by_axis = [0.0; 3];
                for k in 0..3 {
                    by_axis[order[k]] = e[k];
                }
                by_axis
            })
            .collect();
        return (rotation_order(order), out);
    }
    // FBX's eEulerXYZ: R = Rz · Ry · Rx, our order [z, y, x].
    const XYZ: [usize; 3] = [2, 1, 0];
    let mut near = None;
    let out = (0..frames)
        .map(|f| {
            let mut q = UnitQuaternion::identity();
            for (c, v) in joint.channels.iter().zip(own(f)) {
                if let Some(a) = c.rotation_axis() {
                    q *= UnitQuaternion::from_axis_angle(
                        &nalgebra::Vector3::ith_axis(a),
                        v.to_radians(),
                    );
                }
            }
            let e = to_euler(&q, XYZ, near);
            near = Some(e);
            [e[2], e[1], e[0]]
        })
        .collect();
    (0, out)
}

/// The binary FBX 7.4 of `scene`, whose values are in units of `metres_per_unit` metres
/// with `up` up (+Y or +Z).
pub fn fbx(scene: &Scene<'_>, metres_per_unit: f64, up: Axis) -> Result<Vec<u8>> {
    let frames = scene.frames;
    let nodes = match &scene.figure {
        Figure::Skeleton { joints, .. } => joints.len(),
        Figure::Markers { names, .. } => names.len(),
    };
    // FBX 7.4's records say where they end in 32 bits.
    if len_bound(frames, nodes) > u64::from(u32::MAX) {
        return Err(Error::Invalid(format!(
            "FBX out: {frames} frames of {nodes} nodes pass FBX 7.4's 4 GiB; ask for a shorter \
             range or a lower fps"
        )));
    }
    let fps = scene.fps;
    let times: Vec<i64> = (0..frames)
        .map(|f| (f as f64 * KTIME_PER_SECOND / fps).round() as i64)
        .collect();
    let stop = times.last().copied().unwrap_or(0);
    let mut b = Build {
        ids: Ids(1_000_000),
        objects: Vec::new(),
        connections: Vec::new(),
        times,
        layer: 0,
        counts: [0; 5],
    };
    let stack = b.ids.next();
    b.objects.push(
        node(
            "AnimationStack",
            vec![Prop::I64(stack), named("Take 001", "AnimStack"), s("")],
        )
        .with(vec![properties(vec![
            p_time("LocalStart", 0),
            p_time("LocalStop", stop),
            p_time("ReferenceStart", 0),
            p_time("ReferenceStop", stop),
        ])]),
    );
    b.counts[4] += 1;
    b.layer = b.ids.next();
    b.objects.push(
        node(
            "AnimationLayer",
            vec![Prop::I64(b.layer), named("BaseLayer", "AnimLayer"), s("")],
        )
        .with(Vec::new()),
    );
    b.connect(b.layer, stack);
    match &scene.figure {
        Figure::Skeleton { joints, values } => {
            let mut ids: Vec<i64> = Vec::with_capacity(joints.len());
            let mut first = 0;
            let cc = values.len() / frames.max(1);
            for j in joints.iter() {
                let parent = j.parent.map_or(0, |p| ids[p]);
                let (order, rotations) = joint_rotations(j, first, values, frames);
                let moves = j.channels.iter().any(|c| !c.axis().1);
                let rest = if frames > 0 && moves {
                    translation(j, &values[first..first + j.channels.len()])
                } else {
                    j.offset
                };
                let id = b.model(&j.name, "LimbNode", parent, rest, order);
                if frames > 0 && j.channels.iter().any(|c| c.rotation_axis().is_some()) {
                    b.curves(id, "Lcl Rotation", "R", &rotations);
                }
                if frames > 0 && moves {
                    let t: Vec<[f64; 3]> = (0..frames)
                        .map(|f| {
                            let at = f * cc + first;
                            translation(j, &values[at..at + j.channels.len()])
                        })
                        .collect();
                    b.curves(id, "Lcl Translation", "T", &t);
                }
                ids.push(id);
                first += j.channels.len();
            }
        }
        Figure::Markers { names, positions } => {
            let n = names.len();
            for (k, name) in names.iter().enumerate() {
                let sample = |f: usize| {
                    let at = (f * n + k) * 3;
                    [positions[at], positions[at + 1], positions[at + 2]]
                };
                let present = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
                let seen = (0..frames).map(sample).find(present).unwrap_or([0.0; 3]);
                let mut last = seen;
                let track: Vec<[f64; 3]> = (0..frames)
                    .map(|f| {
                        let v = sample(f);
                        if present(&v) {
                            last = v;
                        }
                        last
                    })
                    .collect();
                let id = b.model(name, "Null", 0, seen, 0);
                if frames > 0 {
                    b.curves(id, "Lcl Translation", "T", &track);
                }
            }
        }
    }

    let mut settings: Vec<Node> = axes(up).iter().map(|&(name, v)| p_int(name, v)).collect();
    settings.extend([
        p_int("OriginalUpAxis", if up == Axis::Z { 2 } else { 1 }),
        p_int("OriginalUpAxisSign", 1),
        p_double("UnitScaleFactor", metres_per_unit * 100.0),
        p_double("OriginalUnitScaleFactor", metres_per_unit * 100.0),
        p_enum("TimeMode", time_mode(fps)),
        p_double("CustomFrameRate", fps),
        p_time("TimeSpanStart", 0),
        p_time("TimeSpanStop", stop),
    ]);
    let mut definitions = vec![
        node("Version", vec![Prop::I32(100)]),
        node(
            "Count",
            vec![Prop::I32(b.counts.iter().sum::<usize>() as i32 + 2)],
        ),
        node("ObjectType", vec![s("GlobalSettings")]).with(vec![node("Count", vec![Prop::I32(1)])]),
        node("ObjectType", vec![s("AnimationLayer")]).with(vec![node("Count", vec![Prop::I32(1)])]),
    ];
    for (t, c) in TYPES.iter().zip(b.counts) {
        if c > 0 {
            definitions.push(
                node("ObjectType", vec![s(t)]).with(vec![node("Count", vec![Prop::I32(c as i32)])]),
            );
        }
    }
    let top = vec![
        node("FBXHeaderExtension", Vec::new()).with(vec![
            node("FBXHeaderVersion", vec![Prop::I32(1003)]),
            node("FBXVersion", vec![Prop::I32(VERSION as i32)]),
            node(
                "Creator",
                vec![s(concat!("mocapstore ", env!("CARGO_PKG_VERSION")))],
            ),
        ]),
        node("FileId", vec![Prop::Raw(FILE_ID.to_vec())]),
        // The FBX SDK checks the file id against the creation time: this pair is the one
        // Blender's writer uses.
        node("CreationTime", vec![s("1970-01-01 10:00:00:000")]),
        node(
            "Creator",
            vec![s(concat!("mocapstore ", env!("CARGO_PKG_VERSION")))],
        ),
        node("GlobalSettings", Vec::new()).with(vec![
            node("Version", vec![Prop::I32(1000)]),
            properties(settings),
        ]),
        node("Documents", Vec::new()).with(vec![
            node("Count", vec![Prop::I32(1)]),
            node(
                "Document",
                vec![Prop::I64(1), named(scene.name, "Scene"), s("Scene")],
            )
            .with(vec![
                properties(vec![p(
                    "ActiveAnimStackName",
                    "KString",
                    "",
                    "",
                    vec![s("Take 001")],
                )]),
                node("RootNode", vec![Prop::I64(0)]),
            ]),
        ]),
        node("References", Vec::new()),
        node("Definitions", Vec::new()).with(definitions),
        node("Objects", Vec::new()).with(std::mem::take(&mut b.objects)),
        node("Connections", Vec::new()).with(std::mem::take(&mut b.connections)),
        node("Takes", Vec::new()).with(vec![node("Current", vec![s("Take 001")])]),
    ];

    let mut out = Vec::with_capacity(len_bound(frames, b.counts[0]) as usize);
    out.extend_from_slice(b"Kaydara FBX Binary  \x00\x1a\x00");
    out.extend_from_slice(&VERSION.to_le_bytes());
    for n in &top {
        put_node(&mut out, n);
    }
    out.extend_from_slice(&NULL_RECORD);
    // The footer as the FBX SDK writes it: an id, padding to 16 bytes, the version, zeros
    // and a closing magic.
    out.extend_from_slice(&FOOTER_ID);
    out.extend_from_slice(&[0; 4]);
    let pad = match out.len() % 16 {
        0 => 16,
        r => 16 - r,
    };
    out.extend(std::iter::repeat_n(0u8, pad));
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&[0; 120]);
    out.extend_from_slice(&FOOTER_MAGIC);
    Ok(out)
}

/// A whole take as FBX, named `name`, whose values were turned to `up` (+Y or +Z), in its
/// own unit.
pub fn of_motion(m: &crate::motion::Motion, name: &str, up: Axis) -> Result<Vec<u8>> {
    let unit = m.unit.metres_per_unit;
    super::super::gltf::with_scene(m, name, serde_json::Value::Null, |scene| {
        fbx(scene, unit, up)
    })
}

/// Bytes of an FBX of `frames` frames of `nodes` models, at most: for sizes checked before
/// anything is built (each model two curve nodes of three curves a frame: a time and a
/// value, and a few hundred bytes of records).
pub fn len_bound(frames: usize, nodes: usize) -> u64 {
    nodes as u64 * (6 * frames as u64 * 12 + 4096) + 16_384
}

const FILE_ID: [u8; 16] = [
    0x28, 0xb3, 0x2a, 0xeb, 0xb6, 0x24, 0xcc, 0xc2, 0xbf, 0xc8, 0xb0, 0x2a, 0xa9, 0x2b, 0xfc, 0xf1,
];
const FOOTER_ID: [u8; 16] = [
    0xfa, 0xbc, 0xab, 0x09, 0xd0, 0xc8, 0xd4, 0x66, 0xb1, 0x76, 0xfb, 0x83, 0x1c, 0xf7, 0x26, 0x7e,
];
const FOOTER_MAGIC: [u8; 16] = [
    0xf8, 0x5a, 0x8c, 0x6a, 0xde, 0xf5, 0xd9, 0x7e, 0xec, 0xe9, 0x0c, 0xe3, 0x75, 0x8f, 0x29, 0x0b,
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::formats::{read_as, Format, ReadOptions};
    use crate::motion::synthetic::dancer;

    /// A dancer through FBX and back through the FBX reader (ufbx): the same joints at the
    /// same places, frame by frame, at the same rate.
    #[test]
    fn a_skeleton_take_reads_back_through_ufbx() {
        let m = dancer(90, 30.0, 4);
        let sk = m.skeleton.as_ref().unwrap();
        let scene = Scene {
            name: "dancer",
            figure: Figure::Skeleton {
                joints: &sk.joints,
                values: &sk.values,
            },
            frames: m.frame_count(),
            fps: m.fps,
            extras: serde_json::Value::Null,
        };
        let bytes = fbx(&scene, 0.01, Axis::Y).unwrap();
        let back = read_as(Format::Fbx, &bytes, &ReadOptions::default()).unwrap();
        assert_eq!(back.motion.frame_count(), m.frame_count());
        assert!(
            (back.motion.fps - m.fps).abs() < 1e-6 * m.fps,
            "{} {}",
            back.motion.fps,
            m.fps
        );
        // Every joint and End Site of ours is a point of theirs at the same place (cm).
        let (a, b) = (&m, &back.motion);
        let mut worst = 0f64;
        for (k, name) in a.point_names.iter().enumerate() {
            let j = b
                .point_names
                .iter()
                .position(|n| n == name)
                .unwrap_or_else(|| panic!("{name} not read back: {:?}", b.point_names));
            for f in 0..a.frame_count() {
                for c in 0..3 {
                    let x = f64::from(a.positions()[(f * a.point_count() + k) * 3 + c]);
                    let y = f64::from(b.positions()[(f * b.point_count() + j) * 3 + c]);
                    worst = worst.max((x - y).abs());
                }
            }
        }
        assert!(worst < 1e-3, "{worst}");
    }

    /// A channel that wraps (170°, 179°, −172° …) is written as the continuous curve (…,
    /// 188°), the same rotation, so an importer interpolating between keys turns the short
    /// way; a flipped triple likewise.
    #[test]
    fn curves_are_continuous_where_the_channels_wrap() {
        use crate::motion::skeleton::Channel;
        let joint = Joint {
            name: "j".into(),
            parent: None,
            offset: [0.0; 3],
            channels: vec![Channel::Zrotation, Channel::Xrotation, Channel::Yrotation],
            end_site: false,
        };
        let values = [
            170.0,
            10.0,
            5.0, //
            179.0,
            10.0,
            5.0, //
            -172.0,
            10.0,
            5.0, //
            -172.0 + 180.0,
            170.0,
            5.0 + 180.0, // the same rotation's other triple
        ];
        let (order, e) = joint_rotations(&joint, 0, &values, 4);
        assert_eq!(order, 3);
        let z: Vec<f64> = e.iter().map(|v| v[2]).collect();
        assert_eq!(&z[..2], &[170.0, 179.0]);
        assert!(
            (z[2] - 188.0).abs() < 1e-9 && (z[3] - 188.0).abs() < 1e-6,
            "{z:?}"
        );
        assert!(
            (e[3][0] - 10.0).abs() < 1e-6 && (e[3][1] - 5.0).abs() < 1e-6,
            "{e:?}"
        );
    }

    #[test]
    fn rotation_orders_name_the_first_applied_axis_first() {
        // BVH's ZXY (R = Rz·Rx·Ry) is FBX's eEulerYXZ.
        assert_eq!(rotation_order([2, 0, 1]), 3);
        assert_eq!(rotation_order([2, 1, 0]), 0);
        assert_eq!(rotation_order([0, 1, 2]), 5);
    }
}
