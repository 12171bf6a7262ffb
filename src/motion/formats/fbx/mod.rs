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

mod records;
pub mod write;

use nalgebra::Matrix4;

use super::posed::{place, Place, Posed, Skeletal};
use super::{Extras, Format, Parsed, Pick, ReadLimits};
use crate::motion::body::{Axis, Prior};
use crate::motion::error::{Error, Location, Result};
use crate::motion::model::Motion;
use crate::motion::skeleton::Animation;

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
fn world(m: &ufbx::Matrix) -> Place {
    place(&Matrix4::new(
        m.m00, m.m01, m.m02, m.m03, m.m10, m.m11, m.m12, m.m13, m.m20, m.m21, m.m22, m.m23, 0.0,
        0.0, 0.0, 1.0,
    ))
}

/// What ufbx says went wrong: its description, its detail, and where in the file's
/// structure it was (the innermost of its frames), so that "Failed to load" says what.
fn load_error(e: &ufbx::Error) -> String {
    let mut said = e.description.to_string();
    let info = e.info();
    if !info.is_empty() {
        said = format!("{said}: {info}");
    }
    let frames = (e.stack_size as usize).min(e.stack.len());
    let context: Vec<String> = e.stack[..frames]
        .iter()
        .map(|f| f.description.to_string())
        .filter(|d| !d.is_empty() && *d != said)
        .collect();
    if !context.is_empty() {
        said = format!("{said} ({})", context.join(" < "));
    }
    said
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

/// The scene of an FBX file, with what was mended on the way.
fn load(bytes: &[u8], limits: &ReadLimits) -> Result<(ufbx::SceneRoot, Vec<String>)> {
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
    let mut warnings = Vec::new();
    let mended = records::mend(bytes);
    if mended.is_some() {
        warnings.push(
            "the file's nested record lists lack the null record that ends them (assimp \
             5.2's FBX writer leaves them out); read by the records' lengths"
                .into(),
        );
    }
    let scene = ufbx::load_memory(mended.as_deref().unwrap_or(bytes), opts)
        .map_err(|e| err(load_error(&e)))?;
    Ok((scene, warnings))
}

/// The joints' names: the file's, `root` for the scene's root, `nodeN` for a nameless one.
fn joint_names(nodes: &[ufbx::Ref<ufbx::Node>], order: &[usize], root: usize) -> Vec<String> {
    order
        .iter()
        .map(|&i| match nodes[i].element.name.to_string() {
            _ if i == root => "root".to_string(),
            n if n.trim().is_empty() => format!("node{}", nodes[i].element.typed_id),
            n => n,
        })
        .collect()
}

/// The joints of a scene, parents first, each joint's parent among them, and the scene's
/// root node (a joint only when the bones hang from it).
struct Chosen {
    order: Vec<usize>,
    parents: Vec<Option<usize>>,
    root: usize,
}

fn choose(scene: &ufbx::Scene, limits: &ReadLimits, warnings: &mut Vec<String>) -> Result<Chosen> {
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
    // The joints: the bones the file's skins bind (a character's, end bones included),
    // else every bone; headed by the lowest node above all of them. Skins decide where
    // they exist because an exporter may leave the bones of one character as several
    // trees under the scene's root (assimp writes a BVH's root there), and a scene of
    // props may hold bones that no character uses.
    let mut marked = vec![false; count + 1];
    for skin in scene.skin_deformers.iter() {
        for bone in skin.clusters.iter().filter_map(|c| c.bone_node.as_ref()) {
            marked[index(bone)] = true;
        }
    }
    if !marked.iter().any(|&m| m) {
        nodes
            .iter()
            .for_each(|n| marked[index(n)] = n.bone.is_some());
    }
    // Marked nodes in each node's subtree, children counted before their parents.
    let mut deepest_first: Vec<usize> = (0..count).collect();
    deepest_first.sort_by_key(|&i| std::cmp::Reverse(nodes[i].node_depth));
    let mut below = vec![0usize; count + 1];
    for &i in &deepest_first {
        below[i] += usize::from(marked[i]);
        if let Some(p) = nodes[i].parent.as_ref() {
            let (p, n) = (index(p), below[i]);
            below[p] += n;
        }
    }
    let root = index(&scene.root_node);
    if below[root] == 0 {
        return Err(err("the file holds no skeleton (no bone or limb nodes)"));
    }
    // Down to the lowest node above every joint: a plain node above a single branch (an
    // armature, a scene's grouping) is not a joint.
    let mut head = root;
    while !marked[head] {
        let mut branches = nodes[head].children.iter().filter(|c| below[index(c)] > 0);
        match (branches.next(), branches.next()) {
            (Some(only), None) => head = index(only),
            _ => break,
        }
    }
    if head == root {
        warnings.push(
            "the bones hang from the scene's root, not from one bone: a still root joint \
             (root) heads them"
                .into(),
        );
    }
    // A child is a joint if joints lie below it, or it is a bone itself (an end bone no
    // skin weights).
    let with_bones = |n: &ufbx::Node| below[index(n)] > 0 || n.bone.is_some();
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

    Ok(Chosen {
        order,
        parents,
        root,
    })
}

pub(crate) fn read(bytes: &[u8], limits: &ReadLimits, animation: Option<&Pick>) -> Result<Parsed> {
    let (scene, mut warnings) = load(bytes, limits)?;
    let nodes: &[ufbx::Ref<ufbx::Node>] = &scene.nodes;
    let count = nodes.len();
    let Chosen {
        order,
        parents,
        root,
    } = choose(&scene, limits, &mut warnings)?;

    // The animation: the stack asked for (else the first), sampled at the file's rate.
    let stacks: &[ufbx::Ref<ufbx::AnimStack>] = &scene.anim_stacks;
    let animations: Vec<String> = stacks
        .iter()
        .enumerate()
        .map(|(i, s)| match s.element.name.trim() {
            "" => format!("stack {i}"),
            n => n.to_string(),
        })
        .collect();
    if stacks.is_empty() {
        return Err(err("the file holds no animation (no animation stack)"));
    }
    let pick = Pick::place(animation, &animations)?;
    let stack = &stacks[pick];
    if stacks.len() > 1 {
        warnings.push(format!(
            "animation stack {:?} of {} ({}); each is a take of its own",
            animations[pick],
            animations.len(),
            animations.join(", ")
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
    limits.check_work(frames_checked, count)?;
    let frames = frames_f as usize;
    let n = order.len();

    // Each frame: every joint's world transform, as the file's author saw it.
    let mut places: Vec<Place> = Vec::with_capacity(frames * n);
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

    let names = joint_names(nodes, &order, root);
    let Skeletal {
        names,
        positions,
        skeleton,
        warnings: scaled,
    } = Posed {
        names,
        parents,
        frames,
        places,
    }
    .skeleton()?;
    warnings.extend(scaled);
    let mut contradictions = Vec::new();
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
            animations,
            animation: pick,
            ..Default::default()
        },
    })
}

/// The skeleton of the file's skinned bones at their bind pose, one frame of values (file
/// units and axes): what a character's bones stood in when its mesh was bound to them.
/// A bone the skins bind stands where its cluster says it was bound; a joint between or
/// below them (an end bone) keeps its resting place relative to its parent. A file without
/// a skin (Mixamo's "without skin" download) stands as its nodes' properties rest them.
pub(crate) fn bind_pose(bytes: &[u8], limits: &ReadLimits) -> Result<(Animation, Vec<String>)> {
    let (scene, mut warnings) = load(bytes, limits)?;
    let nodes: &[ufbx::Ref<ufbx::Node>] = &scene.nodes;
    let count = nodes.len();
    let index = |n: &ufbx::Node| (n.element.typed_id as usize).min(count);
    let Chosen {
        order,
        parents,
        root,
    } = choose(&scene, limits, &mut warnings)?;
    limits.check_shape(1, order.len())?;
    let matrix = |m: &ufbx::Matrix| {
        Matrix4::new(
            m.m00, m.m01, m.m02, m.m03, m.m10, m.m11, m.m12, m.m13, m.m20, m.m21, m.m22, m.m23,
            0.0, 0.0, 0.0, 1.0,
        )
    };
    let mut bound: Vec<Option<Matrix4<f64>>> = vec![None; count + 1];
    for skin in scene.skin_deformers.iter() {
        for c in skin.clusters.iter() {
            if let Some(bone) = c.bone_node.as_ref() {
                bound[index(bone)] = Some(matrix(&c.bind_to_world));
            }
        }
    }
    if !bound.iter().any(Option::is_some) {
        warnings.push(
            "the file has no skin: its bones stand as their own properties rest them (a \
             character's bind pose is where its skin binds them)"
                .into(),
        );
    }
    let mut world: Vec<Matrix4<f64>> = Vec::with_capacity(order.len());
    for (k, &i) in order.iter().enumerate() {
        let w = match (bound[i], parents[k]) {
            (Some(b), _) => b,
            (None, Some(p)) => world[p] * matrix(&nodes[i].node_to_parent),
            (None, None) => matrix(&nodes[i].node_to_world),
        };
        world.push(w);
    }
    let names = joint_names(nodes, &order, root);
    let Skeletal {
        skeleton,
        warnings: scaled,
        ..
    } = Posed {
        names,
        parents,
        frames: 1,
        places: world.iter().map(place).collect(),
    }
    .skeleton()?;
    warnings.extend(scaled);
    Ok((skeleton, warnings))
}
