//! FBX in (binary and ASCII, FBX 6 and 7): a skeleton take from a file's joint hierarchy
//! and its animation, read with the ufbx library, which resolves what makes FBX hard to
//! evaluate (pre- and post-rotations, pivots, rotation orders, scale inheritance) as the
//! authoring tools do.
//!
//! The take is what the file's author saw: every frame of the animation stack is
//! evaluated at the file's frame rate, and each joint's world transform is written as a
//! BVH-style skeleton (the root's world position and rotation, every other joint's
//! rotation relative to its parent's, and its translation where it moves), so forward
//! kinematics gives back the file's joint positions. Meshes, skins, materials and textures
//! are not motion: they are not loaded, and the take says what was left out.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use super::{Extras, Format, Parsed, ReadLimits};
use crate::motion::body::{Axis, Prior};
use crate::motion::error::{Error, Location, Result};
use crate::motion::model::Motion;
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

fn err(reason: impl Into<String>) -> Error {
    Error::parse(Format::Fbx, Location::Whole, reason)
}

/// The memory ufbx may allocate for a file of `bytes` (and for each evaluated frame): room
/// for its node tree and curves, never more than [`crate::limits::MAX_FBX_MEMORY`].
fn allocator(bytes: usize) -> ufbx::AllocatorOpts {
    ufbx::AllocatorOpts {
        memory_limit: (64usize << 20)
            .saturating_add(bytes.saturating_mul(32))
            .min(crate::limits::MAX_FBX_MEMORY),
        ..Default::default()
    }
}

/// A node's world transform: its position, and its rotation with any scale taken out.
fn world(m: &ufbx::Matrix) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let r = Matrix3::new(
        m.m00, m.m01, m.m02, m.m10, m.m11, m.m12, m.m20, m.m21, m.m22,
    );
    let rot = Rotation3::from_matrix_eps(&r, 1e-12, 64, Rotation3::identity());
    (
        Vector3::new(m.m03, m.m13, m.m23),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

fn axis(a: ufbx::CoordinateAxis) -> Option<Axis> {
    use ufbx::CoordinateAxis as C;
    Some(match a {
        C::PositiveX => Axis::X,
        C::NegativeX => Axis::X.flipped(),
        C::PositiveY => Axis::Y,
        C::NegativeY => Axis::Y.flipped(),
        C::PositiveZ => Axis::Z,
        C::NegativeZ => Axis::Z.flipped(),
        C::Unknown => return None,
    })
}

pub(crate) fn read(bytes: &[u8], limits: &ReadLimits) -> Result<Parsed> {
    let opts = ufbx::LoadOpts {
        temp_allocator: allocator(bytes.len()),
        result_allocator: allocator(bytes.len()),
        ignore_geometry: true,
        ignore_embedded: true,
        load_external_files: false,
        node_depth_limit: u32::try_from(limits.max_depth.saturating_add(8)).unwrap_or(u32::MAX),
        file_format: ufbx::FileFormat::Fbx,
        ..Default::default()
    };
    let scene = ufbx::load_memory(bytes, opts).map_err(|e| {
        let info = e.info();
        err(if info.is_empty() {
            e.description.to_string()
        } else {
            format!("{}: {info}", e.description)
        })
    })?;
    let mut warnings = Vec::new();

    // The joints: the bones of the file's largest skeleton and the nodes between them (an
    // exporter may put a plain node among its bones, as assimp does with a BVH's root),
    // headed by the lowest node above all of them; parents first.
    let nodes: &[ufbx::Ref<ufbx::Node>] = &scene.nodes;
    let count = nodes.len();
    let index = |n: &ufbx::Node| (n.element.typed_id as usize).min(count);
    if let Some(deep) = nodes
        .iter()
        .find(|n| u64::from(n.node_depth) > limits.max_depth)
    {
        return Err(Error::Limit {
            what: "skeleton depth",
            actual: u64::from(deep.node_depth),
            limit: limits.max_depth,
        });
    }
    // Bones in each node's subtree, children counted before their parents.
    let mut deepest_first: Vec<usize> = (0..count).collect();
    deepest_first.sort_by_key(|&i| std::cmp::Reverse(nodes[i].node_depth));
    let mut below = vec![0usize; count + 1];
    for &i in &deepest_first {
        below[i] += usize::from(nodes[i].bone.is_some());
        if let Some(p) = nodes[i].parent.as_ref() {
            let (p, n) = (index(p), below[i]);
            below[p] += n;
        }
    }
    let with_bones = |n: &ufbx::Node| below[index(n)] > 0;
    let tops: Vec<usize> = scene
        .root_node
        .children
        .iter()
        .filter(|c| with_bones(c))
        .map(|c| index(c))
        .collect();
    let mut head = *tops
        .iter()
        .max_by_key(|&&t| below[t])
        .ok_or_else(|| err("the file holds no skeleton (no bone or limb nodes)"))?;
    for &other in tops.iter().filter(|&&t| t != head) {
        warnings.push(format!(
            "the skeleton under {:?} left out: a take holds one skeleton, the largest ({:?})",
            nodes[other].element.name.to_string(),
            nodes[head].element.name.to_string()
        ));
    }
    // Down to the lowest node above every bone: a plain node above a single branch (an
    // armature, a scene's grouping) is not a joint.
    while nodes[head].bone.is_none() {
        let mut branches = nodes[head].children.iter().filter(|c| with_bones(c));
        match (branches.next(), branches.next()) {
            (Some(only), None) => head = index(only),
            _ => break,
        }
    }
    let mut order = Vec::new();
    let mut stack = vec![head];
    while let Some(i) = stack.pop() {
        order.push(i);
        let kids: Vec<usize> = nodes[i]
            .children
            .iter()
            .filter(|c| with_bones(c))
            .map(|c| index(c))
            .collect();
        stack.extend(kids.into_iter().rev());
    }
    let index_of: std::collections::HashMap<usize, usize> =
        order.iter().enumerate().map(|(k, &i)| (i, k)).collect();
    let parents: Vec<Option<usize>> = order
        .iter()
        .map(|&i| {
            nodes[i]
                .parent
                .as_ref()
                .and_then(|p| index_of.get(&index(p)).copied())
        })
        .collect();
    let mut leaf = vec![true; order.len()];
    for p in parents.iter().flatten() {
        leaf[*p] = false;
    }

    // The animation: the first stack, sampled at the file's frame rate.
    let stacks: &[ufbx::Ref<ufbx::AnimStack>] = &scene.anim_stacks;
    let stack = stacks
        .first()
        .ok_or_else(|| err("the file holds no animation (no animation stack)"))?;
    if stacks.len() > 1 {
        warnings.push(format!(
            "{} animation stacks; the first ({:?}) was read",
            stacks.len(),
            stack.element.name.to_string()
        ));
    }
    let fps = scene.settings.frames_per_second;
    crate::limits::fps(fps).map_err(|e| err(format!("its frame rate: {e}")))?;
    let span = stack.time_end - stack.time_begin;
    if !(span.is_finite() && span >= 0.0) {
        return Err(err(format!(
            "its animation runs from {} s to {} s",
            stack.time_begin, stack.time_end
        )));
    }
    let frames_f = (span * fps).round() + 1.0;
    let frames_checked = if frames_f < 1e15 {
        frames_f as usize
    } else {
        usize::MAX
    };
    limits.check_shape(frames_checked, order.len())?;
    // Each frame evaluates the whole node tree, not only the joints: bounded the same way,
    // so that a file of few joints and many other nodes cannot make the work unbounded.
    limits.check_shape(frames_checked, count.max(order.len()))?;
    let frames = frames_f as usize;
    let n = order.len();

    // Each frame: every joint's world transform, as the file's author saw it.
    let mut places: Vec<(Vector3<f64>, UnitQuaternion<f64>)> = Vec::with_capacity(frames * n);
    for f in 0..frames {
        let t = stack.time_begin + f as f64 / fps;
        let eval = ufbx::EvaluateOpts {
            temp_allocator: allocator(bytes.len()),
            result_allocator: allocator(bytes.len()),
            ..Default::default()
        };
        let at = ufbx::evaluate_scene(&scene, &stack.anim, t, eval)
            .map_err(|e| err(format!("frame {f}: {}", e.description)))?;
        for &i in &order {
            places.push(world(&at.nodes[i].node_to_world));
        }
    }

    // The skeleton: each joint's translation and rotation relative to its parent's.
    let local = |f: usize, k: usize| -> (Vector3<f64>, UnitQuaternion<f64>) {
        let (p, q) = places[f * n + k];
        match parents[k] {
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
    for (k, &i) in order.iter().enumerate() {
        let (t0, _) = local(0, k);
        moves[k] = k == 0 || (1..frames).any(|f| (local(f, k).0 - t0).amax() > FIXED);
        let leaf = leaf[k];
        let mut channels = Vec::new();
        if moves[k] {
            channels.extend(POSITIONS);
        }
        // A leaf's rotation turns nothing below it: it is an end site unless it moves.
        rotates[k] = !leaf || k == 0;
        if rotates[k] {
            channels.extend(ROTATIONS);
        }
        // A joint's name, made unique (exporters repeat names; a take's points must not).
        let base = match nodes[i].element.name.to_string() {
            n if n.trim().is_empty() => format!("node{}", nodes[i].element.typed_id),
            n => n,
        };
        let mut name = base.clone();
        let mut suffix = 2;
        while joints.iter().any(|j: &Joint| j.name == name) {
            name = format!("{base}_{suffix}");
            suffix += 1;
        }
        joints.push(Joint {
            name,
            parent: parents[k],
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
    // What the skeleton gives back against the file's own world positions: apart only
    // where the file scales a joint unevenly (a skeleton has no scale).
    let mut worst = 0.0f64;
    for (f, chunk) in fk.chunks_exact(n * 3).enumerate() {
        for k in 0..n {
            let p = places[f * n + k].0;
            let d = Vector3::new(chunk[k * 3], chunk[k * 3 + 1], chunk[k * 3 + 2]) - p;
            worst = worst.max(d.norm());
        }
    }
    if worst > 1e-3 {
        warnings.push(format!(
            "the file scales joints unevenly: the skeleton's joints lie up to {worst:.4} file \
             units from the file's (a skeleton has no scale)"
        ));
    }
    let mut contradictions = Vec::new();
    let positions: Vec<f32> = fk.into_iter().map(|v| v as f32).collect();
    let bad = positions.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        contradictions.push(format!("{bad} joint coordinates are not finite"));
    }
    let meshes = scene.meshes.len();
    if meshes > 0 || !scene.materials.is_empty() || !scene.textures.is_empty() {
        warnings.push(format!(
            "{meshes} meshes, {} materials and {} textures are not motion: left out",
            scene.materials.len(),
            scene.textures.len()
        ));
    }
    let unit = scene.settings.unit_meters;
    let motion = Motion::new(
        fps,
        super::unsettled_unit(),
        names,
        positions,
        Some(skeleton),
    )?;
    let up = axis(scene.settings.axes.up).map(|up| Prior {
        up,
        says: format!("the file's GlobalSettings say UpAxis {up}"),
    });
    Ok(Parsed {
        motion,
        declared_unit: (unit.is_finite() && unit > 0.0).then_some(unit),
        warnings,
        contradictions,
        extras: Extras {
            up,
            ..Default::default()
        },
    })
}
